"""Plain data handed from one diagnosis stage to the next (the stages of :mod:`bldc_actuator.diagnosis.pipeline`: search -> judge -> fit -> report)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

from ..params import ActuatorParams
from .frame.equation_error import Context, Fit
from .frame.writeback import FinalFit
from .frame.selection import SelectionResult
from .significance import Verdict


@dataclass
class Search:
    """What equation error found: the prepared recording, the nominal residuals, where they sit, the terms
    selected by ΔBIC + held-out gate, and the output-error searches (thermal network, voltage limit)."""

    ctx: Context                         #: the recording in the model's frame (prepared once, read by every stage)
    names: list[str]                     #: effects tested
    lib: dict                            #: effect name -> Candidate
    nominal_fit: Fit                     #: equation-error residuals of the nominal model
    located: dict[str, dict]             #: equation -> bins, change points, angle-order spectrum
    windows: list[dict]                  #: time windows where a residual changes level
    selection: SelectionResult           #: equation-error terms accepted, rejected, aliased
    special: dict[str, Any]              #: findings/rejected/not_checkable of the thermal and voltage-limit searches
    starts_holdout: list[int] = field(default_factory=list)   #: held-out replay windows (sample indices)
    replay_nominal: dict | None = None   #: nominal replay over all windows
    data_issues: list[dict] = field(default_factory=list)
    timing: dict[str, float] = field(default_factory=dict)


@dataclass
class Judgement:
    """What survives the judges: practical significance, identifiability and the held-out simulation."""

    selection: SelectionResult           #: the accepted equation-error terms after the judges
    final: FinalFit                      #: their joint fit
    parameters: dict[str, dict]          #: effect -> {parameter: {"value", "sd", "field", ...}}
    special: dict[str, Any]              #: thermal / voltage-limit / drive-mode findings after the judges
    verdicts: list[Verdict]              #: every finding refused, with its reason
    simulation: dict[str, dict]          #: effect -> simulated before/after verdict
    alias_simulation: list[dict] = field(default_factory=list)
    params_linear: ActuatorParams | None = None   #: nominal + the accepted equation-error findings (their values)
    notes: list[str] = field(default_factory=list)          #: what writing those values said
    not_simulated: list[str] = field(default_factory=list)
    timing: dict[str, float] = field(default_factory=dict)


@dataclass
class Model:
    """The updated parameters: equation-error values, then the output-error refit, then the special findings."""

    params: ActuatorParams
    notes: list[str]
    not_simulated: list[str]
    output_error: dict | None
    base: dict | None                    #: several core values far off (base_model.check)
    timing: dict[str, float] = field(default_factory=dict)


Say = Callable[[str], None]
