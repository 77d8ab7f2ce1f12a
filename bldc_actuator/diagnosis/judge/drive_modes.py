"""The drive at the voltage limit (issue #7): which ``drive.voltage_limit_mode`` did the recording's drive use?

Real drives differ where the PI controller demands more voltage than the inverter's circle holds: the whole
d/q vector scaled onto the circle (``proportional``), v_d served first (``d_priority``), v_q served first
(``q_priority``), or a field-weakening regulator that commands negative i_d (``field_weakening``). Below the
limit they are identical, so equation error cannot tell them apart and only a simulation can: the windows of
the recording where the model's voltage demand reaches the circle are replayed (multiple shooting from recorded
states, :func:`.simulate.simulate_windows`, the node's own kernel) under every mode.

Method: the mode with the lowest simulated error on the TRAINING windows near the limit (current, speed and,
when recorded, the d current; each channel's error relative to the nominal mode's) is the candidate; it is
accepted when, on the HELD-OUT windows near the limit, it lowers the simulated current error beyond the noise
floor (``z`` standard errors of the paired per-window difference) and the practical tolerance, without worsening
the speed. Field weakening is tried with the drive's current limit as its d-current budget.

One entry point, plain data out: :func:`identify`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...kernel import VOLTAGE_LIMIT_MODES
from ...params import ActuatorParams, current_loop_limit
from ..effects import Route, registry
from ..frame import simulate

#: a sample counts as "at the voltage limit" when the model's steady voltage demand |(R i + K ω) + j p ω L i|
#: reaches this fraction of the circle (the PI's transient demand goes above it), or the recorded voltage does
NEAR_LIMIT = 0.9
#: windows near the limit needed on each side (training, held-out) for a verdict
MIN_WINDOWS = 6
#: windows replayed per side at most
MAX_WINDOWS = 60


def drive_replay_unavailable(ctx, effect: str) -> dict[str, Any] | None:
    """The ``not_checkable`` record of a drive finding (``effect``) that only a closed-loop replay of the drive can
    decide, when the recording lacks what that replay needs: the current, the speed and the current or torque
    command; None when it has them. (This module's voltage-limit mode and :mod:`...drive_feedforward`'s form.)"""
    if "i_q" in ctx.sig and "omega" in ctx.sig and any(c in ctx.have for c in ("current_command", "torque_command")):
        return None
    return {"effect": effect, "reason": "needs current, speed and the current or torque command",
            "needs": ["current", "velocity|position", "current_command|torque_command"]}


def _near_limit(ctx) -> np.ndarray:
    """Per raw sample: does the nominal model's steady voltage demand, or the recorded voltage, reach NEAR_LIMIT
    of the circle?"""
    S, m = ctx.sig, ctx.params.motor
    cmd, _ = simulate.commands(ctx)
    w = S["omega_s"]
    need = np.hypot(S["R"] * cmd + S["K"] * w, m.pole_pairs * w * m.q_inductance * cmd)
    limit = ctx.params.drive.modulation_limit * S["v_max"]
    near = need >= NEAR_LIMIT * limit
    if "headroom" in S:
        near |= np.nan_to_num(S["headroom"]) >= NEAR_LIMIT * ctx.params.drive.modulation_limit
    return near


def _limit_windows(ctx, which: str, window_s: float, near: np.ndarray) -> list[int]:
    L = max(5, int(round(window_s * ctx.fs)))
    return simulate.thin([s for s in simulate.windows(ctx, window_s, 10 ** 9, which) if near[s:s + L + 1].any()],
                      MAX_WINDOWS)


def _stable_windows(ctx, starts: list[int], window_s: float, params: ActuatorParams) -> tuple[list[int], str]:
    """The windows whose speed stays inside the stable range of the model's current loop (a complex-vector law
    diverges above it, :func:`...params.current_loop_limit`: its replay says nothing about the limit modes there),
    and, when some are dropped, why."""
    lim = current_loop_limit(params)
    if lim is None or not starts:
        return starts, ""
    L = max(5, int(round(window_s * ctx.fs)))
    w = np.abs(np.asarray(ctx.sig["omega_s"], float))
    keep = [s for s in starts if lim.stable_at(w[s:s + L + 1])]
    if len(keep) == len(starts):
        return starts, ""
    return keep, (f"{len(starts) - len(keep)} window(s) left out: "
                  + lim.unstable_above("the model's drive.current_controller complex_vector"))


def _variants(params: ActuatorParams) -> dict[str, ActuatorParams]:
    out = {}
    for mode in VOLTAGE_LIMIT_MODES:
        kw = {"drive.voltage_limit_mode": mode}
        if mode == "field_weakening" and params.drive.field_weakening_current_max <= 0.0:
            kw["drive.field_weakening_current_max"] = params.drive.current_limit
        out[mode] = params.replace(**kw)
    return out


def _score(e: dict[str, np.ndarray], ref: dict[str, np.ndarray]) -> float:
    """Sum over channels of the mean per-window error relative to the reference set's (1 each when equal)."""
    return float(sum(np.mean(e[k]) / max(np.mean(ref[k]), 1e-12) for k in e))


