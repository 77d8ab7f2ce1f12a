"""``diagnose()``: locate where a recording and the model differ, name the missing physics, fit it,
and show the fit improve on data it did not fit.

The method in stages, each a package whose ``stage`` module is its one entry point, with plain data between them
(:mod:`.records`), over the shared :mod:`.frame` (equation error, the effect library, window replay); the caller has loaded (:func:`.io.loaders.load`) and cleaned (:func:`.io.cleaning.clean`) the
recording:

* :mod:`.search.stage` — equation error: the recording in the model's frame, the nominal residuals and replay,
  where they sit (bins, change points, angle orders), forward selection with ΔBIC + held-out gate, the thermal
  network and voltage-limit searches.
* :mod:`.judge.stage` — the simulator as judge: aliases decided by replay, practical significance and
  identifiability, each finding's held-out simulated error with and without it, thermal findings by full-length
  thermal simulation, the drive's voltage-limit mode.
* :mod:`.fit.stage` — output-error refit (multiple shooting) and the updated parameter file.
* :mod:`.report.stage` — findings, before/after, the :class:`.report.document.DiagnosisReport`.

The route is chosen from the channels (:func:`route`): a log with torque and motion but no motor current goes
to the torque balance (:mod:`.torque_balance`), reported by :func:`.report.stage.torque_balance` in the same
:class:`DiagnosisReport` schema. The CLI and ``fleet`` both call :func:`diagnose`. Every report ends in one of
three verdicts (:mod:`.results`: found / nothing missing / not decidable with the reasons of
:mod:`.report.decidability`, including a structured residual outside the catalogue, :mod:`.report.residual_structure`).

One progress line per step on stderr when ``options.progress``, numbered alike on both routes (``k/6``).

Usage::

    from bldc_actuator.diagnosis.pipeline import diagnose, DiagnoseOptions
    report = diagnose(signals, params, options=DiagnoseOptions(holdout=0.3))
    report.to_dict()          # JSON-ready
    report.updated_params     # ActuatorParams with the accepted effects switched on and fitted
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from ..params import ActuatorParams
from .effects import registry
from .report.document import DiagnosisReport
from .frame.selection import GateConfig
from .fit import stage as refit
from .judge import stage as judge
from .report import stage as report
from .search import stage as search
from .threads import SingleThreadedBLAS


@dataclass
class DiagnoseOptions:
    """Knobs of :func:`diagnose` (defaults suit a 1 kHz robot-joint recording)."""

    effects: list[str] | None = None          #: candidate effects to test (default: every candidate of the registry)
    holdout: float = 0.3                      #: fraction of the recording held out (interleaved time blocks)
    holdout_signals: Any = None               #: a separate recording used as the held-out data instead
    cutoff_hz: float | None = None            #: parallel low-pass cut-off (default min(0.1 fs, 100 Hz))
    window_s: float = 0.1                     #: replay (multiple-shooting) window length [s]
    max_windows: int = 120                    #: replay windows per set (evenly thinned)
    replay: bool = True                       #: run the short-window simulation comparison
    gate: GateConfig = field(default_factory=GateConfig)
    simulation_gate: bool = True              #: accept only findings the held-out simulation confirms
    tolerance: float = 0.05                   #: a parameter-change finding must move its parameter by more
    max_relative_uncertainty: float = 0.5     #: every accepted value must be identified this well (sd/|value|)
    progress: bool | Callable[[str], None] = False   #: True: one line per stage on stderr
    #: how the logged voltage is timed against its samples: auto (the recording's declaration first) | applied |
    #: command | sample (:data:`.frame.equation_error.VOLTAGE_TIMINGS`)
    voltage_timing: str = "auto"

    def validated_effects(self) -> list[str]:
        names = list(registry.names(registry.candidates()))   # read now: a plug-in effect counts
        if self.effects is None:
            return names
        bad = [e for e in self.effects if e not in names]
        if bad:
            raise ValueError(f"effects: unknown effect(s) {', '.join(bad)} (known: {', '.join(names)})")
        return list(dict.fromkeys(self.effects))


def _progress(options: DiagnoseOptions) -> Callable[[str], None]:
    if callable(options.progress):
        return options.progress
    if options.progress:
        return lambda msg: print(f"[diagnose] {msg}", file=sys.stderr, flush=True)
    return lambda msg: None


FULL = "equation error + simulation"
TORQUE_BALANCE = "torque balance"
VOLTAGE_MODE = "voltage mode"


def route(signals) -> str:
    """Which route diagnoses ``signals``: :data:`TORQUE_BALANCE` when torque and motion are logged but no
    current (:func:`.torque_balance.applicable`), :data:`VOLTAGE_MODE` when voltage and motion are logged but no
    current (:func:`.voltage_mode.applicable`: the mechanical equation closed by i = (v - K ω)/R), else
    :data:`FULL`."""
    from . import torque_balance, voltage_mode

    if torque_balance.applicable(signals):
        return TORQUE_BALANCE
    return VOLTAGE_MODE if voltage_mode.applicable(signals) else FULL


def diagnose(signals, params: ActuatorParams, *, options: DiagnoseOptions | None = None) -> DiagnosisReport:
    """Diagnose ``signals`` (a :class:`~bldc_actuator.diagnosis.signals.Signals`, cleaned) against the
    nominal ``params``, on the route the recording allows (:func:`route`). See the module docstring for the
    stages and :class:`DiagnosisReport` for the result (one schema on both routes)."""
    options = options or DiagnoseOptions()
    with SingleThreadedBLAS():
        which = route(signals)
        if which == TORQUE_BALANCE:
            return _torque_balance(signals, params, options)
        if which == VOLTAGE_MODE:
            return _voltage_mode(signals, params, options)
        return _diagnose(signals, params, options)


def _voltage_mode(signals, params: ActuatorParams, options: DiagnoseOptions) -> DiagnosisReport:
    from . import voltage_mode

    say = _progress(options)
    t_start = time.perf_counter()
    say(f"1/6 prepare: voltage and motion logged, no current: the voltage-mode route ({len(signals.time)} samples)")
    res = voltage_mode.diagnose(signals, params, holdout=options.holdout, tolerance=options.tolerance,
                                max_relative_uncertainty=options.max_relative_uncertainty,
                                holdout_signals=options.holdout_signals)
    say(f"4/6 attribute: accepted {[f.effect for f in res.findings] or 'nothing'}")
    return voltage_mode.report(signals, params, res, options, say, t_start)


def _torque_balance(signals, params: ActuatorParams, options: DiagnoseOptions) -> DiagnosisReport:
    from . import torque_balance

    say = _progress(options)
    t_start = time.perf_counter()
    say(f"1/6 prepare: torque and motion logged, no motor current: the torque-balance route "
        f"({len(signals.time)} samples)")
    res = torque_balance.diagnose(signals, params, holdout=options.holdout)
    say(f"4/6 attribute: accepted {[f.effect for f in res.findings] or 'nothing'}; "
        f"{len(res.not_checkable)} not checkable")
    return report.torque_balance(signals, params, res, options, say, t_start)


def _diagnose(signals, params: ActuatorParams, options: DiagnoseOptions) -> DiagnosisReport:
    say = _progress(options)
    t_start = time.perf_counter()
    found = search.run(signals, params, options, say)
    if found.selection is None:
        return report.not_checkable(found)
    judged = judge.run(found, options, say)
    model = refit.run(found, judged, options, say)
    return report.run(signals, params, found, judged, model, options, say, t_start)
