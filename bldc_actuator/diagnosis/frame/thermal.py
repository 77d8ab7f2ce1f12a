"""The two-node thermal network against recorded temperatures: its error (:func:`thermal_error`), the search for
thermal-parameter and extra-heat findings (:func:`thermal_select`) and writing them (:func:`apply_thermal`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ... import effects
from ...params import SPECS, ActuatorParams
from .candidates import Candidate
from ..effects import Route, registry
from .equation_error import Context, thermal_response
from ..significance import THERMAL_FIT_BOUND_LOG
from .writeback import within_limits


# -- thermal --------------------------------------------------------------------------------------

def thermal_error(ctx: Context, params: ActuatorParams, extra_heat: np.ndarray | None = None) -> dict[str, Any]:
    """RMS error [K] of the thermal network (driven by the measured current) against the recorded
    temperatures, on training and held-out samples, starting from the first recorded temperatures."""
    chans = [c for c in ("winding_temperature", "housing_temperature") if c in ctx.have]
    if not chans or "i_q" not in ctx.sig:
        return {"available": False}
    a0 = ctx.segments[0][0]
    T0w = ctx.raw.get("winding_temperature", ctx.raw.get("housing_temperature"))[a0]
    T0h = ctx.raw.get("housing_temperature", ctx.raw.get("winding_temperature"))[a0]
    T_w, T_h = thermal_response(ctx, params, extra_heat=extra_heat, T0=(T0w, T0h))
    out: dict[str, Any] = {"available": True}
    ho = ctx.holdout_raw
    for c, sim in (("winding_temperature", T_w), ("housing_temperature", T_h)):
        if c not in ctx.have:
            continue
        ok = ctx.valid[c]
        e = sim - ctx.raw[c]
        out[c] = {"train_rms": float(np.sqrt(np.mean(e[ok & ~ho] ** 2))) if (ok & ~ho).any() else float("nan"),
                  "holdout_rms": float(np.sqrt(np.mean(e[ok & ho] ** 2))) if (ok & ho).any() else float("nan")}
    out["sim"] = (T_w, T_h)
    return out


# -- thermal candidates (output error: the network is simulated, not differentiated) ------------------

_THERMAL_FIELDS = ("winding_to_housing_resistance", "housing_to_ambient_resistance", "winding_heat_capacity",
                   "housing_heat_capacity")


def _thermal_resid(ctx: Context, params: ActuatorParams, extra_heat, every: int):
    chans = [c for c in ("winding_temperature", "housing_temperature") if c in ctx.have]
    a0 = ctx.segments[0][0]
    T0w = ctx.raw.get("winding_temperature", ctx.raw.get("housing_temperature"))[a0]
    T0h = ctx.raw.get("housing_temperature", ctx.raw.get("winding_temperature"))[a0]
    T_w, T_h = thermal_response(ctx, params, extra_heat=extra_heat, T0=(T0w, T0h), every=every)
    idx = np.arange(0, len(ctx.t), every)
    parts, hos = [], []
    for c, sim in (("winding_temperature", T_w), ("housing_temperature", T_h)):
        if c in chans:
            ok = ctx.valid[c][idx]
            parts.append(np.where(ok, sim[idx] - ctx.raw[c][idx], np.nan))
            hos.append(ctx.holdout_raw[idx])
    return np.concatenate(parts), np.concatenate(hos), np.concatenate([ctx.t[idx]] * len(parts))


def thermal_select(ctx: Context, names: list[str], lib: dict[str, Candidate], gate) -> dict[str, Any]:
    """thermal_parameters and iron_loss: least-squares fits of the simulated temperatures (nominal network,
    measured current) to the recorded ones, gated like the others (ΔBIC with the effective sample count,
    held-out improvement)."""
    from scipy.optimize import least_squares

    from .equation_error import integrated_autocorrelation_time

    out: dict[str, Any] = {"findings": [], "rejected": [], "not_checkable": [], "extra_heat": None}
    if not names:
        return out
    temps = [c for c in ("winding_temperature", "housing_temperature") if c in ctx.have]
    for n in names:
        miss = [x for x in lib[n].needs if not any(y in ctx.have for y in x.split("|"))]
        if miss:
            out["not_checkable"].append({"effect": n, "reason": f"needs {', '.join(m.replace('|', ' or ') for m in miss)}",
                                         "needs": miss})
    names = [n for n in names if n not in {x["effect"] for x in out["not_checkable"]}]
    if not names:
        return out
    span = max(float(np.nanmax(ctx.raw[c]) - np.nanmin(ctx.raw[c])) for c in temps)
    if span < 3.0:
        for n in names:
            out["not_checkable"].append({"effect": n, "reason": f"data does not excite it: needs a temperature change "
                                         f"of a few K (recorded span {span:.1f} K)", "needs": []})
        return out
    every = max(1, int(ctx.fs / 2.0))     # 0.5 s steps: exact for the step-mean power, far below thermal time constants
    p0 = ctx.params
    w = ctx.sig.get("omega", np.zeros(len(ctx.t)))

    def params_with(x):
        th = p0.thermal
        vals = {f"thermal.{f}": getattr(th, f) * math.exp(v) for f, v in zip(_THERMAL_FIELDS, x)}
        return p0.replace(**vals)

    def heat(k):
        return effects.iron_loss_power(w, abs(k[0]), abs(k[1]))   # the simulator's iron-loss power

    def stats(r, ho):
        ok = np.isfinite(r)
        tr = r[ok & ~ho]
        return float(tr @ tr), int(len(tr)), integrated_autocorrelation_time(tr) if len(tr) > 8 else 1.0

    r0, ho, tt = _thermal_resid(ctx, p0, None, every)
    base_rss, n, _ = stats(r0, ho)
    state = {"x": np.zeros(4), "k": np.zeros(2), "r": r0, "rss": base_rss, "k_params": 0}
    for rnd in range(2):
        evals = []
        for name in names:
            if any(f["effect"] == name for f in out["findings"]):
                continue
            if not registry.get(name).motion_heat:      # the network itself (else a heat source driven by motion)
                def f(x):
                    r, _, _ = _thermal_resid(ctx, params_with(x), heat(state["k"]) if state["k"].any() else None, every)
                    r = r[~ho]
                    return np.nan_to_num(r)
                sol = least_squares(f, state["x"], bounds=(-THERMAL_FIT_BOUND_LOG, THERMAL_FIT_BOUND_LOG), x_scale=0.3,
                                    max_nfev=40)
                r1, _, _ = _thermal_resid(ctx, params_with(sol.x), heat(state["k"]) if state["k"].any() else None, every)
                evals.append((name, sol, r1, 4))
            else:
                scale = max(float(np.mean(np.abs(w))), 1e-3)
                def f(k):
                    r, _, _ = _thermal_resid(ctx, params_with(state["x"]), heat(k), every)
                    return np.nan_to_num(r[~ho])
                sol = least_squares(f, np.array([1e-4, 1e-7]), bounds=(0, np.inf),
                                    x_scale=np.array([1.0 / scale, 1.0 / scale ** 2]) * 0.1, max_nfev=40)
                r1, _, _ = _thermal_resid(ctx, params_with(state["x"]), heat(sol.x), every)
                evals.append((name, sol, r1, 2))
        best = None
        for name, sol, r1, k in evals:
            rss1, n1, tau = stats(r1, ho)
            n_eff = max(2.0, n1 / tau)
            dbic = n_eff * math.log(state["rss"] / max(rss1, 1e-300)) - k * math.log(n_eff)
            okh = np.isfinite(r1) & ho
            e0 = np.sqrt(np.mean(state["r"][okh] ** 2)) if okh.any() else float("nan")
            e1 = np.sqrt(np.mean(r1[okh] ** 2)) if okh.any() else float("nan")
            rel = 1.0 - e1 / e0 if e0 > 0 else 0.0
            passed = dbic > gate.bic_threshold and rel > max(gate.min_heldout_gain, 0.05)
            reason = (f"passed: ΔBIC {dbic:.1f}, held-out temperature error -{100 * rel:.1f}%" if passed else
                      f"ΔBIC {dbic:.1f}, held-out temperature error {-100 * rel:+.1f}% (needs ΔBIC > "
                      f"{gate.bic_threshold:g} and > 5% held-out gain)")
            rec = {"name": name, "sol": sol, "r": r1, "rss": rss1, "dbic": dbic, "rel": rel, "e0": e0, "e1": e1,
                   "passed": passed, "reason": reason}
            if passed and (best is None or rel > best["rel"]):
                best = rec
            elif not passed:
                out["rejected"] = [x for x in out["rejected"] if x["effect"] != name]
                out["rejected"].append({"effect": name, "form": "thermal output error", "reason": reason,
                                        "delta_bic": round(dbic, 2), "heldout_gain": round(rel, 4)})
        if best is None:
            break
        out["rejected"] = [x for x in out["rejected"] if x["effect"] != best["name"]]
        sol = best["sol"]
        J = sol.jac
        s2 = best["rss"] / max(1, len(sol.fun) - J.shape[1])
        cov = np.linalg.pinv(J.T @ J) * s2
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
        if not registry.get(best["name"]).motion_heat:
            state["x"] = sol.x
            th = p0.thermal
            pars = {f: getattr(th, f) * math.exp(v) for f, v in zip(_THERMAL_FIELDS, sol.x)}
            unc = {f: pars[f] * s for f, s in zip(_THERMAL_FIELDS, sd)}
            units = dict(zip(_THERMAL_FIELDS, ("K/W", "K/W", "J/K", "J/K")))
            fields = {f: f"thermal.{f}" for f in _THERMAL_FIELDS}
        else:
            state["k"] = np.abs(sol.x)
            pars = {"hysteresis_loss_coefficient": float(state["k"][0]), "eddy_loss_coefficient": float(state["k"][1])}
            unc = {"hysteresis_loss_coefficient": float(sd[0]), "eddy_loss_coefficient": float(sd[1])}
            units = {"hysteresis_loss_coefficient": "W*s/rad", "eddy_loss_coefficient": "W*s^2/rad^2"}
            fields = {"hysteresis_loss_coefficient": "effects.iron_loss_hysteresis",
                      "eddy_loss_coefficient": "effects.iron_loss_eddy"}
            out["extra_heat"] = heat(state["k"])
        state["r"], state["rss"] = best["r"], best["rss"]
        out["findings"].append({
            "effect": best["name"], "description": lib[best["name"]].description, "form": "thermal output error",
            "parameters": pars, "uncertainty": unc, "units": units, "fields": fields,
            "simulated": True,
            "evidence": [f"temperature simulated from the measured current misses the recording by "
                         f"{best['e0']:.2f} K RMS on held-out data", best["reason"]],
            "held_out": {"metric": "temperature error RMS (held-out)", "unit": "K", "before": best["e0"],
                         "after": best["e1"]},
            "metrics": [{"metric": "temperature error RMS (held-out)", "unit": "K", "before": best["e0"],
                         "after": best["e1"]}],
            "delta_bic": best["dbic"], "round": rnd + 1, "correlations": []})
    return out


def apply_thermal(params: ActuatorParams, thermal: dict[str, Any]):
    notes, not_sim = [], []
    flat = {}
    for f in thermal["findings"]:
        if f.get("updated_fields"):          # categorical settings (drive.voltage_limit_mode), written as found
            flat.update(f["updated_fields"])
        elif registry.get(f["effect"]).route in (Route.THERMAL, Route.VOLTAGE_LIMIT) and f.get("simulated"):
            for name, fld in f["fields"].items():
                flat[fld] = within_limits(SPECS[fld], f["parameters"][name], notes, fld)
            if registry.get(f["effect"]).motion_heat:
                # the nominal friction and damping already hold the total drag a test measured: the iron terms
                # take their share of it (and heat the stator), the rest stays friction
                b = params.motor.viscous_damping - flat["effects.iron_loss_eddy"]
                tc = params.effects.coulomb_friction - flat["effects.iron_loss_hysteresis"]
                flat["motor.viscous_damping"] = max(b, 0.0)
                flat["effects.coulomb_friction"] = max(tc, 0.0)
                if b < 0 or tc < 0:
                    notes.append("iron_loss: its drag exceeds the nominal damping/friction; those set to 0, the "
                                 "simulated drag is now larger than nominal")
        else:
            not_sim.append(f["effect"])
    if flat:
        try:
            params = params.replace(**flat)
        except Exception as exc:  # noqa: BLE001
            notes.append(f"thermal parameters rejected by the schema ({exc}); nominal kept")
    return params, notes, not_sim
