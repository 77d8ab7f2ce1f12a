"""Practical significance and identifiability of findings (issue #7): a statistically supported term is still
not worth reporting when it changes a parameter by less than a tolerance, or when its value is not identified
by the data.

* **Consistent with nominal**: a parameter-change finding (torque constant, inertia, resistance, inductance,
  thermal network) that moves its parameter by less than ``tolerance`` (default 5 %) of the nominal value.
* **Suspected, not identifiable**: a finding whose simulated parameters have a relative standard uncertainty
  above ``max_relative_uncertainty`` (default 50 %) — for a set of separate claims (the thermal network, a
  changed constant) the worst one, for a series (cogging harmonics, a load's terms) the best one: the data
  cannot pin it down; the report names the experiment that would (the candidate's separating experiment, or
  what excites it).

One entry point, :func:`judge`, on plain data (the effect parameters as the refit maps them); the pipeline drops
what it returns from the accepted set BEFORE the final fit and the updated parameter file.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

from ..params import ActuatorParams
from .effects import registry

# parameter-change effects (a changed constant, the thermal network) name the nominal values they move: the
# registry's ``Effect.nominal``, (parameter name in the effect's parameters, dotted path in ActuatorParams)


#: |log(value / nominal)| bound of the thermal network's output-error fit (refit.thermal_select)
THERMAL_FIT_BOUND_LOG = math.log(10.0)


@dataclass
class Verdict:
    effect: str
    kind: str          #: "consistent_with_nominal" | "not_identifiable"
    message: str


def _nominal_value(params: ActuatorParams, path: str) -> float:
    return functools.reduce(getattr, path.split("."), params)


def _nominal_of(effect: str) -> tuple[tuple[str, str], ...]:
    return registry.get(effect).nominal if registry.known(effect) else ()


def _relative_change(effect: str, values: dict[str, float], nominal: ActuatorParams) -> float | None:
    """The largest relative change among the nominal values a parameter-change effect moves; None for others."""
    ch = [abs(values[name] / _nominal_value(nominal, path) - 1.0) for name, path in _nominal_of(effect)
          if name in values and _nominal_value(nominal, path)]
    return max(ch) if ch else None


def judge(effects: dict[str, dict[str, dict[str, Any]]], nominal: ActuatorParams, *, tolerance: float = 0.05,
          max_relative_uncertainty: float = 0.5, experiments: dict[str, str] | None = None) -> list[Verdict]:
    """``effects``: effect -> {parameter: {"value", "sd", "field", ...}} (the refit's mapping; thermal findings
    as {name: {"value", "sd", "field"}}). Returns the findings to drop, each with its reason."""
    out: list[Verdict] = []
    experiments = experiments or {}
    for effect, pars in effects.items():
        values = {k: v["value"] for k, v in pars.items() if isinstance(v.get("value"), (int, float))}
        change = _relative_change(effect, values, nominal)
        if change is not None and change < tolerance:
            out.append(Verdict(effect, "consistent_with_nominal",
                               f"{effect}: consistent with nominal (the fit moves it by {100 * change:.2g} %, below "
                               f"the {100 * tolerance:g} % tolerance)"))
            continue
        if registry.known(effect) and registry.get(effect).bounded_log_fit:   # fit bounded to [1/10, 10] x nominal
            pinned = [f for f, path in _nominal_of(effect) if f in values and _nominal_value(nominal, path)
                      and abs(math.log(values[f] / _nominal_value(nominal, path))) > THERMAL_FIT_BOUND_LOG * 0.98]
            if pinned:
                out.append(Verdict(effect, "not_identifiable",
                                   f"{effect}: suspected, not identifiable — {', '.join(pinned)} ran to the fit's bound "
                                   f"(10x or 1/10 of nominal): the data do not pin the thermal network down; "
                                   f"experiment that would separate it: "
                                   f"{experiments.get(effect) or 'a longer run with a larger temperature span (heating and cooling)'}"))
                continue
        rels = []
        for name, info in pars.items():
            v, sd = info.get("value"), info.get("sd")
            if not info.get("field") or not isinstance(v, (int, float)) or sd is None or not math.isfinite(sd):
                continue
            if v == 0:
                continue
            rels.append((abs(sd / v), name, v, sd))
        if not rels:
            continue
        # a set of separate claims (thermal network, a changed constant): each must be identified; a series
        # (cogging harmonics, a load's sin/cos/constant): its best-identified term carries it
        rel, name, v, sd = max(rels) if _nominal_of(effect) else min(rels)
        if rel > max_relative_uncertainty:
            exp = experiments.get(effect) or "record data that excites it more (longer, larger, more varied)"
            out.append(Verdict(effect, "not_identifiable",
                               f"{effect}: suspected, not identifiable — {name} = {v:.3g} ± {sd:.2g} "
                               f"({100 * rel:.0f} % relative uncertainty, bound {100 * max_relative_uncertainty:g} %); "
                               f"experiment that would separate it: {exp}"))
    return out
