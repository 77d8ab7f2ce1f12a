"""Recordings in, clean :class:`~..signals.Signals` out: the diagnosis' input side.

:mod:`.loaders` decides how a file is read (``--map`` mapping, ``--profile``, a self-describing file, or the
auto-detected input profile) over :mod:`.csvio`, :mod:`.mcapio` and :mod:`.mapping` (``--map`` expressions);
:mod:`.input_profiles` holds log formats as YAML data (``config/input_profiles/``) and :mod:`.quirks` the generic
operations a profile names; :mod:`.cleaning` finds and reports dirty data (never silently). Loaders only translate;
the next stage is always ``cleaning.clean``.

Nothing is imported here, so ``from bldc_actuator.diagnosis.io import cleaning`` does not pull in the MCAP reader.
"""
