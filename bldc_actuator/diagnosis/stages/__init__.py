"""The diagnosis as stages a reader can follow (issue #7), each a module with one entry point ``run`` and plain
data between them (:mod:`.data`):

load (:func:`..io.loaders.load`) -> clean (:func:`..io.cleaning.clean`) -> :mod:`.search` (equation error: where and
what) -> :mod:`.judge` (simulation: does it help held-out data) -> :mod:`.refit` (output error, the parameter
file) -> :mod:`.report` (findings, before/after, :class:`..report.DiagnosisReport`).
"""
