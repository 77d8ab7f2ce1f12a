"""Inverter dead time.

The catalogue record and its regressor forms (``FORMS``: the sign form and current-band forms, excitation test,
parameter mapping, its own reason when the held-out gate cannot decide it)."""

from __future__ import annotations

import functools
import math

import numpy as np

from ... import frames, kernel
from .forms import Forms, Variant, frac, sd, smooth_sign
from .record import Bounds, Effect, Param, Story

EFFECT = Effect(
    name="dead_time", rank=190,
    description="inverter dead time: the applied voltage falls short by a constant times the sign of the current",
    equations=("electrical",), needs=("voltage_q", "current", "velocity|position"), simulated=True,
    confusable={"coulomb_friction": "friction acts on torque: compare the voltage equation at standstill "
                "with current of both signs"},
    params=(Param("dead_time_voltage", "V", bounds=(Bounds(lo=0.0, lo_sd=3.0),)), Param("dead_time", "s", "drive.dead_time"),
            Param("dead_time_current_band", "A", "drive.dead_time_current_band")),
    story=Story.ELECTRICAL_CURRENT_TREND, replay_form=True,
)


def _sign_width(ctx, i) -> float:
    """Width [A] the dead-time sign form is smoothed over: 3 x the current's content above the low-pass (sensor
    noise, and the chatter of a drive whose sign is sampled once per control period) — the sign cannot be told
    closer to zero than that."""
    return max(3.0 * float(np.std(i - ctx.dec.lowpass(i))), 1e-3 * float(np.percentile(np.abs(i), 90)), 1e-6)


def col_dead_time(ctx):
    S = ctx.sig
    i = S["i_col"]
    return {"electrical": smooth_sign(ctx.dec.lowpass(i), _sign_width(ctx, i))}


#: the current's sign is not visible when the sign form's width exceeds this percentile of |low-passed i_q|
DEAD_TIME_IN_BAND_PERCENTILE = 99.5


def dead_time_in_band(ctx):
    """Why a dead time cannot be decided when the current stays inside its chatter band: (reason, what to do), or
    None. The sign form's smoothing width (:func:`_sign_width`) exceeds the 99.5th percentile of |low-passed
    i_q|: over the whole recording the form is linear in the current, i.e. a resistance. Issue #14, motulator's
    dead time without load (now ``tp_dead_time_in_band``): width 0.71 A for |i_q| <= 0.41 A; its sign sampled once
    per 100 us control period makes the phase currents chatter period-2 and the leg error holds them near zero (a
    sliding mode): its mean is linear in the current (a resistance, +0.80 ohm fitted, about L/T_s) and the rest
    follows the per-period current signs, which no log at 1 kHz holds; given a resistance, no dead-time form of
    the logged signals adds anything (ΔBIC <= -1.8)."""
    if "i_q" not in ctx.sig:
        return None
    i = ctx.sig["i_q"]
    width = _sign_width(ctx, i)
    top = float(np.percentile(np.abs(ctx.dec.lowpass(i)), DEAD_TIME_IN_BAND_PERCENTILE))
    if not width > top:
        return None
    return (f"the current stays inside the dead time's chatter band (its content above the low-pass, "
            f"{width / 3:.2g} A RMS, covers |i_q| <= {top:.2g} A, the {DEAD_TIME_IN_BAND_PERCENTILE:g}th "
            f"percentile): there the inverter's error is linear in the current, a resistance in disguise",
            f"record with currents of both signs well beyond {width:.2g} A (a load, faster accelerations)")


