"""``bldc-actuator diagnose``: hold the simulation against real recordings, locate where they differ,
name the missing physics, model it and show the fit improve (issue 4).

Data layer: :mod:`.signals` (Signals, DataIssue, CANONICAL), :mod:`.loaders` (CSV, MCAP, Mapping),
:mod:`.cleaning` (detect and report dirty data), :mod:`.input_profiles` (log formats as YAML data, detected by their header).
"""

from .signals import CANONICAL, DataIssue, Signals

__all__ = ["CANONICAL", "DataIssue", "Signals"]
