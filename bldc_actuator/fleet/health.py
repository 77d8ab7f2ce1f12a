"""Tracked health parameters: the same few physical parameters fitted on EVERY recording.

``diagnose`` reports an effect only when it passes its acceptance gates; a slow drift never does in one
log. For trends the fleet needs the fitted value ± uncertainty of the parameters that say something about
an actuator's health, on every recording, whether or not anything was "found". This module fits them with
the diagnosis' own machinery (no second copy of any equation):

=============================  ==================================  =============================================
parameter (unit)               equation / columns                  needs
=============================  ==================================  =============================================
``coulomb_friction`` (N*m)     mechanical, ``candidates`` column   current, velocity or position
                               of ``coulomb_friction``
``viscous_damping``            mechanical, column of               current, velocity or position
(N*m*s/rad)                    ``viscous_friction``
``torque_constant_q`` (N*m/A)  mechanical + electrical (back-EMF)  current, velocity or position (+ voltage_q)
                               column of ``torque_constant_error``
``phase_resistance`` (ohm)     electrical, column of               voltage_q, current, velocity or position
                               ``resistance_error``
``housing_to_ambient_          thermal network (``equation_error.  current and a recorded temperature that
resistance`` (K/W)             thermal_response``) output error,   changes by >= 1 K
                               R_ha only, the rest nominal
=============================  ==================================  =============================================

Estimator (well defined, the same for every recording):

1. :func:`prepare`: :func:`..diagnosis.frame.equation_error.prepare` with the nominal parameters (same filter,
   decimation and held-out blocks as ``diagnose``) and the search stage's alignment of the logged current to
   the motion, as ``diagnose`` does.
2. ONE joint least-squares fit (:func:`..diagnosis.frame.selection.fit_model`: instrumental variables for
   current-proportional columns, fixed-point K_t column) of the four linear columns that are checkable
   plus the always-fitted nuisance columns, each equation weighted by 1/robust std of its nominal training
   residual. The joint fit keeps friction from absorbing a K_t change and vice versa.
3. Values = nominal + fitted change, mapped by each candidate's own ``to_params``; uncertainty = the
   larger of the fit's standard deviation (covariance inflated by the residual's correlation time) and the
   time-cluster sandwich of :func:`cluster_covariance` (coloured, model-form residuals).
4. Held-out before/after per parameter: held-out RMS of that parameter's equation, in its own unit, with the
   other tracked parameters fitted and this one at nominal (before) vs all fitted (after).
5. Support (:func:`support`): does the change from nominal pass the rule a ``diagnose`` finding must pass
   (the forward selection's gate on "this parameter fitted" vs "at nominal", then the significance judge; for
   R_ha the held-out temperature gain and the significance judge)? An off-nominal alert needs it.
6. R_ha: 1-parameter nonlinear least squares of ``log(R_ha/R_ha,nom)`` on the training part of the
   recorded temperatures simulated from the measured current (both nodes' start temperatures
   fitted as nuisances around the first recorded samples: a start pinned to one noisy sample biased R_ha by
   up to 1 % at a stated 0.08 %); uncertainty from the Jacobian, inflated by the residual's correlation time; held-out =
   temperature RMS on the held-out blocks. Assumes the nominal ambient temperature (``thermal.
   ambient_temperature``) and the other thermal parameters; a warm actuator cooling (or heating) during the
   recording makes it identifiable.

Only uses public names of the diagnosis modules; :data:`TRACKED` lists what is reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..params import ActuatorParams

#: tracked parameter -> (effect of the diagnosis library, unit, dotted parameter field)
TRACKED: dict[str, tuple[str, str, str]] = {
    "coulomb_friction": ("coulomb_friction", "N*m", "effects.coulomb_friction"),
    "viscous_damping": ("viscous_friction", "N*m*s/rad", "motor.viscous_damping"),
    "torque_constant_q": ("torque_constant_error", "N*m/A", "motor.torque_constant_q"),
    "phase_resistance": ("resistance_error", "ohm", "motor.phase_resistance"),
    "housing_to_ambient_resistance": ("thermal_parameters", "K/W", "thermal.housing_to_ambient_resistance"),
}

#: relative uncertainty floor of the R_ha fit (see :func:`_track_r_ha`)
R_HA_FLOOR = 1e-3

#: effects fitted by the linear joint fit, in column order
LINEAR_EFFECTS = ("coulomb_friction", "viscous_friction", "torque_constant_error", "resistance_error")


@dataclass
class Tracked:
    """One tracked parameter of one recording."""

    parameter: str
    effect: str
    unit: str
    value: float                 #: fitted value (nan when not checkable)
    uncertainty: float           #: 1 sigma
    nominal: float
    heldout_before: float = float("nan")
    heldout_after: float = float("nan")
    heldout_metric: str = ""
    status: str = "ok"           #: ok | not_checkable
    reason: str = ""
    #: the fitted change passes the acceptance rule of a ``diagnose`` finding (:func:`support`); an off-nominal
    #: alert needs it
    supported: bool = False
    support: str = ""            #: the rule's verdict in words (passed: ... / why not)

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _nominal(params: ActuatorParams, parameter: str) -> float:
    return float(params.to_flat()[TRACKED[parameter][2]])


def _rms(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if len(x) else float("nan")


def prepare(signals, params: ActuatorParams, *, holdout: float = 0.3):
    """The recording in the model's frame exactly as ``diagnose`` brings it there: :func:`..diagnosis.frame.
    equation_error.prepare`, then the search stage's sub-sample alignment of the measured current to the motion
    it drove (:func:`..diagnosis.search.stage.current_alignment` / ``align_mechanical``). Without the alignment
    the tracked friction pair absorbed the misalignment's residual: on the demo's unmodified ak80_9 recording
    (current 0.37 sample off the motion; the aligned mechanical residual is 16 % of the unaligned one) Coulomb
    came out 0.0548 +- 0.0019 N*m for the true 0.0298 and viscous -1.0e-4 for 1e-5, and with the alignment
    0.0300 +- 0.0003 and 8.6e-6 +- 1.7e-6."""
    from ..diagnosis.frame import equation_error as ee
    from ..diagnosis.search.stage import align_mechanical, current_alignment

    ctx = ee.prepare([(signals, False)], params, holdout=holdout)
    align = current_alignment(ctx) if ctx.blocks else None
    if align is not None:
        align_mechanical(ctx, align["shift"])
        ctx.notes.append(f"the mechanical equation reads the measured current {align['shift']:+.2f} sample(s) "
                         f"later (aligned with the motion it drove, as diagnose does)")
    return ctx


def track(signals, params: ActuatorParams, *, holdout: float = 0.3, ctx=None) -> list[Tracked]:
    """Fit the :data:`TRACKED` parameters on one cleaned recording (see the module docstring). ``ctx``: a
    context from :func:`prepare` (made here when None)."""
    from ..diagnosis.frame import candidates as cands
    from ..diagnosis.frame import equation_error as ee

    if ctx is None:
        ctx = prepare(signals, params, holdout=holdout)
    out = _track_linear(ctx, params, cands, ee)
    out.append(_track_r_ha(ctx, params, ee))
    return out


def _not_checkable(parameter: str, params, reason: str) -> Tracked:
    effect, unit, _ = TRACKED[parameter]
    return Tracked(parameter, effect, unit, float("nan"), float("nan"), _nominal(params, parameter),
                   status="not_checkable", reason=reason)


def _weights(ctx, nominal_fit, ee) -> dict[str, float]:
    """1 / scale of each equation's nominal training residual. The scale is the robust std, but never below
    a tenth of the residual's RMS: on a noise-free log most of a residual can be (nearly) exactly zero, its
    MAD then is ~0 and a weight of 1/MAD (floored at 1e12 before) let one equation swamp the fit and sent the
    held-out figures to 1e7."""
    ho = ctx.holdout_dec
    out = {}
    for eq, B in ctx.blocks.items():
        r = nominal_fit.resid[eq][B.rows(ho, "train")]
        scale = max(ee.robust_std(r), 0.1 * _rms(r), 1e-300)
        out[eq] = 1.0 / scale
    return out


def cluster_covariance(ctx, cols: dict, keys: list[str], weights: dict[str, float], fit, *,
                       min_clusters: int = 12) -> np.ndarray:
    """Covariance of the joint fit's coefficients robust to coloured residuals (a cluster / block sandwich).

    The fit's own covariance is ``s^2 (X'X)^-1`` with one pooled ``s^2`` of all equations, times the mean
    correlation time of the residuals. On a short or noise-free log the residual is model-form error (a
    slow, structured signal that the correlation-time window cuts off early) and the pooled ``s^2`` mixes
    equations of very different scale: the stated sd then was far too small (friction 0.0548 +- 0.0023 for a
    true 0.0298 on a 30 s closed-loop log). Here the training rows are cut into contiguous time clusters
    longer than the residuals' correlation time (rows of every equation at the same time in the same
    cluster) and ``cov = G/(G-1) A (sum_g s_g s_g') A'`` with the cluster scores ``s_g = sum Z_i w^2 r_i``
    and ``A = (Z'W^2X)^-1`` (least squares: Z = X; instrumental variables: the instruments). Honest for
    any residual correlation shorter than a cluster; with few clusters it is itself uncertain (G dof)."""
    from ..diagnosis.frame.equation_error import integrated_autocorrelation_time

    ho = ctx.holdout_dec
    Xs, Zs, rs, idx = [], [], [], []
    tau = 1.0
    for eq, B in ctx.blocks.items():
        rows = B.rows(ho, "train")
        if not rows.any():
            continue
        w = weights[eq]
        X = np.zeros((int(rows.sum()), len(keys)))
        Z = np.zeros_like(X)
        for j, k in enumerate(keys):
            c = cols[k].get(eq)
            if c is None:
                continue
            X[:, j] = c[rows]
            inst = ctx.instrument(k)
            Z[:, j] = inst[eq][rows] if inst is not None and inst.get(eq) is not None else c[rows]
        r = fit.resid[eq][rows]
        r = np.where(np.isfinite(r), r, 0.0)
        Xs.append(w * X)
        Zs.append(w * Z)
        rs.append(w * r)
        idx.append(np.flatnonzero(rows))
        tau = max(tau, integrated_autocorrelation_time(r))
    X, Z, r, i = np.vstack(Xs), np.vstack(Zs), np.concatenate(rs), np.concatenate(idx)
    n_time = len(np.unique(i))
    # clusters: >= 4 correlation times long, at least min_clusters of them when the log allows
    length = max(1, int(math.ceil(4.0 * tau)))
    n_cl = max(2, min(n_time // length, 200))
    if n_cl < min_clusters:
        n_cl = max(2, min(min_clusters, n_time // 2))
    rank = np.searchsorted(np.unique(i), i)          # time order of each row's sample (equations share it)
    g = (rank * n_cl) // max(1, n_time)
    A = np.linalg.pinv(Z.T @ X)
    S = np.zeros((n_cl, len(keys)))
    np.add.at(S, g, Z * r[:, None])
    meat = S.T @ S * (n_cl / max(1, n_cl - 1))
    return A @ meat @ A.T


def _track_linear(ctx, params, cands, ee) -> list[Tracked]:
    from ..diagnosis.frame.selection import checkable, fit_model

    lib = cands.library()
    names = {e: p for p, (e, _, _) in TRACKED.items()}
    out: list[Tracked] = []
    variants = {}
    for effect in LINEAR_EFFECTS:
        cand = lib[effect]
        vs, why = checkable(ctx, cand, {})
        if not vs:
            out.append(_not_checkable(names[effect], params, (why or {}).get("reason", "no usable form")))
            continue
        variants[effect] = vs[0]
    if not variants or not ctx.blocks:
        return out
    cols = {k: ctx.column(k, b) for k, b in ctx.nuisance.items()}
    keys = list(ctx.nuisance)
    iterating = {}
    for effect, v in variants.items():
        for k, b in v.columns.items():
            cols[k] = ctx.column(k, b)
            keys.append(k)
        if v.iterate is not None:
            iterating[v.keys[0]] = v
    nominal_fit = ee.fit_columns(ctx, {k: cols[k] for k in ctx.nuisance}, list(ctx.nuisance),
                                 {eq: 1.0 for eq in ctx.blocks})
    ho = ctx.holdout_dec
    weights = _weights(ctx, nominal_fit, ee)
    full = fit_model(ctx, cols, keys, weights, iterating)
    coef = full.coef()
    # the fit's covariance, or the cluster sandwich where that is larger (coloured / model-form residuals)
    try:
        cov_cl = cluster_covariance(ctx, cols, list(full.keys), weights, full)
    except (np.linalg.LinAlgError, ValueError):
        cov_cl = np.zeros_like(full.cov)
    for effect, v in variants.items():
        idx = [full.keys.index(k) for k in v.keys]
        c = np.array([coef[k] for k in v.keys])
        cov = full.cov[np.ix_(idx, idx)]
        cov_c = cov_cl[np.ix_(idx, idx)]
        inflated = np.all(np.isfinite(cov_c)) and np.trace(cov_c) > np.trace(cov)
        pars = lib[effect].to_params(c, cov_c if inflated else cov, v.keys, v, ctx)
        parameter = names[effect]
        rec = pars.get(parameter)
        if rec is None:
            out.append(_not_checkable(parameter, params, "the fit did not return this parameter"))
            continue
        # held-out: this effect at nominal (others fitted) vs all fitted, RMS of its equation in its own unit
        rest = [k for k in keys if k not in v.keys]
        without = fit_model(ctx, dict(cols), rest, weights, {k: w for k, w in iterating.items() if k in rest})
        eq = next((e for e in lib[effect].equations if e in ctx.blocks), None)
        if eq is not None:
            rows = ctx.blocks[eq].rows(ho, "holdout")
            before, after = _rms(without.resid[eq][rows]), _rms(full.resid[eq][rows])
            metric = f"held-out {eq} equation error RMS [{ctx.blocks[eq].unit}]"
        else:
            before, after, metric = float("nan"), float("nan"), ""
        reason = ("sd from the time-cluster sandwich (coloured residual: the fit's own sd was "
                  f"{math.sqrt(max(float(np.trace(cov)), 0.0) / max(1, len(idx))):.2g} in fit units)"
                  if inflated else "")
        ok, why = support(ctx, lib[effect], v, without, full, weights, {effect: pars}, params)
        out.append(Tracked(parameter, effect, TRACKED[parameter][1], float(rec["value"]), float(rec["sd"]),
                           _nominal(params, parameter), before, after, metric, reason=reason, supported=ok,
                           support=why))
    return out


def support(ctx, cand, variant, without, full, weights, claimed: dict, params: ActuatorParams) -> tuple[bool, str]:
    """Is the fitted change of ``cand`` supported the way a ``diagnose`` finding must be? ONE rule, the
    diagnosis' own code: the forward selection's gate (:func:`..diagnosis.frame.selection.judge_form`: plausible,
    ΔBIC, a significant held-out improvement that worsens no equation) of the fit ``full`` against ``without``
    (this effect at nominal, the others fitted), then the practical significance and identifiability judge
    (:func:`..diagnosis.significance.judge`, diagnose's default tolerance and uncertainty bound) on ``claimed``
    (effect -> the candidate's parameter mapping)."""
    from ..diagnosis import significance
    from ..diagnosis.pipeline import DiagnoseOptions
    from ..diagnosis.frame.selection import judge_form

    opts = DiagnoseOptions()
    ev = judge_form(ctx, cand, variant, list(variant.keys), without, full, weights, opts.gate)
    if not ev.passed:
        return False, ("not decidable: " if ev.undecided else "not supported: ") + ev.reason.removeprefix("not decidable: ")
    verdicts = significance.judge(claimed, params, tolerance=opts.tolerance,
                                  max_relative_uncertainty=opts.max_relative_uncertainty)
    if verdicts:
        return False, "; ".join(v.message for v in verdicts)
    return True, ev.reason


def _track_r_ha(ctx, params: ActuatorParams, ee) -> Tracked:
    from scipy.optimize import least_squares

    parameter = "housing_to_ambient_resistance"
    temps = [c for c in ("housing_temperature", "winding_temperature") if c in ctx.have]
    if not temps or "i_q" not in ctx.sig:
        return _not_checkable(parameter, params, "needs current and a recorded temperature")
    span = max(float(np.ptp(ctx.raw[c][ctx.valid[c]])) if ctx.valid[c].any() else 0.0 for c in temps)
    if span < 1.0:
        return _not_checkable(parameter, params, f"the recorded temperature changes by {span:.2f} K (< 1 K)")
    every = max(1, int(ctx.fs / 10.0))
    idx = np.arange(0, len(ctx.t), every)
    a0 = ctx.segments[0][0]
    T0w = ctx.raw.get("winding_temperature", ctx.raw.get("housing_temperature"))[a0]
    T0h = ctx.raw.get("housing_temperature", ctx.raw.get("winding_temperature"))[a0]
    R0 = params.thermal.housing_to_ambient_resistance
    ho = np.concatenate([ctx.holdout_raw[idx]] * len(temps))
    # the start temperatures are nuisances fitted with R_ha: the first recorded sample carries the sensor's
    # noise, and a cooling curve pinned to a noisy start biased R_ha by up to 1 % with a stated sd of 0.08 %
    # (z up to 12 over 20 generated recordings); the node that is not recorded starts at an unknown temperature

    def resid(x, step: int = every) -> np.ndarray:
        p = params.replace(**{"thermal.housing_to_ambient_resistance": R0 * math.exp(x[0])})
        T_w, T_h = ee.thermal_response(ctx, p, T0=(T0w + x[1], T0h + x[2]), every=step)
        sims = {"winding_temperature": T_w, "housing_temperature": T_h}
        return np.concatenate([np.where(ctx.valid[c][idx], sims[c][idx] - ctx.raw[c][idx], np.nan) for c in temps])

    def train(x, step: int = every):
        return np.nan_to_num(resid(x, step)[~ho])

    lim = math.log(10)
    x0 = np.zeros(3)
    lo, hi = np.array([-lim, -30.0, -30.0]), np.array([lim, 30.0, 30.0])
    # nominal "before": the best start temperatures with the nominal R_ha
    s0 = least_squares(lambda d: train(np.array([0.0, d[0], d[1]])), np.zeros(2), bounds=(lo[1:], hi[1:]),
                       max_nfev=40)
    r0 = resid(np.array([0.0, *s0.x]))
    sol = least_squares(train, np.array([0.0, *s0.x]), bounds=(lo, hi), x_scale=np.array([0.3, 1.0, 1.0]),
                        max_nfev=80)
    r1 = resid(sol.x)
    rt = r1[~ho & np.isfinite(r1)]
    s2 = float(rt @ rt) / max(1, len(rt) - len(x0))
    J = sol.jac
    tau = ee.integrated_autocorrelation_time(rt) if len(rt) > 8 else 1.0
    var_x = float(np.linalg.pinv(J.T @ J)[0, 0]) * s2 * tau
    # a floor for what the fit cannot see: the Joule power is the mean of the SAMPLED current squared, the
    # ambient is the nominal one. On noise-free generated logs (where only the 0.01 K quantisation is left)
    # R_ha came out up to 0.02 % off at a stated 0.006 % (z 3.7); 0.1 % covers that with a margin
    var_x = max(var_x, R_HA_FLOOR ** 2)
    value = R0 * math.exp(float(sol.x[0]))
    note = "; start temperatures fitted as nuisances" + (" (one node not recorded)" if len(temps) == 1 else "")
    sd = value * math.sqrt(max(var_x, 0.0))
    before, after = _rms(r0[ho]), _rms(r1[ho])
    ok, why = _thermal_support(before, after, value, sd, params)
    return Tracked(parameter, "thermal_parameters", "K/W", value, sd, R0, before, after,
                   "held-out temperature RMS [K] (" + ", ".join(temps) + ")" + note, supported=ok, support=why)


def _thermal_support(before: float, after: float, value: float, sd: float, params: ActuatorParams) -> tuple[bool, str]:
    """The R_ha change is supported when the held-out temperature RMS improves by more than the selection gate's
    least relative gain (``GateConfig.min_heldout_gain``) and the significance judge keeps it (tolerance,
    identifiability), as for a thermal finding of ``diagnose``."""
    from ..diagnosis import significance
    from ..diagnosis.pipeline import DiagnoseOptions

    opts = DiagnoseOptions()
    if not (math.isfinite(before) and math.isfinite(after) and before > 0):
        return False, "not supported: no held-out temperature"
    gain = 1.0 - after / before
    if gain <= opts.gate.min_heldout_gain:
        return False, (f"not supported: held-out temperature RMS {before:.3g} -> {after:.3g} K ({-100 * gain:+.2f} %), "
                       f"not better by more than {100 * opts.gate.min_heldout_gain:g} %")
    field = TRACKED["housing_to_ambient_resistance"][2].split(".", 1)[1]
    verdicts = significance.judge({TRACKED["housing_to_ambient_resistance"][0]: {field: {"value": value, "sd": sd, "field": field}}},
                                  params, tolerance=opts.tolerance,
                                  max_relative_uncertainty=opts.max_relative_uncertainty)
    if verdicts:
        return False, "; ".join(v.message for v in verdicts)
    return True, f"passed: held-out temperature RMS {before:.3g} -> {after:.3g} K ({-100 * gain:+.2f} %)"