def identify(ctx, params: ActuatorParams, window_s: float, *, wanted: bool = True, z: float = 2.0,
             tolerance: float = 0.05) -> dict[str, Any]:
    """``{"findings": [...], "rejected": [...], "not_checkable": [...], "simulation": {...} | None}`` for the
    effect ``voltage_limit_mode``; ``params`` = the model so far (every other accepted finding applied)."""
    eff = registry.one(lambda e: e.route is Route.DRIVE_MODE)
    name = eff.name
    par = eff.params[0]         # the one categorical setting it writes
    out: dict[str, Any] = {"findings": [], "rejected": [], "not_checkable": [], "simulation": None}
    if not wanted:
        return out
    missing = drive_replay_unavailable(ctx, name)
    if missing:
        out["not_checkable"].append(missing)
        return out
    near = _near_limit(ctx)
    tr, why_tr = _stable_windows(ctx, _limit_windows(ctx, "train", window_s, near), window_s, params)
    ho, why_ho = _stable_windows(ctx, _limit_windows(ctx, "holdout", window_s, near), window_s, params)
    unstable = "; ".join(f"{side}: {why}" for side, why in (("training", why_tr), ("held-out", why_ho)) if why)
    if len(tr) < MIN_WINDOWS or len(ho) < MIN_WINDOWS:
        out["not_checkable"].append({
            "effect": name, "needs": [],
            "reason": (f"too few windows at the voltage limit inside the stable speed range of the model's current "
                       f"loop ({len(tr)} training and {len(ho)} held-out {window_s:g} s windows; {MIN_WINDOWS} each "
                       f"needed): {unstable}") if unstable else
                      (f"data does not reach the voltage limit often enough ({len(tr)} training and {len(ho)} "
                       f"held-out {window_s:g} s windows where the voltage demand reaches {NEAR_LIMIT:.0%} "
                       f"of the circle; {MIN_WINDOWS} each needed): the modes differ only there")})
        return out
    nominal = params.drive.voltage_limit_mode
    variants = _variants(params)
    modes = list(variants)
    e_tr = dict(zip(modes, simulate.window_errors(ctx, list(variants.values()), tr, window_s, current_d=True)))
    scores = {m: _score(e_tr[m], e_tr[nominal]) for m in modes}
    best = min(modes, key=lambda m: scores[m])
    sim = {"training_windows": len(tr), "heldout_windows": len(ho), "window_s": window_s,
           "training_score": {m: round(v, 4) for m, v in scores.items()}, "nominal": nominal, "candidate": best}
    if unstable:
        sim["unstable_windows"] = unstable
    out["simulation"] = sim
    if best == nominal:
        out["rejected"].append({"effect": name, "form": "simulated at the voltage limit",
                                "reason": f"the nominal mode ({nominal}) simulates the windows at the limit best "
                                          f"(relative training error {', '.join(f'{m} {v:.3f}' for m, v in scores.items())})"})
        return out
    e_ho = simulate.window_errors(ctx, [variants[nominal], variants[best]], ho, window_s, current_d=True)
    imp, se = simulate.mean_se(e_ho[0]["current"] - e_ho[1]["current"])
    imp_w, se_w = simulate.mean_se(e_ho[0]["velocity"] - e_ho[1]["velocity"])
    before, after = float(np.mean(e_ho[0]["current"])), float(np.mean(e_ho[1]["current"]))
    w_before, w_after = float(np.mean(e_ho[0]["velocity"])), float(np.mean(e_ho[1]["velocity"]))
    worse_w = imp_w < -z * se_w and -imp_w > tolerance * w_before
    confirmed = imp > z * se and imp > tolerance * before and not worse_w
    verdict = "confirmed" if confirmed else ("worsens the simulated velocity" if worse_w else "not confirmed")
    sim.update({"channel": "current", "without": before, "with": after, "improvement": imp,
                "noise_floor": z * se, "other_channel": "velocity", "other_channel_change": -imp_w,
                "velocity_without": w_before, "velocity_with": w_after, "verdict": verdict, "windows": len(ho)})
    reason = (f"held-out windows at the limit: simulated current error {before:.3g} -> {after:.3g} A RMS with "
              f"{best} (noise floor {z * se:.2g} A), speed {w_before:.3g} -> {w_after:.3g} rad/s")
    if not confirmed:
        out["rejected"].append({"effect": name, "form": f"{best} instead of {nominal}", "verdict": verdict,
                                "reason": f"{verdict}: {reason}"})
        return out
    out["findings"].append({
        "effect": name,
        "description": "the drive limits the voltage at the circle differently from the model "
                       f"({best}, not {nominal})",
        "form": f"{best} instead of {nominal}",
        "mode": best,
        "parameters": {par.name: best}, "uncertainty": {par.name: None},
        "units": {par.name: par.unit}, "fields": {par.name: par.field},
        "simulated": True,
        "evidence": [f"{len(tr)} training windows at the voltage limit simulated under every mode: relative error "
                     + ", ".join(f"{m} {v:.3f}" for m, v in scores.items()), reason],
        "held_out": {"metric": "simulated current error RMS on held-out windows at the voltage limit", "unit": "A",
                     "before": before, "after": after},
        "metrics": [{"metric": "simulated current error RMS on held-out windows at the voltage limit", "unit": "A",
                     "before": before, "after": after},
                    {"metric": "simulated speed error RMS on held-out windows at the voltage limit",
                     "unit": "rad/s", "before": w_before, "after": w_after}],
        "simulation": sim,
        "updated_fields": {"drive.voltage_limit_mode": best, **(
            {"drive.field_weakening_current_max": variants[best].drive.field_weakening_current_max}
            if best == "field_weakening" else {})},
    })
    return out
