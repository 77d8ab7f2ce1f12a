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

1. :func:`..diagnosis.equation_error.prepare` with the nominal parameters (same filter, decimation and
   held-out blocks as ``diagnose``).
2. ONE joint least-squares fit (:func:`..diagnosis.selection.fit_model`: instrumental variables for
   current-proportional columns, fixed-point K_t column) of the four linear columns that are checkable
   plus the always-fitted nuisance columns, each equation weighted by 1/robust std of its nominal training
   residual. The joint fit keeps friction from absorbing a K_t change and vice versa.
3. Values = nominal + fitted change, mapped by each candidate's own ``to_params``; uncertainty = the
   fit's standard deviation (covariance inflated by the residual's correlation time).
4. Held-out before/after per parameter: held-out RMS of that parameter's equation with the other
   tracked parameters fitted and this one at nominal (before) vs all fitted (after).
5. R_ha: 1-parameter nonlinear least squares of ``log(R_ha/R_ha,nom)`` on the training part of the
   recorded temperatures simulated from the measured current (starting at the first recorded
   temperatures; when only one of winding / housing is recorded, the other node's start temperature is
   fitted too, as a nuisance); uncertainty from the Jacobian, inflated by the residual's correlation time; held-out =
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

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _nominal(params: ActuatorParams, parameter: str) -> float:
    return float(params.to_flat()[TRACKED[parameter][2]])


def _rms(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if len(x) else float("nan")


def track(signals, params: ActuatorParams, *, holdout: float = 0.3, ctx=None) -> list[Tracked]:
    """Fit the :data:`TRACKED` parameters on one cleaned recording (see the module docstring)."""
    from ..diagnosis import candidates as cands
    from ..diagnosis import equation_error as ee

    if ctx is None:
        ctx = ee.prepare([(signals, False)], params, holdout=holdout)
    out = _track_linear(ctx, params, cands, ee)
    out.append(_track_r_ha(ctx, params, ee))
    return out


def _not_checkable(parameter: str, params, reason: str) -> Tracked:
    effect, unit, _ = TRACKED[parameter]
    return Tracked(parameter, effect, unit, float("nan"), float("nan"), _nominal(params, parameter),
                   status="not_checkable", reason=reason)


def _track_linear(ctx, params, cands, ee) -> list[Tracked]:
    from ..diagnosis.selection import checkable, fit_model

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
    weights = {eq: 1.0 / max(ee.robust_std(nominal_fit.resid[eq][B.rows(ho, "train")]), 1e-12)
               for eq, B in ctx.blocks.items()}
    full = fit_model(ctx, dict(cols), keys, weights, iterating)
    coef = full.coef()
    for effect, v in variants.items():
        idx = [full.keys.index(k) for k in v.keys]
        c = np.array([coef[k] for k in v.keys])
        cov = full.cov[np.ix_(idx, idx)]
        pars = lib[effect].to_params(c, cov, v.keys, v, ctx)
        parameter = names[effect]
        rec = pars.get(parameter)
        if rec is None:
            out.append(_not_checkable(parameter, params, "the fit did not return this parameter"))
            continue
        # held-out: this effect at nominal (others fitted) vs all fitted
        rest = [k for k in keys if k not in v.keys]
        without = fit_model(ctx, dict(cols), rest, weights, {k: w for k, w in iterating.items() if k in rest})
        eqs = [eq for eq in lib[effect].equations if eq in ctx.blocks]
        before = _rms(np.concatenate([without.resid[eq][ctx.blocks[eq].rows(ho, "holdout")] * weights[eq]
                                      for eq in eqs])) if eqs else float("nan")
        after = _rms(np.concatenate([full.resid[eq][ctx.blocks[eq].rows(ho, "holdout")] * weights[eq]
                                     for eq in eqs])) if eqs else float("nan")
        metric = ("held-out equation error RMS, " + " + ".join(eqs) +
                  " (each in units of its nominal residual's robust std)")
        out.append(Tracked(parameter, effect, TRACKED[parameter][1], float(rec["value"]), float(rec["sd"]),
                           _nominal(params, parameter), before, after, metric))
    return out


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
    # the node that is not recorded starts at an unknown temperature: a nuisance offset fitted with R_ha
    free_T0 = len(temps) == 1

    def resid(x) -> np.ndarray:
        p = params.replace(**{"thermal.housing_to_ambient_resistance": R0 * math.exp(x[0])})
        d = x[1] if free_T0 else 0.0
        T0 = (T0w + d, T0h) if temps == ["housing_temperature"] else (T0w, T0h + d)
        T_w, T_h = ee.thermal_response(ctx, p, T0=T0, every=every)
        sims = {"winding_temperature": T_w, "housing_temperature": T_h}
        return np.concatenate([np.where(ctx.valid[c][idx], sims[c][idx] - ctx.raw[c][idx], np.nan) for c in temps])

    def train(x):
        return np.nan_to_num(resid(x)[~ho])

    x0 = np.zeros(2 if free_T0 else 1)
    lim = math.log(10)
    lo = np.array([-lim, -30.0])[: len(x0)]
    hi = np.array([lim, 30.0])[: len(x0)]
    r0 = resid(x0)
    if free_T0:    # nominal "before": the best start temperature with the nominal R_ha
        s0 = least_squares(lambda d: train(np.array([0.0, d[0]])), np.zeros(1), bounds=(-30.0, 30.0), max_nfev=30)
        r0 = resid(np.array([0.0, s0.x[0]]))
    sol = least_squares(train, x0, bounds=(lo, hi), x_scale=np.array([0.3, 1.0])[: len(x0)], max_nfev=60)
    r1 = resid(sol.x)
    rt = r1[~ho & np.isfinite(r1)]
    s2 = float(rt @ rt) / max(1, len(rt) - len(x0))
    J = sol.jac
    tau = ee.integrated_autocorrelation_time(rt) if len(rt) > 8 else 1.0
    var_x = float(np.linalg.pinv(J.T @ J)[0, 0]) * s2 * tau
    value = R0 * math.exp(float(sol.x[0]))
    note = "; the unrecorded node's start temperature fitted as a nuisance" if free_T0 else ""
    return Tracked(parameter, "thermal_parameters", "K/W", value, value * math.sqrt(max(var_x, 0.0)), R0,
                   _rms(r0[ho]), _rms(r1[ho]), "held-out temperature RMS [K] (" + ", ".join(temps) + ")" + note)
