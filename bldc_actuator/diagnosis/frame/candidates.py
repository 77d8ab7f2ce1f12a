"""The library of named candidate effects: each a small group of regressor columns built from the shared
effect terms (:mod:`bldc_actuator.effects`), with the channels it needs, an excitation check, how its
fitted coefficients map onto the parameter file, and what it is confusable with.

A column is ``key -> {equation: raw-rate array}``; its coefficient is the *change* of a parameter
(the equation-error residual of :mod:`.equation_error` is ``Σ column · Δparameter``). Sign conventions::

    mechanical r_m = K i_q - J ω' - b ω - τ_f - τ_cog - τ_ext/N    (true - nominal opposing torques)
    electrical r_e = v_q - R i_q - L i_q' - K ω - p ω L i_d

Variants: a candidate may offer several forms (cogging order, Stribeck velocity, which equations a
torque-constant error enters...); selection tries each and keeps the best.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ... import effects, frames, kernel
from ..effects import Effect, Route, Story, registry
from ..effects.backlash import BACKLASH_EXPERIMENT
from ..effects.forms import Forms, Single, Variant, v_single, params_generic
from ..effects.forms import elec as _elec, flat as _flat, mech as _mech, sd as _sd, smooth_sign as _smooth_sign

#: frame factors a torque-constant error is compared with (fitted K / nominal K): every ratio a K_t read in one
#: frame and entered as another produces, drives on delta motors included (:func:`frames.torque_constant_frame_factors`)
FRAME_FACTORS = {name: value for name, (value, _) in frames.torque_constant_frame_factors().items()}


def match_frame_factor(ratio: float, sigma: float) -> str:
    """Name of the frame factor within max(2 %, 2σ) of ``ratio``, else ``"none"``."""
    best, best_err = "none", float("inf")
    for name, f in FRAME_FACTORS.items():
        err = abs(ratio - f)
        if err <= max(0.02 * f, 2.0 * sigma) and err < best_err:
            best, best_err = name, err
    return best


@dataclass
class Candidate:
    name: str
    equations: tuple[str, ...]
    needs: tuple[str, ...]                        #: channels ("a|b" = either)
    description: str                              #: plain words: what physics this is
    simulated: bool                               #: has parameters in the schema
    confusable: dict[str, str] = field(default_factory=dict)   #: other effect -> experiment separating them
    variants: Callable = None                     #: (ctx, locate) -> list[Variant]
    excited: Callable = None                      #: (ctx) -> None | reason it is not identifiable here
    to_params: Callable = None                    #: (coef, cov, keys, variant, ctx) -> Finding parameters
    #: a candidate that is never fitted on its own but may hide behind these accepted effects (checked as an
    #: alias only for them, :func:`..selection.unexcited_aliases`); None: behind any effect sharing an equation
    hides_behind: tuple[str, ...] | None = None
    #: (ctx) -> None | (why, what to do): the candidate's own reason when the held-out gate cannot decide it
    #: (:func:`..selection._gate`), in place of "held-out too short" where the data, not its length, are at fault
    undecided_why: Callable | None = None
    #: the effect's registry record (every facet the stages ask about)
    record: Effect | None = None


# ---------------------------------------------------------------------------------------- builders

def _fric_cols(ctx, omega_s):
    return effects.friction_basis(ctx.sig["omega_s"], omega_s, ctx.omega_eps)


def col_fric_sign(ctx):
    return {"mechanical": _fric_cols(ctx, 1.0)[:, 0]}


def col_fric_abs(ctx):
    return {"mechanical": _fric_cols(ctx, 1.0)[:, 1]}


def col_stribeck(omega_s):
    return lambda ctx: {"mechanical": _fric_cols(ctx, omega_s)[:, 2]}


def col_viscous(ctx):
    return {"mechanical": effects.viscous_basis(ctx.sig["omega"])[:, 0]}


def resolvable(ctx, order) -> np.ndarray:
    """Weight in [0, 1]: 1 where an angle harmonic of ``order`` (cycles per revolution) at the current speed
    lies well inside the low-pass (f < fc/2), falling smoothly to 0 at f = fc. Above that the measured
    signals cannot show it (and the raw-rate regressor would alias), so the column is switched off there."""
    f = np.abs(ctx.sig["omega_s"]) * order / (2 * math.pi)
    fc = ctx.dec.fc
    x = np.clip((f - 0.5 * fc) / (0.5 * fc), 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(math.pi * x))


def col_harmonic(order, k, which, current_weighted=False):
    def build(ctx):
        b = effects.angle_harmonic_basis(ctx.sig["theta"], order, k)[:, 2 * (k - 1) + (0 if which == "cos" else 1)]
        b = b * resolvable(ctx, k * order)
        if current_weighted:
            b = b * ctx.sig["i_col"]
        return {"mechanical": b}
    return build


def col_load(kind):
    def build(ctx):
        N = ctx.params.gear.gear_ratio
        th_out = ctx.sig["theta"] / N
        f = {"sin": np.sin(th_out), "cos": np.cos(th_out), "lin": th_out, "const": np.ones_like(th_out)}[kind]
        return {"mechanical": f / N}
    return build


def col_kt(equations, kappa: float = 1.0):
    """Torque-constant scale κ = K_true/K (coefficient κ - 1). Mechanical (current units): i = P/(κK), so
    the column is -P/(κ̂K) at the current estimate κ̂ (iterated to a fixed point); electrical: K ω."""
    def build(ctx):
        S = ctx.sig
        out = {}
        if "mechanical" in equations:
            out["mechanical"] = -S["P"] / kappa       # divided by K with every mechanical column
        if "electrical" in equations and "v_q" in S:
            out["electrical"] = S["K"] * S["omega"]
        return out
    return build


def col_inertia(ctx):
    return {"mechanical": ctx.sig["omega_dot"]}


def col_r_err(ctx):
    m = ctx.params.motor
    S = ctx.sig
    return {"electrical": S["i_col"] * S["R"] / m.phase_resistance}


def col_l_err(ctx):
    return {"electrical": ctx.sig["di_dt"]}


def col_r_temp(ctx):
    m = ctx.params.motor
    S = ctx.sig
    return {"electrical": m.phase_resistance * (S["T_w"] - m.reference_temperature) * S["i_col"]}


def col_magnet(ctx):
    m = ctx.params.motor
    S = ctx.sig
    dT = S["T_h"] - m.reference_temperature
    out = {"mechanical": -dT * S["P"]}
    if "v_q" in S:
        out["electrical"] = m.torque_constant_q * dT * S["omega"]
    return out


def col_saturation(ctx):
    S = ctx.sig
    return {"mechanical": S["K"] * S["i_col"] * np.abs(S["i_col"])}


def _sign_width(ctx, i) -> float:
    """Width [A] the dead-time sign form is smoothed over: 3 x the current's content above the low-pass (sensor
    noise, and the chatter of a drive whose sign is sampled once per control period) — the sign cannot be told
    closer to zero than that."""
    return max(3.0 * float(np.std(i - ctx.dec.lowpass(i))), 1e-3 * float(np.percentile(np.abs(i), 90)), 1e-6)


def col_dead_time(ctx):
    S = ctx.sig
    i = S["i_col"]
    return {"electrical": _smooth_sign(ctx.dec.lowpass(i), _sign_width(ctx, i))}


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
    from .equation_error import delta_bic, fit_columns, heldout_comparison, robust_std

    if "electrical" not in ctx.blocks:
        return False
    cols = {k: ctx.column(k, b) for k, b in ctx.nuisance.items()}
    cols["dead"] = ctx.column("dead", col_dead_time)
    keys = list(ctx.nuisance)
    base = fit_columns(ctx, cols, keys, {eq: 1.0 for eq in ctx.blocks})
    w = {eq: 1.0 / max(robust_std(base.resid[eq][B.rows(ctx.holdout_dec, "train")]), 1e-12)
         for eq, B in ctx.blocks.items()}
    base = fit_columns(ctx, cols, keys, w)
    new = fit_columns(ctx, cols, keys + ["dead"], w)
    ho = heldout_comparison(ctx, base, new, w)
    return delta_bic(base, new) > DEAD_TIME_BAND_GATE[0] and ho.get("available", False) \
        and ho.get("rel", 0.0) > DEAD_TIME_BAND_GATE[1]


def v_dead_time(ctx, loc):
    """The sign form (smoothed at the current's noise) and, with current of both signs, band forms
    (:data:`DEAD_TIME_BANDS`), the band refined in the final fit."""
    out = [Variant("dead_time", "dead_time", {"dead": col_dead_time})]
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
        out.append(Variant("dead_time", f"current band {b:.3g} A", {key: col_dead_band(b)},
                           hyper={"dead_time_current_band": b},
                           nonlinear={"dead_time_current_band": (b, max(0.02 * ref, b / 2.5),
                                                                 min(DEAD_TIME_BAND_MAX * ref, b * 2.5),
                                               lambda c, v, key=key: {key: col_dead_band(v)})}))
    return out


def col_delay(ctx):
    """The voltage-rate column: ``v(t - d) = v - d dv/dt``; where the log's voltage/current pairing is known
    (:func:`.equation_error.voltage_alignment`) the equation already holds the nominal delay and hold, and the
    coefficient is the departure from them."""
    return {"electrical": ctx.sig["dv_dt"]}


def _delay_cross(ctx):
    """the loop-fed current-sensor noise this column shares with the voltage equation's residual (:mod:`.loop_noise`)"""
    from .loop_noise import voltage_rate_cross

    return voltage_rate_cross(ctx)


col_delay.cross = _delay_cross


def col_deflection(kind, half: float = 0.0, zero: float = 0.0):
    """Columns of the transmission torque on the rotor measured by two encoders (rotor ``theta`` and load
    ``theta_load``, the load's at the output): ``tau_s/N = (k delta + c d(delta)/dt + offset)/N``,
    ``delta = theta/N - theta_load``; ``kind`` = ``k`` (delta/N), ``c`` (d(delta)/dt / N), ``offset`` (1/N: the
    two encoders' zeros differ by an unknown angle, k times it a constant torque), ``inertia`` (-omega': the load
    the rigid model held in the rotor inertia). With a backlash (``half`` its half width [rad, output side], ``zero``
    the encoders' offset, the dead zone's centre) the spring columns are ``dz(delta - zero)/N`` and the damping's
    only in contact, as the kernel's (:func:`bldc_actuator.kernel.backlash_deflection`)."""
    def build(ctx):
        S = ctx.sig
        N = ctx.params.gear.gear_ratio
        if kind == "inertia":
            return {"mechanical": -S["omega_dot"]}
        if kind == "offset":
            return {"mechanical": np.full(len(ctx.t), 1.0 / N)}
        d = S["theta"] / N - S["theta_load"] - zero
        contact = np.abs(d) > half
        if kind == "k":
            return {"mechanical": (np.sign(d) * np.maximum(np.abs(d) - half, 0.0) if half > 0 else d) / N}
        rate = S["omega"] / N - S["omega_load"]
        return {"mechanical": (rate * contact if half > 0 else rate) / N}
    return build


def compliance_filter(f_a: float, zeta: float, fs: float):
    """Discrete ``(b, a)`` of ``H(s) = -s^2 / (s^2 + 2 zeta w_a s + w_a^2)``, ``w_a = 2 pi f_a`` (bilinear,
    pre-warped at ``w_a`` so the anti-resonance stays where it is): the rotor acceleration's share that the load
    behind a compliant transmission does NOT follow (see :func:`col_compliance`)."""
    w = 2.0 * fs * math.tan(math.pi * f_a / fs)       # pre-warped anti-resonance [rad/s]
    k = 2.0 * fs                                      # s = k (1 - 1/z) / (1 + 1/z)
    kk, dz, ww = k * k, 2.0 * zeta * w * k, w * w
    a0 = kk + dz + ww
    return (np.array([-kk, 2.0 * kk, -kk]) / a0, np.array([1.0, (2.0 * ww - 2.0 * kk) / a0, (kk - dz + ww) / a0]))


def col_compliance(f_a: float, zeta: float):
    """Transmission compliance seen from the rotor alone (motor-side angle, no load encoder). The load J_l behind
    a spring k and damper c (output side) follows the rotor through
    ``theta_l = G theta/N``, ``G = (w_a^2 + 2 zeta w_a s)/(s^2 + 2 zeta w_a s + w_a^2)``, ``w_a = sqrt(k/J_l)``
    (the anti-resonance), ``c = 2 zeta w_a J_l``; the spring torque on the rotor is ``J_l theta_l''/N``. Against a
    rigid model holding the load in the rotor inertia (J_nominal = J + J_l/N^2) the mechanical residual is
    ``(J_l/N^2) (G - 1) omega'`` = column x (reflected load inertia): for a given ``f_a`` and ``zeta`` the
    column is the rotor acceleration through ``G - 1 = -s^2/(s^2 + 2 zeta w_a s + w_a^2)``, its coefficient the
    load inertia reflected to the rotor, ``J_l/N^2`` [kg m^2]. Filtered per segment at the raw rate, started in
    its steady state."""
    def build(ctx):
        from scipy.signal import lfilter, lfilter_zi

        b, a = compliance_filter(f_a, zeta, ctx.fs)
        x = ctx.sig["omega_dot"]
        y = np.zeros_like(x)
        zi = lfilter_zi(b, a)
        for lo, hi in ctx.segments:
            if hi > lo:
                y[lo:hi], _ = lfilter(b, a, x[lo:hi], zi=zi * x[lo])
        return {"mechanical": y}

    def cross(ctx):
        """the loop-fed current-sensor noise this column shares with the residual (fitted out: :mod:`.loop_noise`);
        it depends on the load the coefficient describes (the joint loop answers the noise through it), so it is
        taken at the coefficient of the column's own compensated fit beside the always-fitted nuisance columns"""
        from .loop_noise import compensated_solve, filter_cross_of_load

        if "mechanical" not in ctx.blocks:
            return {"mechanical": 0.0}
        cross_of = filter_cross_of_load(ctx, *compliance_filter(f_a, zeta, ctx.fs), ctx.fs)
        rows = ctx.train_rows("mechanical")
        col = ctx.dec.apply(np.nan_to_num(build(ctx)["mechanical"] / ctx.sig["K"]))[rows]
        nuis = [ctx.column(k, b).get("mechanical") for k, b in ctx.nuisance.items()]
        X = np.column_stack([col] + [c[rows] for c in nuis if c is not None])
        y = ctx.blocks["mechanical"].target[rows]
        try:
            _, bias = compensated_solve(X.T @ X, X.T @ y, 0, cross_of)
        except np.linalg.LinAlgError:
            bias = cross_of(0.0)
        return {"mechanical": bias}
    build.cross = cross
    return build


# ------------------------------------------------------------------------------------ excitation

def _frac(x):
    return float(np.mean(x)) if np.size(x) else 0.0


def excite_friction(ctx):
    w = ctx.dsig("omega_s")
    m = np.abs(w) > 2 * ctx.omega_eps
    pos, neg = _frac((w > 0) & m), _frac((w < 0) & m)
    if min(pos, neg) < 0.03:
        return (f"needs motion in both directions (moving ω>0 {100 * pos:.0f}%, ω<0 {100 * neg:.0f}% of samples)")
    return None


def excite_one_direction(ctx):
    w = ctx.dsig("omega_s")
    return None if _frac(np.abs(w) > 2 * ctx.omega_eps) > 0.05 else "needs the rotor to move (it is at rest)"


def excite_stribeck(ctx):
    r = excite_friction(ctx)
    if r:
        return r
    w = np.abs(ctx.dsig("omega_s"))
    slow = (w > 2 * ctx.omega_eps) & (w < 0.1 * np.percentile(w, 95))
    return None if _frac(slow) > 0.02 else "needs slow motion (few samples at low non-zero speed)"


def excite_viscous(ctx):
    w = np.abs(ctx.dsig("omega_s"))
    return None if np.percentile(w, 95) > 20 * ctx.omega_eps else "needs a range of speeds"


def excite_angle(order):
    """``order`` cycles per revolution, or a callable(params) -> order."""
    def check(ctx):
        o = order(ctx.params) if callable(order) else order
        if float(ctx.sig["theta_known"]) <= 0:
            return "needs the rotor angle (position channel)"
        th = ctx.dsig("theta")
        span = float(np.nanmax(th) - np.nanmin(th)) * o / (2 * math.pi)
        return None if span >= 2.0 else f"needs the rotor to sweep at least two periods of order {o}"
    return check


def excite_load(ctx):
    if float(ctx.sig["theta_known"]) <= 0:
        return "needs the rotor angle (position channel)"
    N = ctx.params.gear.gear_ratio
    th = ctx.dsig("theta") / N
    span = float(np.nanmax(th) - np.nanmin(th))
    return None if span >= 0.5 else f"needs output motion over a larger angle (swept {span:.2f} rad)"


def excite_inertia(ctx):
    a = ctx.dsig("omega_dot")
    return None if np.std(a) > 0 else "needs acceleration"


def excite_temperature(ctx):
    have = [c for c in ("winding_temperature", "housing_temperature") if c in ctx.have]
    if not have:
        return "needs winding_temperature or housing_temperature"
    T = ctx.dsig("T_w")
    span = float(np.nanmax(T) - np.nanmin(T))
    return None if span >= 3.0 else f"needs a temperature change of a few K (recorded span {span:.1f} K)"


def excite_saturation(ctx):
    i = np.abs(ctx.dsig("i_q"))
    lim = ctx.params.drive.current_limit
    top = float(np.percentile(i, 99.5))
    return None if top >= 0.4 * lim else (f"needs high current (99.5th percentile |i_q| = {top:.3g} A, "
                                          f"limit {lim:.3g} A)")


def excite_headroom(ctx):
    if "headroom" not in ctx.sig:
        return "needs voltage_q"
    h = ctx.dsig("headroom")
    return None if _frac(h > 0.9) > 0.005 else "needs operation near the voltage limit (|v|/v_max > 0.9)"


def excite_compliance(ctx):
    """A two-mass shows where the rotor's motion has content near the anti-resonance: acceleration with a part
    above a few hertz, inside the equation error's band."""
    if ctx.params.gear.transmission_stiffness > 0.0:
        return "the nominal parameters already hold a compliant transmission (gear.transmission_stiffness > 0)"
    if ctx.steady:
        return "needs transient motion (a steady-state recording)"
    a = ctx.dsig("omega_dot")
    if not np.std(a) > 0:
        return "needs acceleration"
    if compliance_band(ctx) is None:
        return f"needs a log fast enough to show a resonance (equation-error band up to {ctx.dec.fc:.3g} Hz)"
    fast = a - ctx.dec.lowpass(ctx.sig["omega_dot"], COMPLIANCE_MIN_HZ)[ctx.dec.idx]
    share = float(np.var(fast) / np.var(a))
    return None if share > 0.01 else (f"needs motion with content above {COMPLIANCE_MIN_HZ:g} Hz (the acceleration "
                                      f"holds {100 * share:.2g} % of its variance there)")




def excite_backlash(ctx):
    """Never fitted on its own. With a load encoder the backlash is a form of transmission_compliance (the dead zone
    on the measured deflection); from the rotor's angle alone a dead zone behind a stiffer spring moves the rotor
    like a softer spring (the load follows through the spring's mean stiffness), so it is not checkable and is
    reported as the compliance finding's alias (:func:`v_backlash`)."""
    if "theta_load" in ctx.sig:
        return ("with the load encoder (load_position) it is identified as a form of transmission_compliance "
                "(the dead zone on the measured deflection)")
    return ("needs the load's angle (a load-side encoder, load_position) or a load reversal at low torque: from the "
            "rotor's angle alone a dead zone behind a spring moves the rotor like a softer spring")


def excite_dead_time(ctx):
    i = ctx.dsig("i_q")
    pos, neg = _frac(i > 0), _frac(i < 0)
    return None if min(pos, neg) > 0.05 else "needs current of both signs"


# ---------------------------------------------------------------------------------------- variants

def v_stribeck(ctx, loc):
    w = np.abs(ctx.dsig("omega_s"))
    moving = w[w > 2 * ctx.omega_eps]
    if len(moving) < 10:
        return []
    lo = max(2.0 * ctx.omega_eps, float(np.percentile(moving, 2)))
    hi = max(lo * 1.5, 0.5 * float(np.median(moving)))
    out = []
    for ws in np.geomspace(lo, hi, 6):
        ws = float(ws)
        out.append(Variant("stribeck_friction", f"omega_s={ws:.3g} rad/s", {f"stribeck@{ws:.6g}": col_stribeck(ws)},
                           hyper={"omega_s": ws},
                           nonlinear={"omega_s": (ws, lo / 2, hi * 2, lambda c, v: {f"stribeck@{ws:.6g}": col_stribeck(v)})}))
    return out


def _cogging_orders(ctx, loc) -> list[int]:
    p = ctx.params.motor.pole_pairs
    orders = []
    if ctx.params.effects.cogging_order:
        orders.append(int(ctx.params.effects.cogging_order))
    spec = (loc.get("mechanical") or {}).get("order_spectrum") or {}
    # N_c = lcm(slots, 2p) is always a multiple of 2p: other peaks (p, 3p...) are electrical, not cogging
    for pk in spec.get("peaks", [])[:6]:
        o = int(pk["order"])
        if o not in orders and o % (2 * p) == 0:
            orders.append(o)
    return orders


def v_cogging(ctx, loc):
    out = []
    for o in _cogging_orders(ctx, loc):
        for nh in (1, 2):
            cols = {}
            for k in range(1, nh + 1):
                cols[f"cog{o}c{k}"] = col_harmonic(o, k, "cos")
                cols[f"cog{o}s{k}"] = col_harmonic(o, k, "sin")
            out.append(Variant("cogging_torque", f"order {o}, {nh} harmonic{'s' if nh > 1 else ''}", cols,
                               hyper={"order": o, "harmonics": nh}))
    return out


def col_eripple(order, which, kind):
    """Electrical-angle ripple, coefficient in A (sensor) or per unit (flux), shared by both equations:

    offset  current-sensor offsets: i_meas = i_true + δ cos(pθ+φ) -> mechanical (current units) +δ·cos,
            voltage -R δ·cos (the loop regulates the measured current, so the true one carries -δ)
    gain    sensor gain mismatch: i_meas = i_true (1 + g cos(2pθ+φ)) -> +g i cos, voltage -R g i cos
    flux    flux harmonic: torque and back-EMF x (1 + h cos(6pθ+φ)) -> -h i cos, voltage +K ω h cos
    """
    def build(ctx):
        S = ctx.sig
        b = effects.angle_harmonic_basis(S["theta"], order, 1)[:, 0 if which == "cos" else 1]
        b = b * resolvable(ctx, order)
        out = {}
        if kind == "offset":
            out["mechanical"] = S["K"] * b                      # /K -> current units
            if "v_q" in S:
                out["electrical"] = -S["R"] * b
        elif kind == "gain":
            out["mechanical"] = S["K"] * S["i_col"] * b
            if "v_q" in S:
                out["electrical"] = -S["R"] * S["i_col"] * b
        elif kind == "flux":
            out["mechanical"] = -S["K"] * S["i_col"] * b
            if "v_q" in S:
                out["electrical"] = S["K"] * S["omega"] * b
        else:   # a torque ripple independent of current
            out["mechanical"] = b
        return out
    return build


#: lowest anti-resonance [Hz] the compliance candidate looks for (below it a load follows its rotor like a rigid one
#: over any useful motion); the highest is a fraction of the equation error's band. Not higher: far below its
#: anti-resonance the column is ``(omega/w_a)^2 omega'``, the shape of the acceleration's own high-frequency deficit
#: (central differences of the angle, twice: ``sinc^2(omega T) ~ 1 - (omega T)^2/3``), which a rigid recording's
#: residual holds (a rigid 1 kHz recording was "explained" by a 77 Hz anti-resonance with 4 % of the inertia when
#: the band reached 70 Hz); a minimum at the top of the band is that deficit, not a resonance, and is not offered
COMPLIANCE_MIN_HZ = 3.0
COMPLIANCE_TOP_OF_BAND = 0.4
#: the compliance search (its grid of anti-resonances) fits the residual and the column low-passed at this fraction of
#: the equation error's cut-off: above it the residual keeps, by design, the angle-locked torques whose columns are
#: switched off there (:func:`resolvable`), and a torque the model leaves out moves the rotor, so the residual
#: follows the acceleration with the opposite sign -- the shape of a load that decouples (builtin
#: cogging_drive_log_10khz: an "anti-resonance" at 8.9 Hz fitted on the cogging left in 60-100 Hz, where the
#: residual followed -0.6 x the inertia's torque with coherence 0.9). Only the search: the final fit keeps the whole
#: band (low-passing the column alone biases its coefficient by the filter's transition).
COMPLIANCE_EVIDENCE_OF_BAND = 0.5


def compliance_evidence_hz(ctx) -> float:
    """[Hz] the compliance search's band (:data:`COMPLIANCE_EVIDENCE_OF_BAND` of the cut-off)."""
    return COMPLIANCE_EVIDENCE_OF_BAND * ctx.dec.fc


#: the backlash form (two encoders) is offered when it lowers the linear form's training residual by at least this
#: fraction, with a dead zone wider than this many load-encoder steps
BACKLASH_MIN_GAIN = 0.1
BACKLASH_MIN_STEPS = 2.0


def _encoder_backlash(ctx) -> Variant | None:
    """Backlash seen by two encoders: the dead zone's half width (log grid from two load-encoder steps to 0.05 rad)
    and centre (the encoders' zero offset, from the linear fit, refined on a small grid) that fit the training
    residual best with the spring, damping, inertia and offset columns; offered when it beats the linear form by
    :data:`BACKLASH_MIN_GAIN`."""
    B = ctx.blocks["mechanical"]
    rows = ctx.train_rows("mechanical")
    y = B.target[rows]
    nuis = [ctx.column(k, b).get("mechanical") for k, b in ctx.nuisance.items()]
    X0 = [c[rows] for c in nuis if c is not None]
    cache = {}

    def dec(kind, half=0.0, zero=0.0):
        key = (kind, half, zero)
        if key not in cache:
            raw = col_deflection(kind, half, zero)(ctx)["mechanical"]
            # decimated in current units, as the equation-error columns are (a search: not cached in the context)
            cache[key] = ctx.dec.apply(np.nan_to_num(raw / ctx.sig["K"]))[rows]
        return cache[key]

    def fit(half, zero):
        X = np.column_stack([dec("k", half, zero), dec("c", half, zero), dec("inertia"), dec("offset")] + X0)
        beta, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ beta
        return float(r @ r), beta

    base, beta = fit(0.0, 0.0)
    if not beta[0] > 0:
        return None
    zero0 = -float(beta[3]) / float(beta[0])      # k (delta - zero) = k delta + offset
    th_l = ctx.sig["theta_load"]
    steps = np.abs(np.diff(th_l))
    steps = steps[steps > 0]
    lo = max(BACKLASH_MIN_STEPS * (float(np.min(steps)) if len(steps) else 0.0), 1e-5)
    best = (base, 0.0, zero0)
    for half in np.geomspace(lo, 0.05, 12):
        for dz in (-0.5, -0.25, 0.0, 0.25, 0.5):
            r, b = fit(float(half), zero0 + dz * float(half))
            if b[0] > 0 and r < best[0]:
                best = (r, float(half), zero0 + dz * float(half))
    if not best[1] > 0 or best[0] > (1.0 - BACKLASH_MIN_GAIN) * base:
        return None
    from scipy.optimize import minimize

    _, h0, z0 = best

    def cost(v):
        half, zero = h0 * math.exp(v[0]), z0 + h0 * v[1]
        if half < lo:
            return float("inf")
        r, b = fit(half, zero)
        return r if b[0] > 0 else float("inf")

    res = minimize(cost, np.zeros(2), method="Nelder-Mead",
                   options={"xatol": 1e-3, "maxiter": 80, "initial_simplex": np.array([[0, 0], [0.2, 0], [0, 0.2]])})
    half, zero = (h0 * math.exp(res.x[0]), z0 + h0 * res.x[1]) if res.fun < best[0] else (h0, z0)
    tag = f"@{half:.6g},{zero:.6g}"      # its own column keys (columns are cached by key)
    return Variant("transmission_compliance",
                   f"from the rotor and load encoders, backlash {1e3 * 2 * half:.3g} mrad",
                   {"tr_k" + tag: col_deflection("k", half, zero), "tr_c" + tag: col_deflection("c", half, zero),
                    "tr_j": col_deflection("inertia"), "tr_0": col_deflection("offset")},
                   hyper={"kind": "encoders", "backlash": 2.0 * half})


def compliance_band(ctx) -> tuple[float, float] | None:
    """(lowest, highest) anti-resonance [Hz] the recording can show, or None."""
    hi = COMPLIANCE_TOP_OF_BAND * min(ctx.dec.fc, 0.4 * ctx.fs)
    return (COMPLIANCE_MIN_HZ, hi) if hi > 2.0 * COMPLIANCE_MIN_HZ else None


def _compliance_rss(ctx, loc=None):
    """``rss(f_a, zeta) -> (rss, coefficient, noise_coefficient)``: the nominal mechanical residual (training rows)
    fitted by the compliance column (with the always-fitted nuisance columns and the angle harmonics of the orders
    the locate stage found in it: an angle-locked torque moves the rotor, so it is fitted beside the column, not
    through it), all low-passed again at
    :func:`compliance_evidence_hz`; the column filtered at the DECIMATED rate from the decimated acceleration (all
    linear: a quick stand-in for the raw-rate column, for the search only). Bias-compensated: the current sensor's
    noise that the drive's loop feeds into the motor makes the residual and the acceleration share a noise of
    opposite signs (:mod:`.loop_noise`), whose expected cross product -- through the joint loop as the recording shows
    it, which answers the noise through the load the coefficient describes -- is taken out of the normal equations
    together with the coefficient (:func:`.loop_noise.compensated_solve`); ``noise_coefficient`` is the reflected
    inertia that noise alone would give the column (plain least squares = ``coefficient + noise_coefficient``),
    ``rss`` the residual left by the compensated fit."""
    from scipy.signal import butter, lfilter, lfilter_zi, sosfiltfilt

    from .loop_noise import compensated_solve, filter_cross_of_load

    B = ctx.blocks["mechanical"]
    rows = ctx.train_rows("mechanical")
    K = np.broadcast_to(np.asarray(ctx.sig["K"], float), ctx.sig["omega_dot"].shape)
    x = ctx.dec.apply(ctx.sig["omega_dot"] / K)
    fs_dec = ctx.fs / max(ctx.dec.q, 1)
    runs = np.flatnonzero(np.diff(ctx.dec.seg_of)) + 1
    bounds = list(zip(np.r_[0, runs], np.r_[runs, len(x)]))
    band = compliance_evidence_hz(ctx)
    sos = butter(ctx.dec.order, min(band, 0.45 * fs_dec) / (0.5 * fs_dec), output="sos")

    def clean(v):
        out = np.nan_to_num(np.asarray(v, float))
        for lo, hi in bounds:
            if hi - lo > 6 * (2 * ctx.dec.order + 1):
                out[lo:hi] = sosfiltfilt(sos, out[lo:hi])
        return out

    y = clean(B.target)[rows]
    yy = float(y @ y)
    nuis = [ctx.column(k, b).get("mechanical") for k, b in ctx.nuisance.items()]
    peaks = ((loc or {}).get("mechanical") or {}).get("order_spectrum") or {}
    for o in sorted({int(pk["order"]) for pk in peaks.get("peaks", [])[:6]}):
        nuis += [ctx.column(f"cog{o}{w[0]}1", col_harmonic(o, 1, w)).get("mechanical") for w in ("cos", "sin")]
    X0 = [clean(c)[rows] for c in nuis if c is not None]

    def rss(f_a, zeta):
        if not 0.0 < f_a < 0.45 * fs_dec:
            return float("inf"), 0.0, 0.0
        b, a = compliance_filter(f_a, zeta, fs_dec)
        col = np.zeros_like(x)
        zi = lfilter_zi(b, a)
        for lo, hi in bounds:
            col[lo:hi], _ = lfilter(b, a, x[lo:hi], zi=zi * x[lo])
        X = np.column_stack([clean(col)[rows]] + X0)
        G, g = X.T @ X, X.T @ y
        bias = np.zeros(len(g))
        try:
            beta, bias[0] = compensated_solve(G, g, 0, filter_cross_of_load(ctx, b, a, fs_dec, (sos, fs_dec)))
            plain = np.linalg.solve(G, g)
        except np.linalg.LinAlgError:
            return float("inf"), 0.0, 0.0
        return yy - float((g - bias) @ beta), float(beta[0]), float(plain[0] - beta[0])
    return rss


#: anti-resonances tried before refining (log-spaced over the band) and damping ratios
COMPLIANCE_GRID = 48
COMPLIANCE_ZETA_GRID = (0.02, 0.05, 0.1, 0.2, 0.4)
#: local minima of the grid refined and offered as forms
COMPLIANCE_FORMS = 2


def v_compliance(ctx, loc):
    """The anti-resonance (``f_a``) and its damping ratio searched on the nominal residual: a log grid over
    :func:`compliance_band` x :data:`COMPLIANCE_ZETA_GRID` (a lightly damped two-mass is a narrow valley in
    ``f_a``, so a coarse grid misses it by tens of percent), its best local minima (with a positive load inertia)
    refined jointly in (log f_a, log zeta) by Nelder-Mead; each is one form, its ``f_a`` refined again in the
    final fit (beside the other accepted effects)."""
    from scipy.optimize import minimize

    if "theta_load" in ctx.sig and "mechanical" in ctx.blocks:
        out = [Variant("transmission_compliance", "from the rotor and load encoders (deflection measured)",
                       {"tr_k": col_deflection("k"), "tr_c": col_deflection("c"), "tr_j": col_deflection("inertia"),
                        "tr_0": col_deflection("offset")}, hyper={"kind": "encoders"})]
        bl = _encoder_backlash(ctx)
        return out + ([bl] if bl is not None else [])
    band = compliance_band(ctx)
    if band is None or "mechanical" not in ctx.blocks:
        return []
    lo, hi = band
    rss = _compliance_rss(ctx, loc)
    fs = np.geomspace(lo, hi, COMPLIANCE_GRID)
    table = np.array([[rss(float(f), z) for z in COMPLIANCE_ZETA_GRID] for f in fs])   # (f, zeta, [rss, coef, noise])
    val = np.where(table[:, :, 1] > table[:, :, 2], table[:, :, 0], np.inf)
    best_z = np.argmin(val, axis=1)
    curve = val[np.arange(len(fs)), best_z]
    minima = [i for i in range(1, len(fs) - 1) if np.isfinite(curve[i])
              and curve[i] <= curve[i - 1] and curve[i] <= curve[i + 1]]    # interior: a resonance inside the band
    minima = sorted(minima, key=lambda i: curve[i])[:COMPLIANCE_FORMS]
    out = []
    for i in minima:
        x0 = np.array([math.log(fs[i]), math.log(COMPLIANCE_ZETA_GRID[best_z[i]])])

        def cost(v):
            f, z = math.exp(v[0]), math.exp(min(max(v[1], math.log(0.005)), math.log(1.0)))
            r, c, c_noise = rss(f, z)
            return r if c > c_noise else r + abs(r)

        res = minimize(cost, x0, method="Nelder-Mead", options={"xatol": 0.002, "fatol": 1e-9 * curve[i],
                                                                 "maxiter": 200, "initial_simplex":
                                                                 np.array([x0, x0 + [0.04, 0.0], x0 + [0.0, 0.3]])})
        f = float(math.exp(res.x[0]))
        zeta = float(min(max(math.exp(res.x[1]), 0.005), 1.0))
        if not lo < f < hi:     # refined onto or beyond the band's edge: not a resolved anti-resonance
            continue
        _, c, c_noise = rss(f, zeta)
        if not c > c_noise:     # at least half of the plain fit must be more than the loop-fed sensor noise
            continue
        key = f"compliance@{f:.6g},{zeta:.4g}"
        out.append(Variant("transmission_compliance", f"anti-resonance {f:.3g} Hz, damping ratio {zeta:.2g}",
                           {key: col_compliance(f, zeta)}, hyper={"f_a": f, "zeta": zeta},
                           nonlinear={"f_a": (f, max(lo, f / 1.15), min(hi, f * 1.15),
                                              lambda c, v, key=key, zeta=zeta: {key: col_compliance(v, zeta)})}))
    return out


def v_backlash(ctx, loc):
    """The forms a backlash takes seen from the rotor alone: the compliance forms themselves (the load follows a
    dead zone behind a stiffer spring through its mean stiffness: the same column at the softer spring's
    anti-resonance), so the alias with an accepted compliance is exact; none with a load encoder (there the dead
    zone is fitted on the measured deflection, a form of transmission_compliance)."""
    if "theta_load" in ctx.sig:
        return []
    return [Variant("backlash", f"a dead zone behind a stiffer spring, seen from the rotor alone ({v.label})",
                    v.columns, hyper=dict(v.hyper, kind="rotor"))
            for v in v_compliance(ctx, loc)]


def params_backlash(coef, cov, keys, variant, ctx):
    """Not identifiable from the rotor alone (the dead zone's width trades against the spring's stiffness): no
    values, the alias says which experiment separates them."""
    return {}


def v_eripple(ctx, loc):
    p = ctx.params.motor.pole_pairs
    forms = [("current-sensor offset (order p)", p, "offset", "A"),
             ("current-sensor gain mismatch (order 2p, proportional to current)", 2 * p, "gain", ""),
             ("flux harmonic (order 6p, torque and back-EMF)", 6 * p, "flux", ""),
             ("torque ripple at order 6p (independent of current)", 6 * p, "torque", "N*m")]
    out = []
    for label, order, kind, unit in forms:
        cols = {f"er{order}{kind}cos": col_eripple(order, "cos", kind),
                f"er{order}{kind}sin": col_eripple(order, "sin", kind)}
        out.append(Variant("electrical_angle_ripple", label, cols,
                           hyper={"order": order, "kind": kind, "unit": unit,
                                  "current_weighted": kind in ("gain", "flux")}, additive=True))
    return out


def v_load(ctx, loc):
    cols = {"load_sin": col_load("sin"), "load_cos": col_load("cos"), "load_const": col_load("const")}
    out = [Variant("position_dependent_load", "gravity-like sin/cos of the output angle + constant", dict(cols))]
    N = ctx.params.gear.gear_ratio
    th = ctx.dsig("theta") / N
    if float(np.nanmax(th) - np.nanmin(th)) < 4 * math.pi:
        c2 = dict(cols)
        c2["load_lin"] = col_load("lin")
        out.append(Variant("position_dependent_load", "gravity + spring + constant", c2))
    return out


def _kt_iterate(key, equations):
    return lambda ctx, coef: {key: col_kt(equations, max(0.05, 1.0 + coef))}


def v_kt(ctx, loc):
    """One K for torque and back-EMF (the model has one): both equations when both exist."""
    if "electrical" in ctx.blocks and "mechanical" in ctx.blocks:
        eqs, label = ("mechanical", "electrical"), "same factor on torque and back-EMF"
    elif "mechanical" in ctx.blocks:
        eqs, label = ("mechanical",), "from the torque balance (no voltage)"
    else:
        eqs, label = ("electrical",), "from the back-EMF (no motion equation)"
    key = "kt_" + "_".join(e[:4] for e in eqs)
    return [Variant("torque_constant_error", label, {key: col_kt(eqs)}, hyper={"equations": eqs},
                    iterate=_kt_iterate(key, eqs))]


# ------------------------------------------------------------------------------ parameter mapping

def params_saturation(coef, cov, keys, variant, ctx):
    """The coefficient of the K i|i| column is the torque lost per K i|i|: the simulator's effects.kt_saturation
    (K(i) = K (1 - k |i|)); a negative value (torque rising with current) has no simulator term."""
    c = float(coef[0])
    return {"kt_saturation": {"value": c, "sd": _sd(cov, 0), "unit": "1/A",
                              "field": "effects.kt_saturation" if c > 0 else None, "delta": c}}


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
    sd_v = _sd(cov, 0) * (q if band is not None else 1.0)
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


def params_delay(coef, cov, keys, variant, ctx):
    """The dv/dt column's coefficient is the delay d [s] (v(t - d) = v - d dv/dt): drive.current_loop_delay,
    which the simulator takes up to one loop period."""
    delta = float(coef[0])
    drive = ctx.params.drive
    # aligned equation: the coefficient is the change of the nominal delay; else the whole lag of the logged voltage
    d = drive.current_loop_delay + delta if "voltage_alignment" in ctx.sig else delta
    period = 1.0 / drive.current_loop_rate
    fits = 0.0 <= d <= period
    return {"delay": {"value": d, "sd": _sd(cov, 0), "unit": "s", "field": "drive.current_loop_delay" if fits else None,
                      "delta": delta}}


def params_friction(coef, cov, keys, variant, ctx):
    out = {}
    for i, k in enumerate(keys):
        if k == "fric_sign":
            out["coulomb_friction"] = {"value": ctx.params.effects.coulomb_friction + coef[i], "sd": _sd(cov, i),
                                       "unit": "N*m", "field": "effects.coulomb_friction", "delta": float(coef[i])}
        elif k == "fric_abs":
            out["friction_asymmetry"] = {"value": ctx.params.effects.friction_asymmetry + coef[i], "sd": _sd(cov, i),
                                         "unit": "N*m", "field": "effects.friction_asymmetry", "delta": float(coef[i])}
        elif k.startswith("stribeck"):
            out["stribeck_friction"] = {"value": ctx.params.effects.stribeck_friction + coef[i], "sd": _sd(cov, i),
                                        "unit": "N*m", "field": "effects.stribeck_friction", "delta": float(coef[i])}
    return out


def params_cogging(coef, cov, keys, variant, ctx):
    out = {"cogging_order": {"value": variant.hyper["order"], "sd": 0.0, "unit": "", "field": "effects.cogging_order"}}
    for i, k in enumerate(keys):
        kind = "cos" if "c" in k.split(str(variant.hyper["order"]), 1)[1][:1] else "sin"
        h = int(k[-1])
        out[f"cogging_{kind}_{h}"] = {"value": float(coef[i]), "sd": _sd(cov, i), "unit": "N*m",
                                      "field": f"effects.cogging_{kind}[{h - 1}]", "delta": float(coef[i])}
    amp = math.hypot(*(coef[:2])) if len(coef) >= 2 else float("nan")
    out["amplitude_1"] = {"value": amp, "sd": float(max(_sd(cov, 0), _sd(cov, 1))) if len(coef) >= 2 else float("nan"),
                          "unit": "N*m", "field": None}
    return out


def params_eripple(coef, cov, keys, variant, ctx):
    o = variant.hyper["order"]
    kind = variant.hyper.get("kind", "torque")
    unit = variant.hyper.get("unit", "")
    name = {"offset": "sensor_offset", "gain": "sensor_gain_ripple", "flux": "flux_harmonic",
            "torque": "torque_ripple"}.get(kind, "ripple")
    amp = math.hypot(coef[0], coef[1])
    ph = math.atan2(-coef[1], coef[0])     # a cos + b sin = A cos(kθ + φ)
    return {f"{name}_order_{o}_amplitude": {"value": amp, "sd": max(_sd(cov, 0), _sd(cov, 1)), "unit": unit,
                                            "field": None},
            f"{name}_order_{o}_phase": {"value": ph, "sd": float("nan"), "unit": "rad", "field": None},
            # per form: several forms of this effect may be accepted together, and their parameters are merged
            # into one dict per effect (issue #14: the last form's coefficients were written for every form)
            f"_{kind}_cos": {"value": float(coef[0]), "sd": _sd(cov, 0), "unit": unit, "field": None},
            f"_{kind}_sin": {"value": float(coef[1]), "sd": _sd(cov, 1), "unit": unit, "field": None}}


def params_load(coef, cov, keys, variant, ctx):
    ld = ctx.params.load
    c = dict(zip(keys, coef))
    # nominal gravity as sin/cos components: τ_g sin(θ + φ) = τ_g cos φ sin θ + τ_g sin φ cos θ
    a_s = ld.gravity_torque * math.cos(ld.gravity_phase) + c.get("load_sin", 0.0)
    a_c = ld.gravity_torque * math.sin(ld.gravity_phase) + c.get("load_cos", 0.0)
    g = math.hypot(a_s, a_c)
    phi = math.atan2(a_c, a_s)
    i_s, i_c = keys.index("load_sin"), keys.index("load_cos")
    sd_g = math.sqrt(max(0.0, (a_s ** 2 * cov[i_s, i_s] + a_c ** 2 * cov[i_c, i_c] + 2 * a_s * a_c * cov[i_s, i_c])
                         / max(g * g, 1e-300)))
    sd_phi = math.sqrt(max(0.0, (a_c ** 2 * cov[i_s, i_s] + a_s ** 2 * cov[i_c, i_c] - 2 * a_s * a_c * cov[i_s, i_c])
                           / max(g ** 4, 1e-300)))
    out = {"gravity_torque": {"value": g, "sd": sd_g, "unit": "N*m", "field": "load.gravity_torque"},
           "gravity_phase": {"value": phi, "sd": sd_phi, "unit": "rad", "field": "load.gravity_phase"}}
    k0 = keys.index("load_const")
    const = ld.load_torque + c["load_const"]
    if "load_lin" in c:
        k = ld.spring_stiffness + c["load_lin"]
        kl = keys.index("load_lin")
        out["spring_stiffness"] = {"value": k, "sd": _sd(cov, kl), "unit": "N*m/rad", "field": "load.spring_stiffness"}
        # spring zero kept; its constant part moves into load_torque
        const = const + ld.spring_stiffness * ld.spring_zero - k * ld.spring_zero
    out["load_torque"] = {"value": const, "sd": _sd(cov, k0), "unit": "N*m", "field": "load.load_torque"}
    return out


def params_kt(coef, cov, keys, variant, ctx):
    K0 = ctx.params.motor.torque_constant_q
    ratio = 1.0 + float(coef[0])
    sd = _sd(cov, 0)
    return {"torque_constant_q": {"value": K0 * ratio, "sd": K0 * sd, "unit": "N*m/A", "field": "motor.torque_constant_q"},
            "ratio_to_nominal": {"value": ratio, "sd": sd, "unit": "", "field": None},
            "frame_factor": {"value": match_frame_factor(ratio, sd), "sd": 0.0, "unit": "", "field": None}}


def params_compliance(coef, cov, keys, variant, ctx):
    """The column's coefficient is the load inertia reflected to the rotor, ``J_l/N^2`` [kg m^2]; with the
    anti-resonance ``f_a`` (refined, in ``variant.hyper``) and damping ratio: ``J_l``, ``k = (2 pi f_a)^2 J_l``,
    ``c = 2 zeta (2 pi f_a) J_l`` (output side), and the rotor side's own inertia, the nominal one less ``J_l/N^2``
    (written by :func:`bldc_actuator.diagnosis.frame.simulate.updated_params`, so an inertia finding composes with it)."""
    N = ctx.params.gear.gear_ratio
    if variant.hyper.get("kind") == "encoders":     # two encoders: k, c and the load inertia fitted directly
        out = _params_compliance_encoders(coef, cov, keys, ctx)
        if "backlash" in variant.hyper:
            ok = out["transmission_stiffness"]["field"] is not None
            out["backlash"] = {"value": float(variant.hyper["backlash"]), "sd": float("nan"), "unit": "rad",
                               "field": "gear.backlash" if ok else None}
        return out
    j_ref = float(coef[0])
    sd = _sd(cov, 0)
    f_a, zeta = float(variant.hyper["f_a"]), float(variant.hyper["zeta"])
    w_a = 2.0 * math.pi * f_a
    J_l = j_ref * N * N
    j_m = ctx.params.motor.rotor_inertia - j_ref
    f_r = f_a * math.sqrt(1.0 + j_ref / j_m) if j_m > 0 and j_ref > 0 else float("nan")
    rel = sd / abs(j_ref) if j_ref else float("nan")
    ok = j_ref > 0.0
    return {"load_inertia_reflected": {"value": j_ref, "sd": sd, "unit": "kg*m^2", "field": None},
            "load_inertia": {"value": J_l, "sd": sd * N * N, "unit": "kg*m^2", "field": "gear.load_inertia" if ok else None},
            "transmission_stiffness": {"value": w_a * w_a * J_l, "sd": w_a * w_a * J_l * rel, "unit": "N*m/rad",
                                       "field": "gear.transmission_stiffness" if ok else None},
            "transmission_damping": {"value": 2.0 * zeta * w_a * J_l, "sd": 2.0 * zeta * w_a * J_l * rel,
                                     "unit": "N*m*s/rad", "field": "gear.transmission_damping" if ok else None},
            "rotor_inertia_motor_side": {"value": j_m, "sd": sd, "unit": "kg*m^2", "field": None},
            "antiresonance_frequency": {"value": f_a, "sd": float("nan"), "unit": "Hz", "field": None},
            "resonance_frequency": {"value": f_r, "sd": float("nan"), "unit": "Hz", "field": None},
            "damping_ratio": {"value": zeta, "sd": float("nan"), "unit": "", "field": None}}


def _params_compliance_encoders(coef, cov, keys, ctx):
    N = ctx.params.gear.gear_ratio
    ik = next(i for i, key in enumerate(keys) if key.startswith("tr_k"))
    ic = next(i for i, key in enumerate(keys) if key.startswith("tr_c"))
    ij = keys.index("tr_j")
    k, damp, j_ref = float(coef[ik]), float(coef[ic]), float(coef[ij])
    J_l = j_ref * N * N
    ok = k > 0.0 and j_ref > 0.0
    j_m = ctx.params.motor.rotor_inertia - j_ref
    f_a = math.sqrt(k / J_l) / (2.0 * math.pi) if ok else float("nan")
    f_r = f_a * math.sqrt(1.0 + j_ref / j_m) if ok and j_m > 0 else float("nan")
    return {"load_inertia_reflected": {"value": j_ref, "sd": _sd(cov, ij), "unit": "kg*m^2", "field": None},
            "load_inertia": {"value": J_l, "sd": _sd(cov, ij) * N * N, "unit": "kg*m^2",
                             "field": "gear.load_inertia" if ok else None},
            "transmission_stiffness": {"value": k, "sd": _sd(cov, ik), "unit": "N*m/rad",
                                       "field": "gear.transmission_stiffness" if ok else None},
            "transmission_damping": {"value": damp, "sd": _sd(cov, ic), "unit": "N*m*s/rad",
                                     "field": "gear.transmission_damping" if ok and damp >= 0.0 else None},
            "rotor_inertia_motor_side": {"value": j_m, "sd": _sd(cov, ij), "unit": "kg*m^2", "field": None},
            "antiresonance_frequency": {"value": f_a, "sd": float("nan"), "unit": "Hz", "field": None},
            "resonance_frequency": {"value": f_r, "sd": float("nan"), "unit": "Hz", "field": None}}


def params_r_temp(coef, cov, keys, variant, ctx):
    m = ctx.params.motor
    a0 = m.copper_temperature_coefficient if m.resistance_temperature_enabled else 0.0
    return {"copper_temperature_coefficient": {"value": a0 + coef[0], "sd": _sd(cov, 0), "unit": "1/K",
                                               "field": "motor.copper_temperature_coefficient"}}


def params_magnet(coef, cov, keys, variant, ctx):
    m = ctx.params.motor
    b0 = m.magnet_temperature_coefficient if m.magnet_temperature_enabled else 0.0
    return {"magnet_temperature_coefficient": {"value": b0 + coef[0], "sd": _sd(cov, 0), "unit": "1/K",
                                               "field": "motor.magnet_temperature_coefficient"}}


# ------------------------------------------------------------------------------------------ library

def _forms() -> dict[str, tuple]:
    """Each effect's code on the frame's side: (variants, excitation test, parameter mapping, undecided reason);
    everything else about it is its registry record (:mod:`..effects`)."""
    return {
        "coulomb_friction": (Single({"fric_sign": col_fric_sign}), excite_friction,
                             params_friction, None),
        "asymmetric_friction": (Single({"fric_sign": col_fric_sign, "fric_abs": col_fric_abs}),
                                excite_friction, params_friction, None),
        "stribeck_friction": (v_stribeck, excite_stribeck, params_friction, None),
        "viscous_friction": (Single({"visc": col_viscous}), excite_viscous,
                             params_generic({"visc": ("viscous_damping", "N*m*s/rad", "motor.viscous_damping",
                                                      _flat("motor.viscous_damping"))}), None),
        "cogging_torque": (v_cogging, excite_angle(lambda p: 2 * p.motor.pole_pairs), params_cogging, None),
        "electrical_angle_ripple": (v_eripple, excite_angle(lambda p: p.motor.pole_pairs), params_eripple, None),
        "position_dependent_load": (v_load, excite_load, params_load, None),
        "torque_constant_error": (v_kt, None, params_kt, None),
        "inertia_error": (Single({"inertia": col_inertia}), excite_inertia,
                          params_generic({"inertia": ("rotor_inertia", "kg*m^2", "motor.rotor_inertia",
                                                      _flat("motor.rotor_inertia"))}), None),
        "transmission_compliance": (v_compliance, excite_compliance, params_compliance, None),
        "backlash": (v_backlash, excite_backlash, params_backlash, None),
        "resistance_error": (Single({"r_err": col_r_err}), None,
                             params_generic({"r_err": ("phase_resistance", "ohm", "motor.phase_resistance",
                                                       _flat("motor.phase_resistance"))}), None),
        "inductance_error": (Single({"l_err": col_l_err}), None,
                             params_generic({"l_err": ("q_inductance", "H", "motor.q_inductance",
                                                       _flat("motor.q_inductance"))}), None),
        "resistance_temperature": (Single({"r_temp": col_r_temp}), excite_temperature,
                                   params_r_temp, None),
        "magnet_temperature": (Single({"magnet": col_magnet}), excite_temperature,
                               params_magnet, None),
        "magnetic_saturation": (Single({"sat": col_saturation}), excite_saturation,
                                params_saturation, None),
        "dead_time": (v_dead_time, excite_dead_time, params_dead_time, dead_time_in_band),
        "current_loop_delay": (Single({"delay": col_delay}), None, params_delay, None),
    }


def library() -> dict[str, Candidate]:
    """Every candidate effect by its identifier (the names used in the JSON report), in the registry's order:
    its record (:mod:`..effects.registry`) and its forms (:func:`_forms`)."""
    forms = _forms()
    out = {}
    for e in registry.candidates():
        own = registry.forms(e.name)
        if own is not None:
            variants, excited, to_params, undecided = own.variants, own.excited, own.to_params, own.undecided_why
        else:
            variants, excited, to_params, undecided = forms.get(e.name, (None, None, None, None))
        if isinstance(variants, Single):
            variants = v_single(e.name, variants.columns)
        out[e.name] = Candidate(e.name, e.equations, e.needs, e.description, e.simulated, dict(e.confusable),
                                variants, excited, to_params, hides_behind=e.hides_behind, undecided_why=undecided,
                                record=e)
    return out


EFFECT_NAMES = registry.names(registry.candidates())
#: found by the thermal network's output error, not the linear selection
THERMAL = registry.names(registry.by_route(Route.THERMAL))
#: checked by output-error routines and the simulation, not the linear selection
SPECIAL = registry.names(registry.where(lambda e: e.special and e.candidate))


# ------------------------------------------------------------------------------------------ evidence

def _bins(loc, eq, view):
    return ((loc.get(eq) or {}).get("bins") or {}).get(view) or []


def _fmt(x, unit):
    return f"{x:+.3g} {unit.split(' ')[0]}"


def _velocity_story(loc, eq="mechanical") -> str | None:
    bins = _bins(loc, eq, "velocity")
    if not bins:
        return None
    unit = loc[eq]["unit"]
    pos = [b for b in bins if b["lo"] >= 0 and b["count"] > 0 and b["label"] != "|ω|≈0"]
    neg = [b for b in bins if b["hi"] <= 0 and b["count"] > 0 and b["label"] != "|ω|≈0"]
    zero = [b for b in bins if b["label"] == "|ω|≈0" and b["count"] > 0]
    if not pos or not neg:
        return None
    mp = np.average([b["mean"] for b in pos], weights=[b["count"] for b in pos])
    mn = np.average([b["mean"] for b in neg], weights=[b["count"] for b in neg])
    zmax = max(abs(b["z"]) for b in pos + neg)
    s = (f"{eq} residual by speed: mean {_fmt(mp, unit)} for ω>0, {_fmt(mn, unit)} for ω<0 "
         f"(|z| up to {zmax:.0f})")
    if mp * mn < 0:
        s += "; it changes sign with the direction of motion (a step at zero speed)"
        if abs(abs(mp) - abs(mn)) > 0.2 * max(abs(mp), abs(mn)):
            s += ", with different size per direction"
    elif abs(mp - mn) < 0.3 * max(abs(mp), abs(mn)):
        s += "; same sign in both directions (an offset, not friction)"
    slow = [b for b in pos + neg if "slow" in b["label"]]
    fast = [b for b in pos + neg if "fast" in b["label"]]
    if slow and fast:
        ms = np.mean([abs(b["mean"]) for b in slow])
        mf = np.mean([abs(b["mean"]) for b in fast])
        s += f"; |mean| {ms:.3g} at low speed vs {mf:.3g} at high speed"
    if zero:
        s += f"; near-zero-speed bin {_fmt(zero[0]['mean'], unit)} ({zero[0]['count']} samples)"
    return s


def _trend_story(loc, eq, view, what) -> str | None:
    bins = [b for b in _bins(loc, eq, view) if b["count"] > 0]
    if len(bins) < 2:
        return None
    unit = loc[eq]["unit"]
    first, last = bins[0], bins[-1]
    return (f"{eq} residual by {what}: RMS {first['rms']:.3g} in {first['label']} vs {last['rms']:.3g} in "
            f"{last['label']} (mean {_fmt(first['mean'], unit)} -> {_fmt(last['mean'], unit)})")


def _spectrum_story(loc, order, eq="mechanical") -> str | None:
    spec = (loc.get(eq) or {}).get("order_spectrum") or {}
    if not spec.get("orders"):
        return None
    o = np.array(spec["orders"])
    a = np.array(spec["amplitude"])
    i = np.flatnonzero(o == order)
    if not len(i):
        return None
    med = float(np.median(a[(o >= order / 2) & (o <= 2 * order)])) if len(a) else float("nan")
    rank = int((a > a[i[0]]).sum()) + 1
    marks = {v: k for k, v in spec.get("marks", {}).items()}
    tag = f" (= {marks[order]})" if order in marks else ""
    return (f"angle-order spectrum of the {eq} residual: order {order}{tag} has amplitude {a[i[0]]:.3g} "
            f"= {a[i[0]] / med:.1f}x the local median (rank {rank} of {len(a)} orders)")


def evidence(effect: str, variant: Variant, loc: dict, extra: dict) -> list[str]:
    """Plain-word pointers from the locate results to this effect (its fingerprint), plus the selection
    numbers. ``extra``: ``explained`` (share of the nominal residual variance its columns explain),
    ``dbic``, ``heldout``."""
    out: list[str] = []
    record = registry.get(effect) if registry.known(effect) else None
    story = record.story if record is not None else Story.NONE
    if story is Story.VELOCITY:
        s = _velocity_story(loc)
        if s:
            out.append(s)
    elif story is Story.ANGLE_SPECTRUM:
        s = _spectrum_story(loc, int(variant.hyper["order"]))
        if s:
            out.append(s)
    elif story is Story.CURRENT_TREND:
        for eq in ("mechanical", "electrical"):
            s = _trend_story(loc, eq, "current", "|current|")
            if s:
                out.append(s)
    elif story is Story.TEMPERATURE_TREND:
        for eq in ("electrical", "mechanical"):
            s = _trend_story(loc, eq, "temperature", "temperature")
            if s:
                out.append(s)
    elif story is Story.HEADROOM:
        s = _trend_story(loc, "electrical", "headroom", "voltage headroom |v|/v_max")
        if s:
            out.append(s)
    elif story is Story.ELECTRICAL_CURRENT_TREND:
        s = _trend_story(loc, "electrical", "current", "|current|")
        if s:
            out.append(s)
    for eq in ("mechanical", "electrical"):
        wins = (loc.get(eq) or {}).get("windows") or []
        if wins and record is not None and record.level_windows:
            w = max(wins, key=lambda x: x["ratio_to_quietest"])
            out.append(f"{eq} residual changes level at t = {w['start']:.1f}-{w['stop']:.1f} s "
                       f"({w['ratio_to_quietest']:.1f}x the quietest segment)")
    if "explained" in extra:
        out.append(f"its regressors explain {100 * extra['explained']:.1f}% of the nominal equation-error "
                   f"variance (training data)")
    if "dbic" in extra:
        ho = extra.get("heldout", {})
        out.append(f"selection: ΔBIC {extra['dbic']:.1f}; held-out residual RMS -{100 * ho.get('rel', 0):.1f}% "
                   f"(t = {ho.get('t', 0):.1f})")
    return out


# ------------------------------------------------------------------------------------- plausibility

def implausible(cand: Candidate, coef, cov, keys, variant: Variant, ctx) -> str | None:
    """A reason when the fitted parameters are physically implausible (a fit that makes the torque constant
    vanish or the resistance negative explains noise, not physics), else None."""
    try:
        pars = cand.to_params(np.asarray(coef), np.asarray(cov), keys, variant, ctx)
    except Exception:  # noqa: BLE001 - a mapping that cannot even be evaluated is not plausible
        return "its parameters cannot be evaluated"
    p = ctx.params
    m = p.motor

    def val(name):
        x = pars.get(name, {})
        return x.get("value"), x.get("sd", 0.0) or 0.0

    checks = []
    v, sd = val("ratio_to_nominal")
    if v is not None:
        checks.append((0.2 <= v <= 5.0, f"torque constant ratio {v:.3g} outside [0.2, 5]"))
    for name, nominal, lo, hi in (("rotor_inertia", m.rotor_inertia, 0.1, 20.0),
                                  ("phase_resistance", m.phase_resistance, 0.2, 5.0),
                                  ("q_inductance", m.q_inductance, 0.2, 5.0)):
        v, sd = val(name)
        if v is not None:
            checks.append((lo * nominal <= v <= hi * nominal,
                           f"{name} {v:.3g} outside [{lo:g}, {hi:g}] x nominal {nominal:.3g}"))
    for name in ("viscous_damping", "coulomb_friction", "stribeck_friction", "dead_time_voltage"):
        v, sd = val(name)
        if v is not None and isinstance(v, float):
            checks.append((v + 3.0 * sd >= 0.0, f"{name} {v:.3g} < 0"))
    v, sd = val("copper_temperature_coefficient")
    if v is not None:
        checks.append((-0.001 <= v <= 0.01, f"copper coefficient {v:.3g}/K outside [-0.001, 0.01]"))
    v, sd = val("magnet_temperature_coefficient")
    if v is not None:
        checks.append((-0.01 <= v <= 0.002, f"magnet coefficient {v:.3g}/K outside [-0.01, 0.002]"))
    v, sd = val("delay")
    if v is not None:
        checks.append((abs(v) <= 2e-3, f"delay {1e3 * v:.3g} ms beyond 2 ms"))
    v, sd = val("load_inertia_reflected")
    if v is not None:
        checks.append((v - 3.0 * sd > 0.0, f"reflected load inertia {v:.3g} ± {sd:.2g} kg*m^2 not above 0"))
        checks.append((v < 0.95 * m.rotor_inertia, f"reflected load inertia {v:.3g} kg*m^2 leaves no rotor inertia "
                       f"(nominal total {m.rotor_inertia:.3g})"))
    v, sd = val("kt_saturation")
    if v is not None:
        i_max = float(np.percentile(np.abs(ctx.dsig("i_q")), 99.5))
        checks.append((-0.05 <= v * i_max <= 0.6, f"saturation {100 * v * i_max:.3g}% at {i_max:.3g} A"))
    for ok, why in checks:
        if not ok:
            return f"implausible fitted value: {why}"
    return None
