"""Fleet diagnosis: many recordings x joints diagnosed on Dask, tracked parameters trended over time.

Modules: :mod:`.discover` (files, parameter map), :mod:`.source` (joints, actuator id, start time),
:mod:`.health` (the tracked-parameter estimator), :mod:`.run` (Dask), :mod:`.trends` (alerts),
:mod:`.html` (report), :mod:`.cli` (``bldc-actuator fleet``).
"""