def col_dead_band(band: float):
    """Dead time with a current band (``drive.dead_time_current_band``): minus the kernel's d-q error per volt of
    leg error (:func:`kernel.dead_time_error_dq` with ``v_dt`` = 1, the same function the simulator applies), q
    component, at the low-passed recorded currents and electrical angle; its coefficient is ``V_dt`` per leg."""
    def build(ctx):
        S = ctx.sig
        i = ctx.dec.lowpass(S["i_d"]) + 1j * ctx.dec.lowpass(S["i_col"])
        th_e = ctx.params.motor.pole_pairs * S["theta"]
        delta = 1.0 if ctx.params.motor.winding == "delta" else 0.0
        e = kernel.dead_time_error_dq(i, np.zeros(len(i), complex), th_e, 1.0, delta, 0.0, float(band))
        return {"electrical": -np.asarray(e).imag}
    return build


#: current bands the dead-time candidate offers besides the sign, as fractions of the 95th percentile of the
#: recorded |i_dq|: in a drive whose current chatters about zero (a sign sampled once per control period, as in
#: motulator's converter and gym-electric-motor's) or whose switching ripple reverses small currents, the legs'
#: error is linear inside the band (gym-electric-motor: 1.26 us for 1 with the sign, 1.01 with a 0.22 A band)
DEAD_TIME_BANDS = (0.05, 0.12, 0.25, 0.5)


#: the widest band offered or refined, same units: a band the currents seldom leave is a resistance (R i) in
#: disguise (a 40 % resistance error on motulator's near-zero current was fitted as a 0.64 A band at i95 0.18 A)
DEAD_TIME_BAND_MAX = 0.5


#: the sign form alone must improve the nominal model this much (ΔBIC, relative held-out RMS) before band forms
#: are offered: a band only refines a dead time the data show. Offered freely, a 0.05 A band with 7 ns (its in-band
#: slope a resistance) and a resistance error 32 % low explained a 250 Hz log's sampling artefact together, and each
#: "confirmed" the other in the leave-one-out simulation (builtin coulomb_250hz; the sign form there: -1.2 % held-out)
DEAD_TIME_BAND_GATE = (10.0, 0.02)


def _sign_form_shows(ctx) -> bool:
    tools = ctx.tools
    if "electrical" not in ctx.blocks:
        return False
    cols = {k: ctx.column(k, b) for k, b in ctx.nuisance.items()}
    cols["dead"] = ctx.column("dead", col_dead_time)
    keys = list(ctx.nuisance)
    base = tools.fit_columns(ctx, cols, keys, {eq: 1.0 for eq in ctx.blocks})
    w = {eq: 1.0 / max(tools.robust_std(base.resid[eq][B.rows(ctx.holdout_dec, "train")]), 1e-12)
         for eq, B in ctx.blocks.items()}
    base = tools.fit_columns(ctx, cols, keys, w)
    new = tools.fit_columns(ctx, cols, keys + ["dead"], w)
    ho = tools.heldout_comparison(ctx, base, new, w)
    return tools.delta_bic(base, new) > DEAD_TIME_BAND_GATE[0] and ho.get("available", False) \
        and ho.get("rel", 0.0) > DEAD_TIME_BAND_GATE[1]


def v_dead_time(ctx, loc):
    """The sign form (smoothed at the current's noise) and, with current of both signs, band forms
    (:data:`DEAD_TIME_BANDS`), the band refined in the final fit."""
    out = [Variant(EFFECT.name, EFFECT.name, {"dead": col_dead_time})]
    if "theta" not in ctx.sig or excite_dead_time(ctx):
        # under a one-signed current the sign form is a constant and a band only adds a ripple correction to it
        # that the equation error cannot size; the unexcited-alias check must not be offered a band wider than the
        # current's swing there either (R i in disguise)
        return out
    i = np.hypot(ctx.dsig("i_q"), ctx.dsig("i_d") if "i_d" in ctx.sig else 0.0)
    ref = float(np.percentile(i, 95)) if len(i) else 0.0
    if not ref > 0.0 or not _sign_form_shows(ctx):
        return out
    for f in DEAD_TIME_BANDS:
        b = f * ref
        key = f"dead_band@{b:.6g}"
        out.append(Variant(EFFECT.name, f"current band {b:.3g} A", {key: col_dead_band(b)},
                           hyper={"dead_time_current_band": b},
                           nonlinear={"dead_time_current_band": (b, max(0.02 * ref, b / 2.5),
                                                                 min(DEAD_TIME_BAND_MAX * ref, b * 2.5),
                                               lambda c, v, key=key: {key: col_dead_band(v)})}))
    return out


