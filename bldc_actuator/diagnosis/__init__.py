"""``bldc-actuator diagnose``: hold the simulation against real recordings, locate where they differ,
name the missing physics, model it and show the fit improve (issue 4).

Data layer: :mod:`.signals` (Signals, DataIssue, CANONICAL) and :mod:`.io`: :mod:`.io.loaders` (CSV, MCAP, Mapping),
:mod:`.io.cleaning` (detect and report dirty data), :mod:`.io.input_profiles` (log formats as YAML data, detected by
their header), :mod:`.io.quirks`. Typed results of the method: :mod:`.results`; one entry point: :func:`.pipeline.diagnose`.
"""

from .signals import CANONICAL, DataIssue, Signals

__all__ = ["CANONICAL", "DataIssue", "Signals"]
