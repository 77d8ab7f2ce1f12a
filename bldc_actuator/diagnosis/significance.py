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

import math
from dataclasses import dataclass
from typing import Any

from ..params import ActuatorParams

#: parameter-change effects: (parameter name in the effect's parameters, nominal getter)
_CHANGES = {
    "torque_constant_error": ("torque_constant_q", lambda p: p.motor.torque_constant_q),
    "inertia_error": ("rotor_inertia", lambda p: p.motor.rotor_inertia),
    "resistance_error": ("phase_resistance", lambda p: p.motor.phase_resistance),
    "inductance_error": ("q_inductance", lambda p: p.motor.q_inductance),
}
_THERMAL = ("winding_to_housing_resistance", "housing_to_ambient_resistance", "winding_heat_capacity",
            "housing_heat_capacity")


#: |log(value / nominal)| bound of the thermal network's output-error fit (refit.thermal_select)
THERMAL_FIT_BOUND_LOG = math.log(10.0)


@dataclass
class Verdict:
    effect: str
    kind: str          #: "consistent_with_nominal" | "not_identifiable"
    message: str


def _relative_change(effect: str, values: dict[str, float], nominal: ActuatorParams) -> float | None:
    if effect in _CHANGES:
        name, get = _CHANGES[effect]
        v, n = values.get(name), get(nominal)
        return abs(v / n - 1.0) if v is not None and n else None
    if effect == "thermal_parameters":
        th = nominal.thermal
        ch = [abs(values[f] / getattr(th, f) - 1.0) for f in _THERMAL if f in values and getattr(th, f)]
        return max(ch) if ch else None
    return None


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
        if effect == "thermal_parameters":      # the output-error fit is bounded to [1/10, 10] x nominal
            th = nominal.thermal
            pinned = [f for f in _THERMAL if f in values and getattr(th, f)
                      and abs(math.log(values[f] / getattr(th, f))) > THERMAL_FIT_BOUND_LOG * 0.98]
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
        rel, name, v, sd = max(rels) if (effect == "thermal_parameters" or effect in _CHANGES) else min(rels)
        if rel > max_relative_uncertainty:
            exp = experiments.get(effect) or "record data that excites it more (longer, larger, more varied)"
            out.append(Verdict(effect, "not_identifiable",
                               f"{effect}: suspected, not identifiable — {name} = {v:.3g} ± {sd:.2g} "
                               f"({100 * rel:.0f} % relative uncertainty, bound {100 * max_relative_uncertainty:g} %); "
                               f"experiment that would separate it: {exp}"))
    return out