def excite_dead_time(ctx):
    i = ctx.dsig("i_q")
    pos, neg = frac(i > 0), frac(i < 0)
    return None if min(pos, neg) > 0.05 else "needs current of both signs"


def dead_time_q_factor(winding: str) -> float:
    """Angle average of the q-axis voltage error the simulator's dead-time term puts against a q-axis current,
    per V_dt = t_d f_pwm V_bus (i_d = 0), for a ``winding`` of "wye" or "delta": ``-mean e_q`` of
    :func:`kernel.dead_time_error_dq` over one electrical turn (the same function the simulator applies;
    √(3/2)·4/π = 1.5594 for wye, √3 times that for delta, where each winding sees the difference of two legs).
    Midpoint rule on 0.1° cells: the six-step sign changes fall on cell edges, so it is exact to ~1e-7."""
    if winding not in frames.WINDINGS:
        raise ValueError(f"winding must be one of {frames.WINDINGS}, got {winding!r}")
    return _dead_time_q_factor(winding)


@functools.lru_cache(maxsize=4)
def _dead_time_q_factor(winding: str) -> float:
    th = (np.arange(3600) + 0.5) * (2.0 * math.pi / 3600)
    e = kernel.dead_time_error_dq(np.full(th.shape, 1j), np.zeros(th.shape, complex), th, 1.0,
                                  1.0 if winding == "delta" else 0.0, 0.0)
    return -float(np.mean(e.imag))


def params_dead_time(coef, cov, keys, variant, ctx):
    """The sign(i) column's coefficient is the mean q-axis voltage the drive adds against its current,
    :func:`dead_time_q_factor` (winding) × t_d f_pwm V_bus: drive.dead_time. A band form's coefficient is the
    leg's ``V_dt = t_d f_pwm V_bus`` itself (its column holds the angle average), its band
    drive.dead_time_current_band; ``dead_time_voltage`` is the q-axis equivalent in both."""
    c = float(coef[0])
    d = ctx.params.drive
    q = dead_time_q_factor(ctx.params.motor.winding)
    band = variant.hyper.get("dead_time_current_band") if variant is not None else None
    per_leg = d.pwm_frequency * d.bus_voltage
    v = c * q if band is not None else c              # q-axis equivalent [V]
    sd_v = sd(cov, 0) * (q if band is not None else 1.0)
    t_d = v / (q * per_leg)
    out = {"dead_time_voltage": {"value": v, "sd": sd_v, "unit": "V", "field": None, "delta": v},
           "dead_time": {"value": t_d, "sd": sd_v / (q * per_leg),
                         "unit": "s", "field": "drive.dead_time" if t_d > 0 else None, "delta": t_d}}
    if band is None and "i_col" in ctx.sig:
        # the sign form was fitted smoothed, tanh(i / w) (:func:`col_dead_time`): written as the band of the same
        # slope at zero, not as the ideal sign (motulator tp_dead_time seeds 2/3: w = 0.36 A; written as the
        # ideal sign the replay clamped or chattered at every crossing: held-out speed 0.092 vs 0.050 rad/s)
        band = _sign_width(ctx, ctx.sig["i_col"])
    if band is not None:
        out["dead_time_current_band"] = {"value": float(band), "sd": float("nan"), "unit": "A",
                                         "field": "drive.dead_time_current_band" if t_d > 0 else None,
                                         "delta": float(band)}
    return out


FORMS = Forms(v_dead_time, excite_dead_time, params_dead_time, dead_time_in_band)
