"""Base model first (issue #7): before naming effects, check whether the nominal core parameters are far off.

A recording of a different motor than the nominal parameters describe (the demo's default motor diagnosed
against ``--params ak80_9``) must not come out as one tidy effect. From the voltage equation alone —
``v_q = R(T) i_q + L di_q/dt + K(T) ω`` with the nominal temperature dependences of R and K (the d-axis coupling
is small at the speeds where this is fitted) — a free least-squares fit gives R, L and K at the reference
temperature without any effect terms. When two or more of them differ from nominal by more than ``limit``
(default 15 %), the report says so, shows the re-identified core, and asks for it to be used as the nominal
before attributing effects.

A headline about the core model is a finding like any other (issue #24, symptom 6):

* it states what separates its values: two core values whose fitted estimates correlate beyond
  :data:`COLLINEAR` (under a viscous brake ω ∝ i: R and K_t are one column in the voltage equation) are reported
  as the combination the data pins (``R + a·K_t``), not as two values;
* it is checked by the simulator: the held-out windows are replayed (:func:`..frame.simulate.replay`) with the
  claimed core values and with the nominal ones, on the channel the claim concerns (the q voltage where it is
  recorded, else the current); only a claim that lowers the simulated error by more than ``z`` standard errors
  of the paired per-window difference (:func:`..frame.simulate.mean_se`) stands. A claim that cannot be
  simulated (no held-out windows) does not stand while the simulation gate is on.

One entry point, :func:`check`; plain data out: None when the core agrees; else a dict whose ``headline`` says
whether it stands as the verdict's headline (``message``) or is a note only.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...params import keep_controller_of
from ..frame import simulate
from ..frame.combination import COLLINEAR, collinear
from ..frame.least_squares import ols

#: the parameter-file fields of the core values the voltage equation fits, and their symbols in messages
FIELDS = {"phase_resistance": "motor.phase_resistance", "q_inductance": "motor.q_inductance",
          "torque_constant_q": "motor.torque_constant_q"}
SYMBOL = {"phase_resistance": "R", "q_inductance": "L_q", "torque_constant_q": "K_t"}
UNIT = {"phase_resistance": "ohm", "q_inductance": "H", "torque_constant_q": "V*s/rad"}


def _fit(ctx):
    """(names, coef, cov, columns, nominal) of the free voltage-equation fit, or None."""
    S = ctx.sig
    if not all(k in S for k in ("v_q", "i_q", "di_dt", "omega")):
        return None
    m = ctx.params.motor
    n = len(S["i_q"])
    # the nominal temperature dependences (copper R(T), magnet K(T) where the parameter file models them): the
    # fitted values are the reference-temperature ones the file holds
    r_fac = np.asarray(S.get("R", m.phase_resistance), float) / m.phase_resistance * np.ones(n)
    k_fac = np.asarray(S.get("K", m.torque_constant_q), float) / m.torque_constant_q * np.ones(n)
    cols = {"phase_resistance": r_fac * S["i_q"], "q_inductance": np.asarray(S["di_dt"], float),
            "torque_constant_q": k_fac * S["omega"]}
    names = list(cols)
    X = np.column_stack([cols[k] for k in names])
    y = np.asarray(S["v_q"], dtype=float)
    good = np.all(np.isfinite(X), axis=1) & np.isfinite(y)
    X, y = X[good], y[good]
    if len(y) < 50 or np.std(X[:, 2]) == 0 or np.std(X[:, 0]) == 0:
        return None
    coef, cov, r = ols(X, y)
    s2 = float(r @ r) / max(1, len(y) - X.shape[1])
    nominal = {"phase_resistance": m.phase_resistance, "q_inductance": m.q_inductance,
               "torque_constant_q": m.torque_constant_q}
    return names, coef, cov, {k: X[:, i] for i, k in enumerate(names)}, nominal, math.sqrt(s2)


def check(ctx, limit: float = 0.15, *, starts: list[int] | None = None, window_s: float = 0.1,
          simulation_gate: bool = True, z: float = 2.0, reference=None) -> dict[str, Any] | None:
    """None when the voltage equation is not available or the core agrees; else ``{"far_off": [...] (empty when
    only a not-separable pair is reported, its combination agreeing with the nominal),
    "identified": {name: value}, "nominal": {...}, "combinations": [...], "simulation": {...} | None,
    "headline": bool, "message": str}``. ``starts``: the held-out replay windows (``window_s`` long) the claim is
    simulated on; ``simulation_gate`` False: a claim stands on the equation error alone. ``reference``: the
    judged model (the nominal with the accepted findings written in, default the nominal): the claim is replayed
    as that model with the claimed core values against it with the nominal core values, so a claim stands only
    where the core explains the recording better than the findings already judged on it do."""
    fitted = _fit(ctx)
    if fitted is None:
        return None
    names, coef, cov, cols, nominal_all, resid_rms = fitted
    idx = {k: i for i, k in enumerate(names)}
    if coef[idx["phase_resistance"]] <= 0 or coef[idx["torque_constant_q"]] <= 0:
        return None   # R or K not positive: current and speed too alike in this data to separate them
    identified_all = {k: float(coef[idx[k]]) for k in names}
    sd_all = {k: float(math.sqrt(cov[idx[k], idx[k]])) if cov[idx[k], idx[k]] >= 0 else float("nan") for k in names}
    # the inductance is only checked where the recording resolves it
    checked = [k for k in names if k != "q_inductance" or not getattr(ctx, "nuisance", None)]
    nominal = {k: nominal_all[k] for k in checked}
    identified = {k: identified_all[k] for k in checked}
    ratio = {k: identified[k] / nominal[k] for k in checked if nominal[k] > 0}
    # pairs the data cannot separate: reported as the combination it pins, v ~ x_p + a x_q along the pair's
    # common direction (a = <x_q, x_p> / <x_p, x_p> in the nominal units of q per unit of p's column)
    combos, in_combo = [], set()
    for c in collinear(names, coef, cov, cols, among=checked):
        p, q = c.parameters
        nom = nominal_all[p] + c.a * nominal_all[q]
        combos.append({"parameters": [p, q], "correlation": c.correlation, "a": c.a, "value": c.value,
                       "sd": c.sd, "nominal": nom, "ratio": c.value / nom if nom else float("nan"),
                       "far_off": bool(nom and abs(c.value / nom - 1.0) > limit)})
        in_combo |= {p, q}
    far_single = [k for k in checked if k not in in_combo and k in ratio and abs(ratio[k] - 1.0) > limit]
    far_combo = [c for c in combos if c["far_off"]]
    n_far = len(far_single) + 2 * len(far_combo)          # a combination concerns two core values
    sep_text = "; ".join(_combo_text(c) for c in combos)
    if n_far < 2:
        if not combos:
            return None
        return {"far_off": [], "identified": identified, "nominal": nominal, "combinations": combos,
                "limit": limit, "simulation": None, "headline": False,
                "message": f"core values not separable with this data: {sep_text}; the combination agrees with "
                           f"the nominal within {100 * limit:.0f} %: the base model is not far off"}
    far = far_single + [p for c in far_combo for p in c["parameters"]]
    parts = ", ".join(f"{k} {identified[k]:.4g} (nominal {nominal[k]:.4g}, x{ratio[k]:.2f})" for k in far_single)
    parts = "; ".join(x for x in (parts, "; ".join(_combo_text(c) for c in far_combo)) if x)
    sim = _simulate_claim(ctx, {k: identified_all[k] for k in far}, starts, window_s, z, reference)
    # each single value of the claim must itself help (leave one out, like any finding): a value that the simulator
    # does not need is no part of the headline (a drive the emulation cannot express leaves a spurious L beside
    # a true R), and with fewer than two values left the core is not "far off"
    unneeded = [k for k in far_single if sim is not None and not sim["needed"].get(k, True)]
    if unneeded:
        far_single = [k for k in far_single if k not in unneeded]
        n_far = len(far_single) + 2 * len(far_combo)
    stands = n_far >= 2 and ((sim is not None and sim["verdict"] == "confirmed") or (sim is None and not simulation_gate))
    if stands and unneeded:            # the headline names the values the simulation needs
        far = far_single + [p for c in far_combo for p in c["parameters"]]
        parts = "; ".join(x for x in (", ".join(f"{k} {identified[k]:.4g} (nominal {nominal[k]:.4g}, x{ratio[k]:.2f})"
                                                  for k in far_single),
                                      "; ".join(_combo_text(c) for c in far_combo)) if x)
    out = {"far_off": far, "identified": identified, "nominal": nominal, "combinations": combos, "limit": limit,
           "simulation": sim, "headline": bool(stands), "fit_residual_rms_v": resid_rms}
    if stands:
        how = (f"the simulated held-out {sim['channel']} error falls {sim['without']:.3g} -> {sim['with']:.3g} "
               f"(noise floor {sim['noise_floor']:.2g}, {sim['windows']} windows)" if sim else
               "not checked in simulation (simulation gate off)")
        out["message"] = (f"base model far off: the voltage equation alone gives {parts} and {how}; these are not "
                          f"effects to attribute — re-identify the core (or pick the right motor's parameters) and "
                          f"diagnose again against it")
    else:
        why = ("no held-out windows to simulate it on" if sim is None else
               f"the simulated held-out {sim['channel']} error is {sim['without']:.3g} with the nominal core and "
               f"{sim['with']:.3g} with these values (improvement {sim['improvement']:.2g}, noise floor "
               f"{sim['noise_floor']:.2g}, {sim['windows']} windows)")
        if unneeded:
            why += ("; left out one at a time, " + ", ".join(
                f"{SYMBOL.get(k, k)} (error {sim['leave_one_out'][k]['without']:.3g} without it, improvement "
                f"{sim['leave_one_out'][k]['improvement']:.2g}, floor {sim['leave_one_out'][k]['noise_floor']:.2g})"
                for k in unneeded) + " is not needed by the simulation: no core claim of two values stands")
        out["message"] = (f"the voltage equation alone suggests {parts}, but the simulator does not confirm it "
                          f"({why}): not stated as the base model being far off")
    return out


def _combo_text(c: dict) -> str:
    p, q = c["parameters"]
    sp, sq = SYMBOL.get(p, p), SYMBOL.get(q, q)
    return (f"{sp} and {sq} not separable with this data (their fitted estimates correlate {c['correlation']:+.4f}"
            f"{': the speed follows the current' if {p, q} == {'phase_resistance', 'torque_constant_q'} else ''}): "
            f"the data pins {sp} + {c['a']:.4g}·{sq} = {c['value']:.4g} ± {c['sd']:.2g}"
            f"{' V/A (a: the speed per current, rad/s per A)' if sp == 'R' and sq == 'K_t' else ''} "
            f"(nominal {c['nominal']:.4g}, x{c['ratio']:.2f})")


def _simulate_claim(ctx, values: dict[str, float], starts, window_s: float, z: float,
                    reference=None) -> dict[str, Any] | None:
    """The held-out windows replayed with the claimed core values and with the nominal ones, each in the judged
    model ``reference`` (its non-core findings kept; the recorded drive's current loop kept on the nominal
    values); the paired per-window difference of the claim's channel."""
    if not starts:
        return None
    m = ctx.params.motor
    core = {FIELDS[k]: getattr(m, k) for k in FIELDS}
    base = keep_controller_of((reference or ctx.params).replace(**core), ctx.params)
    claimed = keep_controller_of(base.replace(**{FIELDS[k]: v for k, v in values.items()}), ctx.params)
    keys = list(values) if len(values) > 1 else []
    # leave one out: the claim with each value back at its nominal
    loo = [keep_controller_of(claimed.replace(**{FIELDS[k]: getattr(m, k)}), ctx.params) for k in keys]
    res = simulate.replay(ctx, [base, claimed] + loo, list(starts), window_s)
    if not res or not res[0].get("available"):
        return None
    ch = "voltage" if res[0]["per_window"].get("voltage") is not None else "current"
    without, with_ = np.asarray(res[0]["per_window"][ch], float), np.asarray(res[1]["per_window"][ch], float)
    imp, se = simulate.mean_se(without - with_)
    verdict = "confirmed" if math.isfinite(imp) and imp > z * se and imp > 0 else "not confirmed"
    leave, needed = {}, {}
    for k, r in zip(keys, res[2:]):
        e_k = np.asarray(r["per_window"][ch], float)
        g, s_ = simulate.mean_se(e_k - with_)
        leave[k] = {"without": float(np.mean(e_k)), "improvement": g,
                    "noise_floor": z * s_ if math.isfinite(s_) else float("nan")}
        needed[k] = bool(math.isfinite(g) and g > z * s_ and g > 0)
    return {"channel": ch, "without": float(np.mean(without)), "with": float(np.mean(with_)), "improvement": imp,
            "noise_floor": z * se if math.isfinite(se) else float("nan"), "windows": len(starts),
            "window_s": window_s, "values": values, "verdict": verdict, "leave_one_out": leave, "needed": needed}
