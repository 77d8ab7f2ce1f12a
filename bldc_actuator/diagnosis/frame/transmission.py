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
