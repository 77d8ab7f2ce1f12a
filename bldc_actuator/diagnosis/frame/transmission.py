"""The load behind a compliant transmission, estimated from the rotor's recorded motion (no load encoder).

With ``gear.transmission_stiffness`` k > 0 the load (inertia J_l, output side, damping c) obeys
``J_l theta_l'' = k (theta/N - theta_l) + c (omega/N - omega_l) - tau_L``: driven by the rotor alone, it is a
stable second-order filter of the recorded rotor angle, so its angle and speed at any instant follow from the
recording (up to a start transient that decays at the anti-resonance's damping). A replay window started from a
recorded rotor state needs this load state too: seated where a rigid gear would hold it, every window rings at the
two-mass resonance from its first sample (measured on the 25 Hz anti-resonance of test_compliance_diagnosis.py: the
replay's speed error with every finding 5.2 rad/s, 63 % of the recorded speed's RMS, "not decidable"; with the
estimated load state the finding is confirmed, held-out speed error 5.87 -> 0.34 rad/s).

The backlash's dead zone included; of the external load only the constant ``load.load_torque`` (a static
deflection ``tau_L / k``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...params import ActuatorParams


def load_trajectory(theta: np.ndarray, omega: np.ndarray, t: np.ndarray, segments, p: ActuatorParams):
    """``(theta_load_out, omega_load_out)`` [rad, rad/s, output side] at every sample for a rotor moving as recorded
    (``theta`` motor side, NaN-free; ``omega`` its speed, used for the start), under ``p``'s transmission (its
    backlash included); the rigid ``theta/N``, ``omega/N`` when ``p`` is rigid. Per segment, started seated
    (``theta/N - tau_L/k``, ``omega/N``), integrated by the kernel's :func:`~bldc_actuator.kernel.load_follow`
    (the simulator's own load equation with the rotor's motion given)."""
    from ... import kernel

    g = p.gear
    N = g.gear_ratio
    th = np.ascontiguousarray(np.asarray(theta, float) / N)
    w = np.asarray(omega, float) / N
    if not g.transmission_stiffness > 0.0:
        return th.copy(), w.copy()
    k, c, J = g.transmission_stiffness, g.transmission_damping, g.load_inertia
    static = p.load.load_torque / k
    tt = np.ascontiguousarray(np.asarray(t, float))
    th_l, w_l = th.copy(), w.copy()
    for a, b in segments:
        if b - a < 2:
            continue
        x, v = np.empty(b - a), np.empty(b - a)
        # x = theta_l + tau_L/k follows the rotor as an unloaded load would (linear part; with backlash approximate)
        kernel.load_follow(th[a:b], w[a:b], tt[a:b], k / J, c / J, 0.5 * g.backlash, th[a], w[a], x, v)
        th_l[a:b] = x - static
        w_l[a:b] = v
    return th_l, w_l


def window_load_states(ctx, plist: list[ActuatorParams], starts) -> tuple[np.ndarray, np.ndarray]:
    """The load's ``(theta_load_out, omega_load_out)`` at the window starts ``starts`` (one per parameter set of
    ``plist``): measured when a load encoder was recorded (``load_position``, its zero moved onto the rotor's by
    the median deflection), else estimated from the recorded rotor motion (:func:`load_trajectory`, once per
    distinct transmission)."""
    starts = np.asarray(starts, int)
    S = ctx.sig
    th_out = np.empty(len(plist))
    w_out = np.empty(len(plist))
    cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    if "theta_load" in S:       # a load encoder: its (low-passed) reading, the two encoders' zero offset removed
        key = ("measured",)
        N0 = plist[0].gear.gear_ratio if plist else 1.0
        offset = float(np.median(S["theta"] / N0 - S["theta_load"]))
        cache[key] = (ctx.dec.lowpass(S["theta_load"]) + offset, ctx.dec.lowpass(S["omega_load"]))
    for j, p in enumerate(plist):
        g = p.gear
        key = (g.gear_ratio, g.transmission_stiffness, g.transmission_damping, g.load_inertia, p.load.load_torque,
               g.backlash)
        if "theta_load" in S and g.transmission_stiffness > 0.0:
            key = ("measured",)
        if key not in cache:
            cache[key] = load_trajectory(S["theta"], S["omega_s"], ctx.t, ctx.segments, p)
        th_l, w_l = cache[key]
        th_out[j], w_out[j] = th_l[starts[j]], w_l[starts[j]]
    return th_out, w_out


#: the dead-zone candidate's spring, as multiples of the compliance candidate's (a dead zone softens the spring the
#: rotor sees, so its own spring is stiffer): searched with the dead zone's width
DEAD_ZONE_STIFFER = (1.25, 1.6, 2.0, 3.0, 5.0)


@dataclass(frozen=True)
class TransmissionPrediction:
    """What one candidate transmission predicts for the experiments that separate a spring from a dead zone
    (output side): the deflection ``theta/N - theta_load`` a load encoder would read over this recording's
    motion (RMS and peak to peak, from the simulator's load equation driven by the recorded rotor), and the lost
    motion a slow reversal of the transmission torque at low torque shows (the dead zone's width; 0 for a
    spring, whose deflection passes through zero with the torque)."""

    stiffness: float              #: [N*m/rad]
    backlash: float               #: [rad]
    deflection_rms: float         #: [rad]
    deflection_p2p: float         #: [rad]
    lost_motion: float            #: [rad]
    load_angle_rms_difference: float   #: [rad] RMS of its load angle minus the compliance candidate's


def spring_or_dead_zone(ctx, p: ActuatorParams, stiffer=DEAD_ZONE_STIFFER):
    """The two models a rotor-only recording cannot tell apart, each fitted to it, and what each predicts for
    the deciding experiment: ``p`` (a compliant transmission as the finding wrote it) and a dead zone behind a
    stiffer spring (same load inertia and damping ratio; the spring's multiple from ``stiffer`` and the width on a
    log grid, then refined) that makes its load follow the recorded rotor as ``p``'s does (least squares of the
    two load angles over the recording: the rotor cannot see the difference). Returns ``(spring, dead_zone)``
    :class:`TransmissionPrediction` s, or None without a spring or an angle."""
    from scipy.optimize import minimize_scalar

    g = p.gear
    S = ctx.sig
    if not g.transmission_stiffness > 0.0 or "theta" not in S or "omega_s" not in S:
        return None
    N = g.gear_ratio
    th_out = np.asarray(S["theta"], float) / N
    th_a, _ = load_trajectory(S["theta"], S["omega_s"], ctx.t, ctx.segments, p)
    if not np.isfinite(th_a).all():
        return None
    d_a = th_out - th_a

    def dead_zone(r, b):
        return p.replace(**{"gear.transmission_stiffness": r * g.transmission_stiffness,
                            "gear.transmission_damping": g.transmission_damping * math.sqrt(r),
                            "gear.backlash": float(b)})

    def follow(r, b):
        return load_trajectory(S["theta"], S["omega_s"], ctx.t, ctx.segments, dead_zone(r, b))[0]

    def cost(r, b):
        return float(np.mean((follow(r, b) - th_a) ** 2))

    hi = min(0.5, max(2.0 * float(np.percentile(np.abs(d_a), 99)), 1e-6))
    widths = np.geomspace(hi * 1e-2, hi, 10)
    best = min(((cost(r, b), r, i) for r in stiffer for i, b in enumerate(widths)), key=lambda x: x[0])
    _, r, i = best
    lo_b, hi_b = widths[max(i - 1, 0)], widths[min(i + 1, len(widths) - 1)]
    res = minimize_scalar(lambda b: cost(r, b), bounds=(lo_b, hi_b), method="bounded",
                          options={"xatol": (hi_b - lo_b) * 1e-2, "maxiter": 15})
    b = float(res.x) if res.fun <= best[0] else float(widths[i])
    th_b = follow(r, b)
    d_b = th_out - th_b

    def pred(k, gap, d, th_l):
        return TransmissionPrediction(float(k), float(gap), float(np.sqrt(np.mean(d * d))), float(np.ptp(d)),
                                      float(gap), float(np.sqrt(np.mean((th_l - th_a) ** 2))))

    return pred(g.transmission_stiffness, 0.0, d_a, th_a), pred(r * g.transmission_stiffness, b, d_b, th_b)
