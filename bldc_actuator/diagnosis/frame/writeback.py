"""The accepted effects written back: their joint final fit with uncertainties (:func:`final_fit`), each effect's
parameters in the simulator's units (:func:`effect_parameters`) and the updated parameter file
(:func:`updated_params`: fields clipped only into their physical limits, a note outside the usual range; effects
without schema fields listed as not simulated)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ... import frames
from ...params import SPECS, from_flat, keep_controller_of, outside_usual_range
from .candidates import Candidate
from .combination import Combination, collinear
from ..effects import WriteBack, registry
from .equation_error import Context, Fit
from .selection import SelectionResult, fit_model


# -- final fit --------------------------------------------------------------------------------------

@dataclass
class FinalFit:
    fit: Fit
    keys: list[str]
    beta: np.ndarray
    cov: np.ndarray
    nonlinear: dict[str, dict[str, float]] = field(default_factory=dict)   #: effect -> {name: value, name_sd: sd}
    correlations: list[dict[str, Any]] = field(default_factory=list)
    #: pairs of accepted columns whose estimates correlate beyond combination.COLLINEAR (column keys, the
    #: coefficients' combination): reported and written back as their combination (:func:`effect_parameters`)
    combinations: list[Combination] = field(default_factory=list)
    #: the same in the report's words (:func:`combinations_report`, filled by :func:`effect_parameters`)
    combined: list[dict[str, Any]] = field(default_factory=list)


def _stacked(ctx: Context, cols, keys, weights):
    ho = ctx.holdout_dec
    Xs, ys = [], []
    for eq, B in ctx.blocks.items():
        rows = B.rows(ho, "train")
        X = np.zeros((int(rows.sum()), len(keys)))
        for j, k in enumerate(keys):
            c = cols[k].get(eq)
            if c is not None:
                X[:, j] = c[rows]
        Xs.append(weights[eq] * X)
        ys.append(weights[eq] * B.target[rows])
    return np.vstack(Xs), np.concatenate(ys)


def final_fit(ctx: Context, sel: SelectionResult) -> FinalFit:
    from scipy.optimize import minimize_scalar

    from .equation_error import integrated_autocorrelation_time

    cols = dict(sel.cols)
    keys = list(ctx.nuisance) + [k for a in sel.accepted for k in a.added]
    weights = sel.weights
    nl_info: dict[str, dict[str, float]] = {}
    nl_cols: list[tuple[str, str, Any]] = []     # (effect, key, rebuild)
    for a in sel.accepted:
        for name, (value, lo, hi, rebuild) in a.variant.nonlinear.items():
            key = [k for k in a.added if k in a.variant.columns]
            if not key:
                continue
            key = key[0]

            def rss_at(logv, key=key, rebuild=rebuild):
                builders = rebuild(ctx, math.exp(logv))
                b = next(iter(builders.values()))
                cols[key] = ctx.column(("nl", key, round(logv, 9)), b)
                f = fit_model(ctx, cols, keys, weights, sel.iterating)
                return sum(f.rss[eq] * weights[eq] ** 2 for eq in f.rss)

            res = minimize_scalar(rss_at, bounds=(math.log(lo), math.log(hi)), method="bounded",
                                  options={"xatol": 0.02, "maxiter": 25})
            best = math.exp(res.x)
            rss_at(res.x)
            nl_info[a.effect] = {name: best}
            nl_cols.append((a.effect, key, (name, best, rebuild)))
    fit = fit_model(ctx, cols, keys, weights, sel.iterating)
    cov = fit.cov
    # joint covariance including nonlinear parameters (numerical Jacobian column per nonlinear parameter)
    if nl_cols and keys:
        X, y = _stacked(ctx, cols, keys, weights)
        J = [X]
        for effect, key, (name, best, rebuild) in nl_cols:
            h = 0.02
            b = next(iter(rebuild(ctx, best * math.exp(h)).values()))
            c_hi = ctx.column(("nl", key, "hi", h), b)
            tmp = dict(cols)
            tmp[key] = c_hi
            X_hi, _ = _stacked(ctx, tmp, keys, weights)
            j = keys.index(key)
            dcol = (X_hi[:, j] - X[:, j]) / (best * (math.exp(h) - 1.0))
            J.append((fit.beta[j] * dcol)[:, None])
        Jm = np.hstack(J)
        r = y - X @ fit.beta
        s2 = float(r @ r) / max(1, len(y) - Jm.shape[1])
        taus = [integrated_autocorrelation_time(fit.resid[eq][ctx.blocks[eq].rows(ctx.holdout_dec, "train")])
                for eq in ctx.blocks]
        scale = np.sqrt((Jm ** 2).sum(axis=0))
        scale[scale == 0] = 1.0
        full = np.linalg.pinv((Jm / scale).T @ (Jm / scale)) / np.outer(scale, scale) * s2 * float(np.mean(taus))
        cov = full[: len(keys), : len(keys)]
        for n_i, (effect, key, (name, best, _)) in enumerate(nl_cols):
            idx = len(keys) + n_i
            nl_info[effect][name + "_sd"] = float(math.sqrt(max(full[idx, idx], 0.0)))
            # correlation of the nonlinear parameter with its amplitude
            j = keys.index(key)
            den = math.sqrt(max(full[idx, idx] * full[j, j], 1e-300))
            nl_info[effect][name + "_corr_amplitude"] = float(full[idx, j] / den)
    corr = []
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    for i in range(len(keys)):
        for j in range(i + 1, len(keys)):
            if sd[i] > 0 and sd[j] > 0:
                c = cov[i, j] / (sd[i] * sd[j])
                if abs(c) > 0.9:
                    corr.append({"a": keys[i], "b": keys[j], "correlation": round(float(c), 3)})
    # pairs of two accepted effects (within one effect its form's parametrisation is its own: the forms offered are
    # the ones the recording identifies, and e.g. a spring's zero offset is well determined however it correlates)
    owner = {k: a.effect for a in sel.accepted for k in a.added}
    combos = []
    if len(set(owner.values())) >= 2:
        X, _ = _stacked(ctx, cols, keys, weights)
        combos = [c for c in collinear(keys, fit.beta, cov, X, among=list(owner))
                  if owner[c.parameters[0]] != owner[c.parameters[1]]]
    return FinalFit(fit, keys, fit.beta, cov, nl_info, corr, combos)


# -- parameter mapping ------------------------------------------------------------------------------

def _combined(ff: FinalFit) -> tuple[np.ndarray, np.ndarray]:
    """The final fit's coefficients and covariance with each not-separable pair written as its combination:
    the first column carries ``c = b_p + a b_q`` (its variance the combination's), the second its nominal (no
    change: the data did not determine it)."""
    beta, cov = np.array(ff.beta, float), np.array(ff.cov, float)
    if not ff.combinations:
        return beta, cov
    idx = {k: i for i, k in enumerate(ff.keys)}
    T = np.eye(len(beta))
    for c in ff.combinations:
        p, q = idx[c.parameters[0]], idx[c.parameters[1]]
        T[p, q] = c.a
        T[q, q] = 0.0
    return T @ beta, T @ cov @ T.T


def _names_of(cand: Candidate, coef, cov, keys, variant, ctx, key: str) -> list[str]:
    """The parameters of one effect that its column ``key`` moves (a probe of its mapping)."""
    j = keys.index(key)
    base = cand.to_params(coef, cov, keys, variant, ctx)
    step = np.array(coef, float)
    step[j] += max(abs(step[j]), 1e-6)
    moved = cand.to_params(step, cov, keys, variant, ctx)
    return [n for n, v in base.items() if not n.startswith("_") and isinstance(v.get("value"), (int, float))
            and n in moved and moved[n].get("value") != v.get("value")]


def combinations_report(ctx: Context, sel: SelectionResult, ff: FinalFit, lib: dict[str, Candidate],
                        pars: dict[str, dict]) -> list[dict[str, Any]]:
    """The not-separable pairs of the final fit in the report's words: which effects' parameters they combine,
    the combination's value and sd in the first parameter's units, and what was written back."""
    if not ff.combinations:
        return []
    owner = {k: a for a in sel.accepted for k in a.added}
    beta, cov = _combined(ff)
    idx = {k: i for i, k in enumerate(ff.keys)}
    out = []
    for c in ff.combinations:
        kp, kq = c.parameters
        ap, aq = owner[kp], owner[kq]
        names = []
        for a, k in ((ap, kp), (aq, kq)):
            ii = [idx[x] for x in a.added]
            try:
                found = _names_of(lib[a.effect], beta[ii], cov[np.ix_(ii, ii)], a.added, a.variant, ctx, k)
            except (ValueError, KeyError, IndexError, TypeError, ZeroDivisionError):
                found = []      # a mapping that cannot be probed: the column's own key names it
            names.append((a.effect, found[0] if found else k))
        (ep, np_), (eq, nq) = names
        vp = pars.get(ep, {}).get(np_, {})
        vq = pars.get(eq, {}).get(nq, {})
        value = (vp.get("value", float("nan")) + c.a * vq.get("value", float("nan")))
        sym = {"p": f"{ep}.{np_}", "q": f"{eq}.{nq}"}
        rec = {"parameters": [sym["p"], sym["q"]], "columns": [kp, kq], "correlation": c.correlation, "a": c.a,
               "value": value, "sd": vp.get("sd", c.sd), "unit": vp.get("unit", ""),
               "written_back": f"{sym['q']} kept at its nominal value {vq.get('value', float('nan')):.4g}; "
                               f"{sym['p']} = {vp.get('value', float('nan')):.4g} carries the combination (the "
                               f"model simulates the recording as the fit does; the split is not determined)"}
        rec["message"] = (f"{sym['p']} and {sym['q']} are not separable with this data (their fitted estimates "
                          f"correlate {c.correlation:+.4f}): the data pin {sym['p']} + {c.a:.4g}·{sym['q']} = "
                          f"{value:.4g} ± {rec['sd']:.2g} {rec['unit']}".rstrip() + f"; {rec['written_back']}")
        for e, n, other in ((ep, np_, sym["q"]), (eq, nq, sym["p"])):
            if n in pars.get(e, {}):
                pars[e][n]["combined_with"] = other
        if nq in pars.get(eq, {}):
            pars[eq][nq]["held_at_nominal"] = True
            pars[eq][nq]["sd"] = float("nan")
        out.append(rec)
    return out


def effect_parameters(ctx: Context, sel: SelectionResult, ff: FinalFit, lib: dict[str, Candidate]):
    """Per accepted effect: parameters (value, sd, unit, field) in natural units. A pair of columns the data
    cannot separate (``ff.combinations``) is mapped as its combination: the first carries it, the second keeps
    its nominal value (:func:`_combined`)."""
    out = {}
    idx = {k: i for i, k in enumerate(ff.keys)}
    beta_c, cov_c = _combined(ff)
    for a in sel.accepted:
        ii = [idx[k] for k in a.added]
        coef = beta_c[ii]
        cov = cov_c[np.ix_(ii, ii)]
        cand = lib[a.effect]
        # the refined continuous hyper-parameters (final_fit) are what the parameters derive from
        refined = {n: v for n, v in ff.nonlinear.get(a.effect, {}).items() if n in a.variant.hyper}
        variant = dataclasses.replace(a.variant, hyper={**a.variant.hyper, **refined}) if refined else a.variant
        pars = cand.to_params(coef, cov, a.added, variant, ctx)
        for name, info in ff.nonlinear.get(a.effect, {}).items():
            if name.endswith("_sd") or name.endswith("_corr_amplitude"):
                continue
            if name in pars:     # mapped by the candidate itself (e.g. the dead time's current band): its sd
                pars[name]["sd"] = ff.nonlinear[a.effect].get(name + "_sd", float("nan"))
                continue
            fld = "effects.stribeck_velocity" if name == "omega_s" else None
            pars["stribeck_velocity" if name == "omega_s" else name] = {
                "value": info, "sd": ff.nonlinear[a.effect].get(name + "_sd", float("nan")),
                "unit": "rad/s" if name == "omega_s" else "", "field": fld}
        out.setdefault(a.effect, {}).update(pars)
    _rescale_by_torque_constant(out, lib)
    ff.combined = combinations_report(ctx, sel, ff, lib, out)
    return out


#: units of torque-side parameters: fitted in current units (torque / K) they carry the K they were divided by
_TORQUE_UNITS = ("N*m", "N*m*s/rad", "N*m*s^2/rad^2", "N*m/rad", "kg*m^2")


def _rescale_by_torque_constant(pars: dict[str, dict], lib: dict[str, Candidate]) -> None:
    """The mechanical equation is fitted in current units (every torque divided by the NOMINAL K). With a
    torque-constant finding κ = K_true / K the model's torque is κ K i, so every torque-side parameter fitted
    alongside (friction, damping, cogging, loads, inertia change) is κ times its current-unit coefficient;
    without this the updated parameters simulate friction 1/κ too small (issue #7, symptom 2)."""
    scale = registry.torque_scale().name
    kt = pars.get(scale, {}).get("ratio_to_nominal", {})
    kappa = kt.get("value")
    if not isinstance(kappa, (int, float)) or not math.isfinite(kappa) or kappa <= 0:
        return
    for effect, ps in pars.items():
        if effect == scale or "mechanical" not in lib[effect].equations:
            continue
        for name, info in ps.items():
            if info.get("unit") not in _TORQUE_UNITS or not isinstance(info.get("value"), (int, float)):
                continue
            if isinstance(info.get("delta"), (int, float)):     # nominal + fitted change: the change scales
                info["value"] = info["value"] + (kappa - 1.0) * info["delta"]
                info["delta"] = info["delta"] * kappa
            else:                                               # a fitted magnitude (no nominal part)
                info["value"] = info["value"] * kappa
            if isinstance(info.get("sd"), (int, float)):
                info["sd"] = info["sd"] * kappa
            info["scaled_by_torque_constant"] = kappa


def sensor_offsets_for_q_ripple(c: float, s: float) -> tuple[float, float]:
    """Phase-a/b current-sensor offsets [A] whose measured q-current error is ``c cos θ_e + s sin θ_e`` (the
    fitted order-p ripple): the error is linear in the offsets, so two angles of
    :func:`bldc_actuator.frames.abc_to_dq` (the transform the simulated controller uses) give the 2 x 2 map."""
    def e_q(o_a, o_b, th):
        return float(frames.abc_to_dq(o_a, o_b, -(o_a + o_b), th)[1])

    M = np.array([[e_q(1.0, 0.0, 0.0), e_q(0.0, 1.0, 0.0)],
                  [e_q(1.0, 0.0, math.pi / 2), e_q(0.0, 1.0, math.pi / 2)]])
    o_a, o_b = np.linalg.solve(M, np.array([c, s]))
    return float(o_a), float(o_b)


def sensor_gains_for_q_ripple(c: float, s: float) -> tuple[float, float, float]:
    """Phase-a/b current-sensor gain errors (gain = 1 + δ) for a fitted order-2p ripple of the measured q current
    per ampere, ``c cos 2θ_e + s sin 2θ_e``. Returns ``(δ_a, δ_b, share)``.

    With phase c reconstructed from a and b (as the drive does), a gain error's 2θ_e part is fixed in phase and
    depends on the difference δ_a - δ_b only: the common part is a constant scale of the measured current, one
    with a torque-constant error, and is left at zero here (δ_a = -δ_b). ``share`` is the fraction of the
    fitted ripple's power a gain mismatch can explain (its projection on that one direction; the rest is another
    order-2p source). The 2θ_e components come from :func:`bldc_actuator.frames.abc_to_dq` of the mis-scaled
    phase currents."""
    th = np.linspace(0.0, 2.0 * math.pi, 64, endpoint=False)
    a, b, _ = frames.dq_to_abc(0.0, 1.0, th)
    e_q = frames.abc_to_dq(0.5 * a, -0.5 * b, -(0.5 * a - 0.5 * b), th)[1]    # δ_a - δ_b = 1
    u = np.array([np.mean(e_q * np.cos(2 * th)), np.mean(e_q * np.sin(2 * th))]) * 2.0
    y = np.array([c, s])
    diff = float(y @ u / (u @ u))
    share = float((diff * diff * (u @ u)) / (y @ y)) if y @ y > 0 else 0.0
    return 0.5 * diff, -0.5 * diff, share


def within_limits(spec, v, notes: list[str], fld: str):
    """A fitted value for field ``spec``: clipped into its PHYSICAL limits only (a negative friction, a modulation
    limit above 1), with a note; outside the usual (sanity) range it is written as fitted, with a note (issue
    #14: a 95 kg axis's 203.5 N s/m is real)."""
    lo, hi, lo_open = spec.limits
    lo_eff = lo if not lo_open else (lo + abs(lo) * 1e-9 + 1e-300)
    clipped = min(max(v, lo_eff), hi)
    if clipped != v:
        notes.append(f"{fld}: fitted {v:.4g} clipped into its physical limits [{lo:g}, {hi:g}] {spec.unit}")
        v = clipped
    if outside_usual_range(spec, v):
        notes.append(f"{fld}: {v:.4g} {spec.unit} written as fitted, outside the usual range "
                     f"[{spec.range[0]:g}, {spec.range[1]:g}] (a sanity limit, not physics)")
    return v


def updated_params(ctx: Context, sel: SelectionResult, pars: dict[str, dict], lib: dict[str, Candidate]):
    """New :class:`ActuatorParams` with the accepted effects switched on; returns (params, notes, not_simulated)."""
    flat = ctx.params.to_flat()
    flat.update(ctx.drive_updates)      # the drive's settings identified from the recording (drive_feedforward)
    notes: list[str] = []
    not_sim: list[str] = []
    accepted = [a.effect for a in sel.accepted]
    cogging_written = any(registry.get(e).writeback is WriteBack.COGGING_SERIES for e in accepted)
    for a in sel.accepted:
        cand = lib[a.effect]
        eff = registry.get(a.effect)
        p = pars[a.effect]
        kind = a.variant.hyper.get("kind")
        if eff.writeback is WriteBack.CURRENT_SENSORS and kind == "offset":
            o_a, o_b = sensor_offsets_for_q_ripple(p["_offset_cos"]["value"], p["_offset_sin"]["value"])
            flat["drive.current_sensor_offset_a"] = flat["drive.current_sensor_offset_a"] + o_a
            flat["drive.current_sensor_offset_b"] = flat["drive.current_sensor_offset_b"] + o_b
            notes.append(f"electrical_angle_ripple (current-sensor offsets) written as drive.current_sensor_offset_a/_b "
                         f"+= {o_a:.4g} / {o_b:.4g} A: the simulated controller acts on the offset measurement")
            continue
        if eff.writeback is WriteBack.CURRENT_SENSORS and kind == "gain":
            d_a, d_b, share = sensor_gains_for_q_ripple(p["_gain_cos"]["value"], p["_gain_sin"]["value"])
            flat["drive.current_sensor_gain_a"] = flat["drive.current_sensor_gain_a"] + d_a
            flat["drive.current_sensor_gain_b"] = flat["drive.current_sensor_gain_b"] + d_b
            notes.append(f"electrical_angle_ripple (current-sensor gain mismatch) written as "
                         f"drive.current_sensor_gain_a/_b += {d_a:.4g} / {d_b:.4g} (their difference; a common "
                         f"scale of both is a torque-constant error): the simulated controller acts on the "
                         f"mis-scaled measurement; a gain mismatch explains {100 * share:.0f} % of the fitted ripple")
            continue
        if eff.writeback is WriteBack.CURRENT_SENSORS:
            if a.variant.hyper.get("kind") == "torque" and not cogging_written \
                    and not ctx.params.effects.cogging_order:
                o = a.variant.hyper["order"]
                flat["effects.cogging_order"] = o
                flat["effects.cogging_cos"] = (p["_torque_cos"]["value"],)
                flat["effects.cogging_sin"] = (p["_torque_sin"]["value"],)
                notes.append(f"electrical_angle_ripple (order {o}, current-independent) written as a cogging-like "
                             f"term effects.cogging_order={o}")
            else:
                not_sim.append(a.effect)
            continue
        if not cand.simulated:
            not_sim.append(a.effect)
            continue
        if eff.writeback is WriteBack.COGGING_SERIES:
            o = a.variant.hyper["order"]
            nh = a.variant.hyper["harmonics"]
            e = ctx.params.effects
            base_c = list(e.cogging_cos) if e.cogging_order == o else []
            base_s = list(e.cogging_sin) if e.cogging_order == o else []
            n = max(nh, len(base_c))
            cc = [(base_c[k] if k < len(base_c) else 0.0) + p.get(f"cogging_cos_{k + 1}", {}).get("value", 0.0)
                  for k in range(n)]
            ss = [(base_s[k] if k < len(base_s) else 0.0) + p.get(f"cogging_sin_{k + 1}", {}).get("value", 0.0)
                  for k in range(n)]
            flat["effects.cogging_order"] = o
            flat["effects.cogging_cos"] = tuple(cc)
            flat["effects.cogging_sin"] = tuple(ss)
            continue
        if eff.replay_form and ctx.dead_time_sign:
            flat["drive.dead_time_sign"] = ctx.dead_time_sign     # the converter form the replay identified
        for flag in eff.enables:
            flat[flag] = True
        for name, info in p.items():
            fld = info.get("field")
            if not fld or fld not in SPECS:
                continue
            spec = SPECS[fld]
            v = info["value"]
            if spec.type is int:
                v = int(round(v))
            if spec.type in (int, float):
                v = within_limits(spec, v, notes, fld)
            flat[fld] = v
    for e in dict.fromkeys(accepted):
        gives = registry.get(e).takes_from_rotor_inertia
        if gives is None or not flat.get("gear.transmission_stiffness", 0.0) > 0.0:
            continue
        # the rigid model's rotor inertia held the load: the rotor side keeps the rest (after any inertia finding)
        j_ref = pars[e][gives]["value"]
        flat["motor.rotor_inertia"] = flat["motor.rotor_inertia"] - j_ref
        notes.append(f"{e}: motor.rotor_inertia -= {j_ref:.4g} kg*m^2 (the load, now "
                     f"gear.load_inertia behind the spring)")
    try:
        newp = from_flat(flat)
    except Exception as exc:  # noqa: BLE001 - a fitted value the schema refuses: keep the nominal, say why
        notes.append(f"updated parameters rejected by the schema ({exc}); nominal kept")
        newp = ctx.params
    pinned = keep_controller_of(newp, ctx.params)
    if pinned is not newp:
        notes.append("drive.controller_* kept at the nominal motor values: the recorded drive's current loop was "
                     "tuned on them, a finding changes the motor, not the drive")
    return pinned, notes, not_sim
