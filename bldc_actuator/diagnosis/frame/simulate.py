"""Model the accepted effects: final fit with uncertainties, the updated parameter file, and re-simulation.

* :func:`final_fit` — the selected columns fitted jointly; continuous hyper-parameters (the Stribeck
  velocity) refined by bounded 1-D search; covariance of every parameter from the Jacobian of the weighted
  residual (inflated by the residual's correlation time); correlations above 0.9 flagged.
* :func:`updated_params` — accepted effects written onto :class:`~bldc_actuator.params.ActuatorParams` fields
  as fitted (clipped only into a field's physical limits; outside its usual range with a note: bounds are
  sanity limits); effects without schema fields are listed as not simulated.
* :func:`replay` — multiple shooting: the recording cut into short windows, each simulated by the
  :class:`~bldc_actuator.model.BatchActuator` (all windows and parameter sets in ONE batch) from the state
  measured at the window start, driven by the recorded commands and load (interpolated between the samples of
  a log slower than the joint controller); current, speed, angle and q-voltage errors (the voltage at the
  recorded speed: the mechanical replay's back-EMF error removed). Each window starts in the simulated drive's
  own steady state (:func:`window_start`); ``drive="current"`` replays the mechanical equation driven by the
  measured current instead (nothing of the drive's internals needed).
* :func:`thermal_error` — the two-node thermal network driven by the measured current vs recorded
  temperatures.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.signal as sps

from ... import effects, frames
from ...model import BatchActuator
from ...params import SPECS, ActuatorParams, controller_motor, from_flat, keep_controller_of, outside_usual_range
from .candidates import Candidate
from .equation_error import CommandReplay, Context, Fit, thermal_response
from .selection import SelectionResult, fit_model
from .transmission import window_load_states
from ..significance import THERMAL_FIT_BOUND_LOG


# -- final fit --------------------------------------------------------------------------------------

@dataclass
class FinalFit:
    fit: Fit
    keys: list[str]
    beta: np.ndarray
    cov: np.ndarray
    nonlinear: dict[str, dict[str, float]] = field(default_factory=dict)   #: effect -> {name: value, name_sd: sd}
    correlations: list[dict[str, Any]] = field(default_factory=list)


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
    return FinalFit(fit, keys, fit.beta, cov, nl_info, corr)


# -- parameter mapping ------------------------------------------------------------------------------

def effect_parameters(ctx: Context, sel: SelectionResult, ff: FinalFit, lib: dict[str, Candidate]):
    """Per accepted effect: parameters (value, sd, unit, field) in natural units."""
    out = {}
    idx = {k: i for i, k in enumerate(ff.keys)}
    for a in sel.accepted:
        ii = [idx[k] for k in a.added]
        coef = ff.beta[ii]
        cov = ff.cov[np.ix_(ii, ii)]
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
    return out


#: units of torque-side parameters: fitted in current units (torque / K) they carry the K they were divided by
_TORQUE_UNITS = ("N*m", "N*m*s/rad", "N*m*s^2/rad^2", "N*m/rad", "kg*m^2")


def _rescale_by_torque_constant(pars: dict[str, dict], lib: dict[str, Candidate]) -> None:
    """The mechanical equation is fitted in current units (every torque divided by the NOMINAL K). With a
    torque-constant finding κ = K_true / K the model's torque is κ K i, so every torque-side parameter fitted
    alongside (friction, damping, cogging, loads, inertia change) is κ times its current-unit coefficient;
    without this the updated parameters simulate friction 1/κ too small (issue #7, symptom 2)."""
    kt = pars.get("torque_constant_error", {}).get("ratio_to_nominal", {})
    kappa = kt.get("value")
    if not isinstance(kappa, (int, float)) or not math.isfinite(kappa) or kappa <= 0:
        return
    for effect, ps in pars.items():
        if effect == "torque_constant_error" or "mechanical" not in lib[effect].equations:
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


def _within_limits(spec, v, notes: list[str], fld: str):
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
    for a in sel.accepted:
        cand = lib[a.effect]
        p = pars[a.effect]
        kind = a.variant.hyper.get("kind")
        if a.effect == "electrical_angle_ripple" and kind == "offset":
            o_a, o_b = sensor_offsets_for_q_ripple(p["_offset_cos"]["value"], p["_offset_sin"]["value"])
            flat["drive.current_sensor_offset_a"] = flat["drive.current_sensor_offset_a"] + o_a
            flat["drive.current_sensor_offset_b"] = flat["drive.current_sensor_offset_b"] + o_b
            notes.append(f"electrical_angle_ripple (current-sensor offsets) written as drive.current_sensor_offset_a/_b "
                         f"+= {o_a:.4g} / {o_b:.4g} A: the simulated controller acts on the offset measurement")
            continue
        if a.effect == "electrical_angle_ripple" and kind == "gain":
            d_a, d_b, share = sensor_gains_for_q_ripple(p["_gain_cos"]["value"], p["_gain_sin"]["value"])
            flat["drive.current_sensor_gain_a"] = flat["drive.current_sensor_gain_a"] + d_a
            flat["drive.current_sensor_gain_b"] = flat["drive.current_sensor_gain_b"] + d_b
            notes.append(f"electrical_angle_ripple (current-sensor gain mismatch) written as "
                         f"drive.current_sensor_gain_a/_b += {d_a:.4g} / {d_b:.4g} (their difference; a common "
                         f"scale of both is a torque-constant error): the simulated controller acts on the "
                         f"mis-scaled measurement; a gain mismatch explains {100 * share:.0f} % of the fitted ripple")
            continue
        if a.effect == "electrical_angle_ripple":
            if a.variant.hyper.get("kind") == "torque" and "cogging_torque" not in accepted \
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
        if a.effect == "cogging_torque":
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
        if a.effect == "resistance_temperature":
            flat["motor.resistance_temperature_enabled"] = True
        if a.effect == "magnet_temperature":
            flat["motor.magnet_temperature_enabled"] = True
        for name, info in p.items():
            fld = info.get("field")
            if not fld or fld not in SPECS:
                continue
            spec = SPECS[fld]
            v = info["value"]
            if spec.type is int:
                v = int(round(v))
            if spec.type in (int, float):
                v = _within_limits(spec, v, notes, fld)
            flat[fld] = v
    if "transmission_compliance" in accepted and flat.get("gear.transmission_stiffness", 0.0) > 0.0:
        # the rigid model's rotor inertia held the load: the rotor side keeps the rest (after any inertia finding)
        j_ref = pars["transmission_compliance"]["load_inertia_reflected"]["value"]
        flat["motor.rotor_inertia"] = flat["motor.rotor_inertia"] - j_ref
        notes.append(f"transmission_compliance: motor.rotor_inertia -= {j_ref:.4g} kg*m^2 (the load, now "
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


# -- replay (multiple shooting) ----------------------------------------------------------------------

def _commands(ctx: Context) -> tuple[np.ndarray, str]:
    p = ctx.params
    if "current_command" in ctx.have:
        return ctx.raw["current_command"], "current_command"
    if "torque_command" in ctx.have:
        return ctx.raw["torque_command"] / (controller_motor(p)[2] * p.gear.gear_ratio), \
            "torque_command / (the drive's nominal K_t_q x gear ratio)"
    return ctx.dec.lowpass(ctx.sig["i_q"]), "measured current (no command recorded)"


def windows(ctx: Context, length: float, max_windows: int, which: str) -> list[int]:
    """Start indices of non-overlapping windows of ``length`` seconds inside segments; ``which`` = train,
    holdout or all; evenly thinned to ``max_windows``."""
    L = max(5, int(round(length * ctx.fs)))
    starts = []
    ho = ctx.holdout_raw
    need = [c for c in ("current", "position", "velocity") if c in ctx.have]
    for a, b in ctx.segments:
        margin = int(ctx.fs / ctx.dec.fc) * 3
        for s in range(a + margin, b - L - 1 - margin, L):
            if which != "all" and bool(ho[s]) != (which == "holdout"):
                continue
            if which != "all" and bool(ho[s + L]) != (which == "holdout"):
                continue
            if all(ctx.valid[c][s:s + L + 1].all() for c in need):
                starts.append(s)
    return thin(starts, max_windows)


def thin(starts: list[int], max_windows: int) -> list[int]:
    """``starts`` evenly thinned to at most ``max_windows`` (first and last kept)."""
    if len(starts) <= max_windows:
        return list(starts)
    return [starts[i] for i in np.linspace(0, len(starts) - 1, max_windows).round().astype(int)]


def window_errors(ctx: Context, param_sets: list[ActuatorParams], starts: list[int], length: float, *,
                  current_d: bool = False) -> list[dict[str, np.ndarray]]:
    """Per parameter set: per-window RMS closed-loop simulated error of the current and the speed (and, with
    ``current_d`` where the recording has it, of the d current against its low-passed reading)."""
    r = simulate_windows(ctx, param_sets, starts, length)
    nW = len(starts)
    have_d = current_d and "current_d" in ctx.have
    meas_d = ctx.dec.lowpass(ctx.sig["i_d"])[r["idx"][:, :nW]] if have_d else None
    out = []
    for j in range(len(param_sets)):
        sl = slice(j * nW, (j + 1) * nW)
        e = {"current": np.sqrt(np.mean((r["sim_i"][:, sl] - r["meas_i"][:, sl]) ** 2, axis=0)),
             "velocity": np.sqrt(np.mean((r["sim_w"][:, sl] - r["meas_w"][:, sl]) ** 2, axis=0))}
        if have_d:
            e["current_d"] = np.sqrt(np.mean((r["sim_id"][:, sl] - meas_d) ** 2, axis=0))
        out.append(e)
    return out


def replay(ctx: Context, param_sets: list[ActuatorParams], starts: list[int], length: float,
           drive: str = "closed_loop") -> list[dict[str, Any]]:
    """Simulate every window under every parameter set (one BatchActuator); per set: RMS error of current
    [A], speed [rad/s], angle [rad] and q-voltage [V] (where recorded) against the (low-passed) measurements, and the traces of the first
    windows for plots. ``drive``: ``closed_loop`` (the drive emulated from the recorded commands) or ``current``
    (the mechanical equation driven by the measured current, :func:`simulate_windows`)."""
    if not starts or "i_q" not in ctx.sig or "omega" not in ctx.sig:
        return [{"available": False} for _ in param_sets]
    r = simulate_windows(ctx, param_sets, starts, length, drive=drive)
    nW, nP = len(starts), len(param_sets)
    sim_i, sim_w, sim_th, sim_v = r["sim_i"], r["sim_w"], r["sim_th"], r["sim_v"]
    meas_i, meas_w, meas_th, meas_v, idx = r["meas_i"], r["meas_w"], r["meas_th"], r["meas_v"], r["idx"]
    out = []
    show = np.unique(np.linspace(0, nW - 1, min(4, nW)).round().astype(int))
    for j in range(nP):
        sl = np.arange(j * nW, (j + 1) * nW)
        ei, ew, eth = sim_i[:, sl] - meas_i[:, sl], sim_w[:, sl] - meas_w[:, sl], sim_th[:, sl] - meas_th[:, sl]
        out.append({"available": True, "windows": nW, "window_s": length,
                    "per_window": {"current": np.sqrt(np.mean(ei ** 2, axis=0)),
                                   "velocity": np.sqrt(np.mean(ew ** 2, axis=0)),
                                   "voltage": (np.sqrt(np.mean((sim_v[:, sl] - meas_v[:, sl]) ** 2, axis=0))
                                               if meas_v is not None else None)},
                    "current_rms": float(np.sqrt(np.mean(ei ** 2))), "velocity_rms": float(np.sqrt(np.mean(ew ** 2))),
                    "position_rms": float(np.sqrt(np.mean(eth ** 2))),
                    # q-voltage at the recorded speed (the replay's back-EMF error removed): where the voltage-side
                    # effects (resistance, dead time, K_t's back-EMF) show in a current-controlled drive
                    "voltage_rms": (float(np.sqrt(np.mean((sim_v[:, sl] - meas_v[:, sl]) ** 2)))
                                    if meas_v is not None else None),
                    # RMS of the recorded channel itself over the windows: what an error is measured against
                    "signal_rms": {"current": float(np.sqrt(np.mean(meas_i[:, sl] ** 2))),
                                   "velocity": float(np.sqrt(np.mean(meas_w[:, sl] ** 2))),
                                   "voltage": (float(np.sqrt(np.mean(meas_v[:, sl] ** 2)))
                                               if meas_v is not None else None)},
                    "trace": {"t": ctx.t[idx[:, sl[show]]].T.tolist(),
                              "sim_velocity": sim_w[:, sl[show]].T.tolist(),
                              "meas_velocity": meas_w[:, sl[show]].T.tolist(),
                              "sim_current": sim_i[:, sl[show]].T.tolist(),
                              "meas_current": meas_i[:, sl[show]].T.tolist()}})
    return out


def simulate_windows(ctx: Context, param_sets: list[ActuatorParams], starts: list[int], length: float,
                     drive: str = "closed_loop") -> dict:
    """Multiple shooting: every window started from the recorded state and simulated under every parameter set
    in ONE :class:`BatchActuator` run (one per group of sets that share the current-loop rate and delay, which a
    batch cannot mix). Returns the simulated and measured (low-passed) current, speed, angle and q voltage (and
    the simulated d current ``sim_id``) as ``(samples, sets x windows)`` arrays (set-major columns) and the
    sample indices.

    ``drive="closed_loop"``: the drive emulated (its PI current loop from the recorded command, started in its
    own steady state, :func:`window_start`). ``drive="current"``: what a torque-side effect needs and nothing the
    user rarely knows — the drive's internals — the mechanical equation driven by ``K i`` with the MEASURED
    current (:func:`mechanical_replay_params`); the simulated current is then the measured one."""
    if drive == "current":
        return _simulate_current_driven(ctx, param_sets, starts, length)
    L = max(5, int(round(length * ctx.fs)))
    nW = len(starts)
    plist = []
    use_sensor = "torque" in ctx.have
    for p in param_sets:
        # the recorded drive was tuned on the nominal motor: a set that changes R, L or K changes the plant, not
        # the drive's gains and feed-forward (issue #14: a true K_t x1.15 was refused when the replayed drive's
        # feed-forward followed it)
        p = keep_controller_of(p, ctx.params)
        if use_sensor:   # the sensor measures the load: the modelled load must not count twice
            p = p.replace(**{"load.load_torque": 0.0, "load.gravity_torque": 0.0, "load.spring_stiffness": 0.0})
        plist += [p] * nW
    st = np.array(starts * len(param_sets))
    sims = {k: np.zeros((L, len(plist))) for k in ("sim_i", "sim_w", "sim_th", "sim_v", "sim_id")}
    groups: dict[tuple, list[int]] = {}
    for c, p in enumerate(plist):
        groups.setdefault((p.drive.current_loop_rate, p.drive.current_loop_delay), []).append(c)
    S = ctx.sig
    i_meas = ctx.dec.lowpass(S["i_q"])
    cmd, _ = _commands(ctx)
    load = ctx.raw["torque"] if use_sensor else (ctx.raw["load_torque"] if "load_torque" in ctx.have else None)
    for cols in groups.values():
        part = _simulate_batch(ctx, [plist[c] for c in cols], st[cols], L, i_meas, cmd, load)
        for k, v in part.items():
            sims[k][:, cols] = v
    idx = st[None, :] + np.arange(1, L + 1)[:, None]
    if any(p.drive.dead_time > 0.0 for p in plist):   # the kernel's source of a ripple above the log's cut-off
        as_logged(ctx, sims, S["omega_s"][st], S["omega_s"][idx])
    meas_v = ctx.dec.lowpass(S["v_q"])[idx] if "v_q" in S else None
    return {**sims, "meas_i": i_meas[idx], "meas_w": S["omega_s"][idx], "meas_th": S["theta"][idx],
            "meas_v": meas_v, "idx": idx}



def _lowpass_window(ctx: Context, x: np.ndarray) -> np.ndarray:
    """The recording's zero-phase low-pass (``ctx.dec``) applied to simulated window traces ``(samples, columns)``,
    each end extended by the straight line fitted to its first/last ``3 fs / fc`` samples (what the recorded
    channel's filter sees there is the recording's own continuation: a trend, not a mirrored ripple)."""
    if ctx.dec.steady or ctx.dec.sos is None:
        return x
    n = x.shape[0]
    pad = int(math.ceil(3.0 * ctx.fs / ctx.dec.fc))
    m = max(2, min(n, pad))
    k = np.arange(m) - 0.5 * (m - 1)

    def line(seg, at):     # least squares per column, elementwise: a column's result never depends on its batch
        mean = seg.mean(axis=0)
        slope = (k[:, None] * (seg - mean)).sum(axis=0) / float(k @ k)
        return mean + (np.asarray(at, float) - 0.5 * (m - 1))[:, None] * slope

    left = line(x[:m], np.arange(-pad, 0))
    right = line(x[n - m:], np.arange(m, m + pad))
    y = sps.sosfiltfilt(ctx.dec.sos, np.concatenate([left, x, right]), axis=0, padtype=None)
    return y[pad:pad + n]


def as_logged(ctx: Context, sims: dict[str, np.ndarray], w_start: np.ndarray, w_meas: np.ndarray) -> None:
    """The simulated current, speed and q voltage through the same low-pass as the recorded channels they are
    compared with (in place). Applied to every set of a replay in which any set has a dead time (the one source
    of such a ripple in the kernel); applied to all replays it moved other judgements (a true K_t x1.22 replayed
    a current 0.0144 A vs the nominal's 0.0129 A and was refused; an output-error refit of R was kept 2.6 % off),
    left for later. A true dead time leaves a current ripple at six times the electrical frequency
    (at 25 rad/s, 21 pole pairs: 500 Hz, the 1 kHz log's Nyquist) that the recording holds and its low-pass
    removes: compared unfiltered, the true 2 µs replayed a one-signed recording WORSE than none (current
    0.143 A vs 0.026 A). The speed is started at the recorded SMOOTHED speed, but the true speed at that
    instant sits on the ripple the torque ripple leaves (~0.1 rad/s), and nothing restores a speed: the
    filtered simulated speed is moved so that it starts where the recorded speed, through the same window
    filter, starts (the edge's trend error cancels). Measured on that recording (33 held-out windows of 0.1 s):
    true 2 µs current 0.143 -> 0.022 A, speed 0.137 -> 0.050 rad/s, q-voltage 0.076 -> 0.017 V; the nominal
    (no dead time) 0.026 -> 0.020 A, 0.056 -> 0.052 rad/s, 1.47 V."""
    if ctx.dec.steady or ctx.dec.sos is None:
        return
    for k in ("sim_i", "sim_id", "sim_v"):
        sims[k] = _lowpass_window(ctx, sims[k])
    w_lp = _lowpass_window(ctx, np.vstack([w_start[None, :], sims["sim_w"]]))
    m_lp = _lowpass_window(ctx, np.vstack([w_start[None, :], w_meas]))
    sims["sim_w"] = w_lp[1:] + (m_lp[0] - w_lp[0])[None, :]


#: the torque constant of the electrical side in a current-driven replay [V*s/rad]: the kernel's winding is kept
#: (its equations are the mechanical one's neighbours), but with no current and no back-EMF it exchanges nothing
_INERT_K = 1e-12


def mechanical_replay_params(p: ActuatorParams) -> ActuatorParams:
    """``p`` with an inert electrical side, for the current-driven replay: the motor's torque ``K(T_h, i) i N``
    from the measured current enters the kernel as an external (negative) output load, so every torque-side
    term — inertia, viscous and iron-loss drag, friction with stick/slip, cogging, position loads — is the
    kernel's own (one implementation of the equations)."""
    return p.replace(**{"motor.torque_constant_q": _INERT_K, "drive.dead_time": 0.0,
                        "drive.current_sensor_offset_a": 0.0, "drive.current_sensor_offset_b": 0.0,
                        "drive.current_sensor_gain_a": 1.0, "drive.current_sensor_gain_b": 1.0,
                        "effects.kt_saturation": 0.0})


def true_current(ctx: Context, p: ActuatorParams) -> tuple[np.ndarray, np.ndarray]:
    """The winding d/q current [A] behind the recorded (sensor) current under ``p``'s sensor offsets and gains
    (the sensor model inverted sample by sample; the recorded current when the sensors are ideal)."""
    from ... import kernel

    S = ctx.sig
    i_d, i_q = np.asarray(S["i_d"], float), np.asarray(S["i_q"], float)
    d = p.drive
    if not (d.current_sensor_offset_a or d.current_sensor_offset_b or d.current_sensor_gain_a != 1.0
            or d.current_sensor_gain_b != 1.0):
        return i_d, i_q
    th_e = p.motor.pole_pairs * np.asarray(S["theta"], float)
    args = (d.current_sensor_offset_a, d.current_sensor_offset_b, d.current_sensor_gain_a, d.current_sensor_gain_b)
    f = np.vectorize(lambda x, y, th: kernel.measured_current_dq(x, y, th, *args), otypes=[float, float])
    z = np.zeros_like(th_e)
    m0d, m0q = f(z, z, th_e)
    a_d, a_q = f(z + 1.0, z, th_e)
    b_d, b_q = f(z, z + 1.0, th_e)
    a_d, a_q, b_d, b_q = a_d - m0d, a_q - m0q, b_d - m0d, b_q - m0q
    det = a_d * b_q - b_d * a_q
    rd, rq = i_d - m0d, i_q - m0q
    return (b_q * rd - b_d * rq) / det, (a_d * rq - a_q * rd) / det


def _simulate_current_driven(ctx: Context, param_sets: list[ActuatorParams], starts: list[int], length: float) -> dict:
    L = max(5, int(round(length * ctx.fs)))
    nW = len(starts)
    S = ctx.sig
    use_sensor = "torque" in ctx.have
    w_meas = S["omega_s"]
    st_one = np.asarray(starts, int)
    last = len(ctx.t) - 1
    n_sub = replay_substeps(ctx.fs)
    dt = 1.0 / ctx.fs
    ext = ctx.raw["torque"] if use_sensor else (ctx.raw["load_torque"] if "load_torque" in ctx.have else None)
    plist, drive_torque = [], []
    for p in param_sets:
        if use_sensor:   # the sensor measures the load: the modelled load must not count twice
            p = p.replace(**{"load.load_torque": 0.0, "load.gravity_torque": 0.0, "load.spring_stiffness": 0.0})
        m = p.motor
        # the low-passed current (the equation error's band): the sensor noise above it, integrated over a
        # window, would be a speed random walk larger than most effects
        i_q = true_current(ctx, p)[1]
        if "i_q_torque" in S:       # aligned with the motion (search): the torque's timing, not the sample's
            i_q = i_q + (S["i_q_torque"] - S["i_q"])
        i_q = ctx.dec.lowpass(i_q)
        K = m.torque_constant_q * effects.flux_factor(S["T_h"], m.reference_temperature,
                                                      m.magnet_temperature_coefficient, m.magnet_temperature_enabled)
        K = K * effects.saturation_factor(i_q, p.effects.kt_saturation)
        tau_out = K * i_q * p.gear.gear_ratio                      # the motor's torque at the output
        drive_torque.append(tau_out - (ext if ext is not None else 0.0))
        plist.append(mechanical_replay_params(p))
    groups: dict[tuple, list[int]] = {}
    for j, p in enumerate(plist):
        groups.setdefault((p.drive.current_loop_rate, p.drive.current_loop_delay), []).append(j)
    cols_all = len(plist) * nW
    sims = {k: np.zeros((L, cols_all)) for k in ("sim_i", "sim_w", "sim_th", "sim_v", "sim_id")}
    i_lp = ctx.dec.lowpass(S["i_q"])
    for js in groups.values():
        group = [plist[j] for j in js for _ in range(nW)]
        b = BatchActuator(group)
        st = np.tile(st_one, len(js))
        th_l, w_l = window_load_states(ctx, group, st)   # the load behind a compliant transmission
        b.set_state(i_d=0.0, i_q=0.0, omega=w_meas[st], theta=S["theta"][st], T_winding=S["T_w"][st],
                    T_housing=S["T_h"][st], theta_load_out=th_l, omega_load_out=w_l)
        # a compliant transmission: the motor's torque acts on the rotor, the load's behind the spring
        on_rotor = np.array([p.gear.transmission_stiffness > 0.0 for p in group])
        N_col = np.array([p.gear.gear_ratio for p in group])
        tau = np.vstack([drive_torque[j] for j in js])            # (sets in group, samples)
        rows = np.repeat(np.arange(len(js)), nW)
        cols = np.concatenate([np.arange(j * nW, (j + 1) * nW) for j in js])
        for k in range(L):
            a, z = st + k, np.minimum(st + k + 1, last)
            for jj in range(n_sub):
                # the torque over the sub-step: the measured current at its midpoint (aligned with the motion
                # in search: a current at sample k acts around t_k)
                f = (jj + 0.5) / n_sub
                tau_now = tau[rows, a] + f * (tau[rows, z] - tau[rows, a])
                if on_rotor.any():
                    ext_now = (ext[a] + f * (ext[z] - ext[a])) if ext is not None else 0.0
                    b.set_rotor_torque(np.where(on_rotor, (tau_now + ext_now) / N_col, 0.0))
                    tau_now = np.where(on_rotor, -ext_now, tau_now)   # -> load torque ext at the output
                b.set_load_torque(-tau_now)
                b.step(dt / n_sub)
            sims["sim_w"][k, cols] = b.field("omega")
            sims["sim_th"][k, cols] = b.field("theta")
    idx_one = st_one[None, :] + np.arange(1, L + 1)[:, None]
    idx = np.tile(idx_one, (1, len(plist)))
    sims["sim_i"][:] = i_lp[idx]            # the current is the recording's (not simulated)
    sims["sim_v"][:] = np.nan
    return {**sims, "meas_i": i_lp[idx], "meas_w": w_meas[idx], "meas_th": S["theta"][idx], "meas_v": None,
            "idx": idx}

#: a log slower than this [Hz] holds samples of commands that changed between them (the joint controller runs
#: at 1 kHz or faster): without evidence from the data (:func:`command_replay`), the replay interpolates them
#: linearly over sub-steps of at most 1 / this, and holds the commands of a faster log
REPLAY_HOLD_RATE = 500.0

#: at most this many interpolation sub-steps per sample of a log at or above :data:`REPLAY_HOLD_RATE`
MAX_INTERPOLATION_SUBSTEPS = 20

#: the noise floor reported with the choice: this many standard errors of the per-window mean (the choice itself
#: is the smaller error: the log rate is no evidence either way, issue #14)
COMMAND_REPLAY_Z = 2.0


def replay_substeps(fs: float, hold: bool | None = None, loop_rate: float | None = None) -> int:
    """Sub-steps per recorded sample. ``hold`` (None: decided by the log rate, held at or above
    :data:`REPLAY_HOLD_RATE`): 1, the recorded command held as the drive held it. Interpolated: linear between
    samples over steps of <= 1 / :data:`REPLAY_HOLD_RATE` below that rate; at or above it one step per current-
    loop tick of ``loop_rate`` [Hz] (the instants at which a drive can take a new command; at most
    :data:`MAX_INTERPOLATION_SUBSTEPS`)."""
    if hold is None:
        hold = fs >= REPLAY_HOLD_RATE
    if hold:
        return 1
    if fs < REPLAY_HOLD_RATE:
        return int(math.ceil(REPLAY_HOLD_RATE / fs))
    ticks = int(round(loop_rate / fs)) if loop_rate and loop_rate > 0 else 1
    return max(1, min(MAX_INTERPOLATION_SUBSTEPS, ticks))


def command_steps(ctx: Context) -> tuple[bool, int]:
    """(hold, sub-steps per sample) of the window replay's commands: ``ctx.command_replay`` when it was decided
    (:func:`command_replay`), else by the log rate (:func:`replay_substeps`)."""
    cr = ctx.command_replay
    if cr is not None:
        return cr.hold, cr.substeps
    n = replay_substeps(ctx.fs)
    return n == 1, n


def command_replay(ctx: Context, params: ActuatorParams, starts: list[int], length: float,
                   z: float = COMMAND_REPLAY_Z) -> CommandReplay:
    """Decide from the data how the replay applies the logged commands between samples (issue #14: whether the
    drive held each logged command is a property of the recording its user rarely knows). ``params`` (the
    nominal model) replays the TRAINING windows ``starts`` twice — every logged command held over its sample
    interval, and interpolated linearly between samples (:func:`replay_substeps`) — and the way with the smaller
    error is kept: per window, the current and speed errors' changes (interpolated - held) relative to their
    mean held errors, summed, averaged over the windows (``score``; its noise floor, ``z`` standard errors, is
    reported, not used: the log rate is no evidence either way — on the gym-electric-motor case the nominal
    model's training replay favoured interpolation by 1.7 standard errors, and holding refused the true R).
    The log-rate default (held at or above :data:`REPLAY_HOLD_RATE`) only when there is nothing to replay or no
    difference at all. Decided once, before any finding is judged."""
    hold_default = ctx.fs >= REPLAY_HOLD_RATE
    n_interp = replay_substeps(ctx.fs, hold=False, loop_rate=params.drive.current_loop_rate)
    default = CommandReplay(hold_default, 1 if hold_default else n_interp, "log rate")
    if len(starts) < 3 or "i_q" not in ctx.sig or "omega" not in ctx.sig:
        return default
    errs: dict[str, dict[str, np.ndarray]] = {}
    for way, hold, n in (("hold", True, 1), ("interpolate", False, n_interp)):
        trial = dataclasses.replace(ctx, command_replay=CommandReplay(hold, n, "trial"))
        r = replay(trial, [params], starts, length)[0]
        if not r.get("available"):
            return default
        errs[way] = {ch: np.asarray(r["per_window"][ch], float) for ch in ("current", "velocity")}
    d = np.zeros(len(starts))
    for ch in ("current", "velocity"):
        scale = float(np.mean(errs["hold"][ch]))
        if scale > 0 and math.isfinite(scale):
            d += (errs["interpolate"][ch] - errs["hold"][ch]) / scale
    ok = np.isfinite(d)
    score = float(np.mean(d[ok])) if ok.sum() >= 3 else float("nan")
    floor = float(z * np.std(d[ok], ddof=1) / math.sqrt(ok.sum())) if ok.sum() >= 3 else float("nan")
    means = {way: {ch: float(np.mean(v)) for ch, v in e.items()} for way, e in errs.items()}
    if math.isfinite(score) and score != 0.0:
        hold = score > 0
        return CommandReplay(hold, 1 if hold else n_interp, "training replay", means, score, floor, len(starts))
    return dataclasses.replace(default, errors=means, score=score, noise_floor=floor, windows=len(starts))


def command_replay_note(cr: CommandReplay, fs: float) -> str:
    """Plain words for the report: how the replay applies the logged commands, and why."""
    how = ("each logged command is held until the next sample (as a drive whose controller runs at the log rate "
           "holds it)" if cr.hold else
           f"the logged commands are interpolated linearly between samples over {cr.substeps} sub-steps per sample "
           f"(a drive that updated its command between the {fs:.4g} Hz samples)")
    e = cr.errors
    if cr.decided_by == "training replay":
        clear = abs(cr.score) > cr.noise_floor
        why = (f"decided by the nominal model's replay of {cr.windows} training windows, the smaller error: speed "
               f"error {e['hold']['velocity']:.3g} rad/s held vs {e['interpolate']['velocity']:.3g} interpolated, "
               f"current {e['hold']['current']:.3g} vs {e['interpolate']['current']:.3g} A (relative change "
               f"{cr.score:+.3g}, {'beyond' if clear else 'within'} its noise floor {cr.noise_floor:.2g}"
               f"{'' if clear else ': a slight preference'})")
    elif e:
        why = (f"by the log rate: the nominal model's replay of {cr.windows} training windows is the same both ways "
               f"(speed error {e['hold']['velocity']:.3g} rad/s)")
    else:
        why = "by the log rate (no training windows to replay)"
    return f"window replay: {how}; {why}"


@dataclass
class WindowStart:
    """The drive's and the plant's state at the start of replay windows (one entry per column)."""

    i_d: np.ndarray      #: true winding d current [A] (the sensors' reading inverted)
    i_q: np.ndarray      #: true winding q current [A]
    v: np.ndarray        #: applied d/q voltage (complex) [V], inside the inverter's circle
    z: np.ndarray        #: PI integrators (complex) [V]
    K: np.ndarray        #: the plant's torque / back-EMF constant at the start [V*s/rad]


def window_start(plist: list[ActuatorParams], i_d_meas, i_q_meas, omega, theta, T_w, T_h) -> WindowStart:
    """Steady state of each parameter set's drive at a recorded state (issue #14, symptom 1): the current the
    sensors report is inverted through that set's sensor offsets and gains (the plant starts with the true
    current), the applied voltage is the plant's steady voltage for that current and speed — R(T_w) i, the
    cross-coupling p ω L i and back-EMF K(T_h, i_q) ω — limited to the
    inverter's circle as the drive limits it (``drive.voltage_limit_mode``, ``drive.modulation_limit``), and the
    PI integrators hold what that drive's integrators hold there: the applied voltage less the decoupling
    feed-forward when ``drive.decoupling_enabled`` (R i), the whole voltage without it (R i + K ω: a drive without
    feed-forward carries the back-EMF in its integrator); at the limit the back-calculation anti-windup leaves
    the PI output on the circle. The delayed voltage (``drive.current_loop_delay``) is the same held voltage.
    Started otherwise every window opens with a current transient that grows with K ω and makes the right K look
    wrong. With ``drive.dead_time`` the applied voltage also holds what the legs lose, the kernel's
    interval-average dead-time error at the steady interval change (its fixed point: ``V_dt`` against each line
    current's sign), and the integrator with it: in a closed-loop recording at 1 µs (V_dt 0.48 V, currents
    0.05-0.3 A) the drive's integrator sat at ``R i`` plus a vector on the dead-time hexagon (|z - R i|
    0.68-0.78 V, 5th-95th percentile), not at ``R i``. Started at ``R i`` the integrator had to wind through that
    dead band at ``K_i`` times a current error of ~0.1 A (~5 ms): the first 3 ms were 0.22 A off. The signs of
    phase currents near zero are uncertain in a low-passed current (41 of 180 differed from the true ones), but
    the kernel's Filippov clamp keeps such a phase at zero whichever sign it starts with: 0.043 A, against
    0.035 A started from the recording drive's own integrator."""
    from ... import kernel

    n = len(plist)
    i_d = np.array(i_d_meas, float).copy()
    i_q = np.array(i_q_meas, float).copy()
    omega, theta = np.asarray(omega, float), np.asarray(theta, float)
    K = np.zeros(n)
    v = np.zeros(n, complex)
    z = np.zeros(n, complex)
    for c, p in enumerate(plist):
        m, d = p.motor, p.drive
        th_e = m.pole_pairs * float(theta[c])
        if d.current_sensor_offset_a or d.current_sensor_offset_b or d.current_sensor_gain_a != 1.0 \
                or d.current_sensor_gain_b != 1.0:
            f = lambda x, y: np.array(kernel.measured_current_dq(x, y, th_e, d.current_sensor_offset_a,  # noqa: E731
                                                                   d.current_sensor_offset_b, d.current_sensor_gain_a,
                                                                   d.current_sensor_gain_b))
            m0 = f(0.0, 0.0)
            M = np.column_stack([f(1.0, 0.0) - m0, f(0.0, 1.0) - m0])
            i_d[c], i_q[c] = np.linalg.solve(M, np.array([i_d[c], i_q[c]]) - m0)
        R = effects.resistance_at(m.phase_resistance, float(T_w[c]), m.reference_temperature,
                                  m.copper_temperature_coefficient, m.resistance_temperature_enabled)
        Kc = m.torque_constant_q * effects.flux_factor(float(T_h[c]), m.reference_temperature,
                                                       m.magnet_temperature_coefficient, m.magnet_temperature_enabled)
        Kc = float(Kc * effects.saturation_factor(i_q[c], p.effects.kt_saturation))
        w = float(omega[c])
        i = complex(i_d[c], i_q[c])
        v_plant = (R + 1j * m.pole_pairs * w * m.q_inductance) * i + 1j * Kc * w
        v_max = frames.voltage_limit_q(d.bus_voltage, m.winding) * d.modulation_limit
        mode = float(kernel.VOLTAGE_LIMIT_MODES.index(d.voltage_limit_mode))
        if d.dead_time > 0.0:
            # the drive also supplies what the legs lose: the kernel's interval-average error at the steady
            # interval change, di = (h/L)(v - the kernel's predictor's plant voltage) = -(h/L) e. Seeded with the
            # sign (h/L = 0), one pass is its fixed point; di = 0 instead hits the Filippov clamp (|i_line| is
            # far below (2/3)(h/L) V_dt = 0.56 A at 1 µs) and returns ~i/1.17 A/V, nearly nothing
            v_dt = d.dead_time * d.pwm_frequency * d.bus_voltage
            delta = 1.0 if m.winding == "delta" else 0.0
            h_over_L = 1.0 / (d.current_loop_rate * m.q_inductance)
            v_pred = (m.phase_resistance + 1j * m.pole_pairs * w * m.q_inductance) * i + 1j * m.torque_constant_q * w
            band = d.dead_time_current_band
            e = kernel.dead_time_error_dq(i, 0j, th_e, v_dt, delta, 0.0, band)
            v_try = kernel.limit_voltage(v_plant - e, v_max, mode)
            e = kernel.dead_time_error_dq(i, h_over_L * (v_try - v_pred), th_e, v_dt, delta, h_over_L, band)
            v_plant = v_plant - e
        v_app = kernel.limit_voltage(v_plant, v_max, mode)
        # the feed-forward acts on the MEASURED current with the drive's own model of the motor (its L and
        # nominal-temperature K, drive.controller_*: 0 = the motor's), as the kernel's current loop does
        i_m = complex(float(np.asarray(i_d_meas)[c]), float(np.asarray(i_q_meas)[c]))
        _, L_ctl, K_ctl = controller_motor(p)
        v_ff = 1j * (m.pole_pairs * w * L_ctl * i_m + K_ctl * w) if d.decoupling_enabled else 0j
        K[c], v[c], z[c] = Kc, v_app, v_app - v_ff
    return WindowStart(i_d, i_q, v, z, K)


def _simulate_batch(ctx: Context, plist: list[ActuatorParams], st: np.ndarray, L: int, i_meas: np.ndarray,
                    cmd: np.ndarray, load: np.ndarray | None) -> dict:
    """One :class:`BatchActuator` over windows starting at ``st`` (one parameter set per column), driven by the
    recorded command ``cmd`` and ``load`` and started from the low-passed current ``i_meas``."""
    b = BatchActuator(plist)
    S = ctx.sig
    w_meas = S["omega_s"]
    T_w0, T_h0 = S["T_w"][st], S["T_h"][st]
    i_d_meas0 = ctx.dec.lowpass(S["i_d"])[st]
    ws = window_start(plist, i_d_meas0, i_meas[st], w_meas[st], S["theta"][st], T_w0, T_h0)
    K = ws.K
    th_l, w_l = window_load_states(ctx, plist, st)      # the load behind a compliant transmission
    b.set_state(i_d=ws.i_d, i_q=ws.i_q, omega=w_meas[st], theta=S["theta"][st], T_winding=T_w0, T_housing=T_h0,
                v_d=ws.v.real, v_q=ws.v.imag, z_d=ws.z.real, z_q=ws.z.imag, i_q_ref=cmd[st],
                theta_load_out=th_l, omega_load_out=w_l)
    dt = 1.0 / ctx.fs
    sensed = any(p.drive.current_sensor_offset_a or p.drive.current_sensor_offset_b
                 or p.drive.current_sensor_gain_a != 1.0 or p.drive.current_sensor_gain_b != 1.0 for p in plist)
    out = {k: np.zeros((L, len(plist))) for k in ("sim_i", "sim_w", "sim_th", "sim_v", "sim_id")}
    hold, n_sub = command_steps(ctx)
    last = len(cmd) - 1
    for k in range(L):
        a, z = st + k, np.minimum(st + k + 1, last)
        for j in range(n_sub):
            f = 0.0 if hold else (j + 0.5) / n_sub
            b.set_current_command(cmd[a] + f * (cmd[z] - cmd[a]))
            if load is not None:
                b.set_load_torque(load[a] + f * (load[z] - load[a]))
            b.step(dt / n_sub)
        # the current the drive's sensors report (what the recording holds), not the true winding current
        if sensed:
            o = b.outputs()
            out["sim_i"][k], out["sim_id"][k] = o["i_q_measured"], o["i_d_measured"]
        else:
            i = b.field("i")
            out["sim_i"][k], out["sim_id"][k] = i.imag, i.real
        out["sim_w"][k] = w_sim = b.field("omega")
        out["sim_th"][k] = b.field("theta")
        # the drive's q voltage, where voltage-side effects show, at the RECORDED speed: the back-EMF of the
        # mechanical replay's speed error, K (omega_sim - omega_rec), is the velocity channel's error, not the
        # electrical one's (at 10 Hz it is several times a resistance change's voltage)
        out["sim_v"][k] = b.field("v").imag - K * (w_sim - w_meas[np.minimum(st + k + 1, last)])
    return out


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
            if name == "thermal_parameters":
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
        if best["name"] == "thermal_parameters":
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
        elif f["effect"] in ("thermal_parameters", "voltage_saturation", "iron_loss") and f.get("simulated"):
            for name, fld in f["fields"].items():
                flat[fld] = _within_limits(SPECS[fld], f["parameters"][name], notes, fld)
            if f["effect"] == "iron_loss":
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


# -- voltage saturation (current tracking against the voltage limit) -------------------------------------

def _achievable(i_cmd, omega, R, K, L, p, v_lim):
    """q current the inverter can reach at speed ω with |v_dq| <= v_lim (steady state, i_d = 0):
    (R i + K ω)² + (p ω L i)² = v_lim², the root on the side of the command; the command if reachable."""
    a = R * R + (p * omega * L) ** 2
    b = 2.0 * R * K * omega
    c = (K * omega) ** 2 - v_lim ** 2
    disc = np.maximum(b * b - 4 * a * c, 0.0)
    hi = (-b + np.sqrt(disc)) / (2 * a)
    lo = (-b - np.sqrt(disc)) / (2 * a)
    reach = np.where(np.abs(K * omega) < v_lim, 1.0, 0.0)
    out = np.clip(i_cmd, lo, hi)
    return np.where(reach > 0, out, np.where(i_cmd * omega > 0, 0.0 * i_cmd, np.clip(i_cmd, lo, hi)))


def voltage_saturation_check(ctx: Context, lib: dict[str, Candidate], gate, wanted: bool) -> dict[str, Any]:
    """voltage_saturation: does the current stop following its command at a voltage BELOW the model's limit?

    Tracking residual ``r = i_meas - i_ach(c)`` where ``i_ach`` is the command clipped to what the inverter can
    drive at the speed with ``|v| <= c v_max`` (nominal c = 1). ``c`` is fitted on training data (bounded 1-D
    search), gated like the others (ΔBIC with the effective sample count, held-out improvement)."""
    from scipy.optimize import minimize_scalar

    from .equation_error import integrated_autocorrelation_time

    out: dict[str, Any] = {"findings": [], "rejected": [], "not_checkable": []}
    if not wanted:
        return out
    cand = lib["voltage_saturation"]
    miss = [x for x in ("current", "current_command|torque_command", "velocity|position")
            if not any(y in ctx.have for y in x.split("|"))]
    if miss:
        out["not_checkable"].append({"effect": cand.name, "reason": f"needs {', '.join(m.replace('|', ' or ') for m in miss)}",
                                     "needs": miss})
        return out
    S, p = ctx.sig, ctx.params
    m = p.motor
    cmd, _ = _commands(ctx)
    lp_i = ctx.dec.lowpass(S["i_q"])
    best = None
    for k in range(0, 6):      # the command aligned with the current it produced (0-5 samples later)
        c = np.concatenate([np.full(k, cmd[0]), cmd[: len(cmd) - k]]) if k else cmd
        e = float(np.mean((lp_i - ctx.dec.lowpass(c)) ** 2))
        if best is None or e < best[0]:
            best = (e, c)
    cmd = best[1]
    w = S["omega_s"]
    v_max = S["v_max"]
    R = S["R"]
    K = S["K"]
    i_dec = ctx.dsig("i_q")
    ok = ctx.dec.mask(ctx.valid["current"] & ctx.valid["omega"])
    ho = ctx.holdout_dec

    def resid(c):
        ach = _achievable(cmd, w, R, K, m.q_inductance, m.pole_pairs, c * v_max)
        return i_dec - ctx.dec.apply(ach)

    r0 = resid(1.0)
    need = ctx.dec.apply(np.abs(K * w) + np.abs(R * cmd))
    near = float(np.mean((need / ctx.dec.apply(v_max))[ok] > 0.7))
    if near < 0.005:
        out["not_checkable"].append({"effect": cand.name, "reason": "data does not excite it: needs operation near "
                                     "the voltage limit (back-EMF + R i above 70% of v_max)", "needs": []})
        return out
    tr = ok & ~ho
    hv = ok & ho
    cv_note = ""

    def rss(c):
        r = resid(c)[tr]
        return float(r @ r)

    def fit_c():
        sol = minimize_scalar(rss, bounds=(0.5, 1.0), method="bounded", options={"xatol": 1e-3})
        return float(sol.x)

    c_hat = fit_c()
    r1 = resid(c_hat)
    noise = 1.4826 * float(np.median(np.abs(r0[ok] - np.median(r0[ok]))))
    if (hv & (np.abs(r1 - r0) > 3 * noise)).sum() < 20:
        # the held-out part never comes near the fitted limit: cross-validate inside the rest instead
        from .equation_error import holdout_mask

        inner = holdout_mask(ctx.t, ctx.segments, 0.3)[ctx.dec.idx]
        tr, hv = ok & ~ho & ~inner, ok & ~ho & inner
        cv_note = " (held-out data never nears the limit: checked on interleaved blocks of the training data)"
        c_hat = fit_c()
        r1 = resid(c_hat)
    rss0, rss1 = float(r0[tr] @ r0[tr]), float(r1[tr] @ r1[tr])
    tau = integrated_autocorrelation_time(r1[tr])
    n_eff = max(2.0, tr.sum() / tau)
    dbic = n_eff * math.log(rss0 / max(rss1, 1e-300)) - math.log(n_eff)
    e0 = float(np.sqrt(np.mean(r0[hv] ** 2))) if hv.any() else float("nan")
    e1 = float(np.sqrt(np.mean(r1[hv] ** 2))) if hv.any() else float("nan")
    rel = 1.0 - e1 / e0 if e0 > 0 else 0.0
    # uncertainty of c from the curvature of the RSS
    h = 0.005
    curv = (rss(min(1.0, c_hat + h)) - 2 * rss1 + rss(max(0.5, c_hat - h))) / h ** 2
    s2 = rss1 / max(1, tr.sum() - 1) * tau
    sd = math.sqrt(2 * s2 / curv) if curv > 0 else float("nan")
    passed = dbic > gate.bic_threshold and rel > gate.min_heldout_gain and c_hat < 0.99
    reason = (f"passed: ΔBIC {dbic:.1f}, held-out current-tracking error -{100 * rel:.1f}%{cv_note}" if passed else
              f"ΔBIC {dbic:.1f}, held-out current-tracking error {-100 * rel:+.1f}%, limit {c_hat:.3f} x v_max{cv_note}")
    if not passed:
        out["rejected"].append({"effect": cand.name, "form": "current tracking vs voltage limit", "reason": reason,
                                "delta_bic": round(dbic, 2), "heldout_gain": round(rel, 4)})
        return out
    hd = ctx.dsig("headroom") if "headroom" in S else None
    ev = [f"the measured current falls short of its command where back-EMF + R i approach {c_hat:.2f} x the "
          f"nominal voltage limit (current-tracking residual {e0:.3g} A -> {e1:.3g} A RMS on held-out data)"]
    if hd is not None:
        lost = ok & (np.abs(r0) > 4 * 1.4826 * np.median(np.abs(r0[ok])))
        if lost.sum() > 10:
            ev.append(f"where tracking is lost the recorded |v|/v_max is {np.median(hd[lost]):.2f} (median), "
                      f"never the 1.0 the model allows")
    ev.append(reason)
    out["findings"].append({
        "effect": cand.name, "description": cand.description, "form": "current tracking vs voltage limit",
        "parameters": {"voltage_limit_ratio": c_hat}, "uncertainty": {"voltage_limit_ratio": sd},
        "units": {"voltage_limit_ratio": ""}, "fields": {"voltage_limit_ratio": "drive.modulation_limit"},
        "simulated": True, "evidence": ev, "heldout_nears_limit": not cv_note,
        "held_out": {"metric": "current-tracking error RMS (held-out)", "unit": "A", "before": e0, "after": e1},
        "metrics": [{"metric": "current-tracking error RMS (held-out)", "unit": "A", "before": e0, "after": e1}],
        "delta_bic": dbic, "round": 1, "correlations": []})
    return out
