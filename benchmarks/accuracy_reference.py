#!/usr/bin/env python3
"""Accuracy of the actuator kernel against an INDEPENDENT fine-step reference with the same control law.

``step(1e-3)`` and ``step(1e-4)`` are bit-identical at a fixed current-loop rate (the physics interval is the
controller period), so comparing step sizes only tests interval splitting. This script instead integrates the
continuous plant with its own code — classical RK4 at ``--substep`` (default 0.5 µs), nothing imported from
the kernel — under the SAME discrete controller (d/q PI with pole-zero cancelling gains, ω·L and back-EMF
feed-forward, back-calculation anti-windup, SVPWM circle limit) executed at the same tick times with a
zero-order-hold voltage, and reports how far ``bldc_actuator.model.Actuator`` is from it:

* a current chirp below the voltage limit,
* a current step that drives the rotor into the voltage limit,
* the order of convergence in the loop period (5, 10, 20, 40 kHz current loops).

    python benchmarks/accuracy_reference.py [--seconds 0.4]

Plant (motor side, non-salient, power-invariant d-q, constant R, no friction/thermal terms):
``L di/dt = v - R i - j p ω L i - j K ω``, ``J dω/dt = K i_q - b ω``.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

try:
    from numba import njit
except ImportError:  # pragma: no cover
    def njit(*a, **k):
        return (lambda f: f) if not a or not callable(a[0]) else a[0]


@njit(cache=False)   # also imported by file path from the tests (numba caches need an importable module)
def _reference(cmd, tick_s, substeps, R, L, K, J, b, p, V_max, Kp, Ki, decouple, I_lim, delay_substeps):
    """RK4 of the continuous plant between controller ticks; returns i_q, i_d, ω at every tick. The voltage
    computed at a tick reaches the plant ``delay_substeps`` substeps later (a computation delay)."""
    n = cmd.shape[0]
    out = np.zeros((n, 3))
    i = 0j
    w = 0.0
    z = 0j
    v_old = 0j
    h = tick_s / substeps
    for k in range(n):
        # the drive: sample, PI, limit, anti-windup (its own implementation of the documented law)
        i_ref = min(max(cmd[k], -I_lim), I_lim)
        err = 1j * i_ref - i
        v_ff = 1j * (p * w * L * i + K * w) if decouple else 0j
        v_pi = Kp * err + z + v_ff
        mag = abs(v_pi)
        v_new = v_pi * (V_max / mag) if mag > V_max else v_pi
        z = z + Ki * tick_s * err + (v_new - v_pi)
        for sub in range(substeps):
            v = v_old if sub < delay_substeps else v_new
            def f(i_, w_):
                di = (v - R * i_ - 1j * p * w_ * L * i_ - 1j * K * w_) / L
                dw = (K * i_.imag - b * w_) / J
                return di, dw
            k1i, k1w = f(i, w)
            k2i, k2w = f(i + 0.5 * h * k1i, w + 0.5 * h * k1w)
            k3i, k3w = f(i + 0.5 * h * k2i, w + 0.5 * h * k2w)
            k4i, k4w = f(i + h * k3i, w + h * k3w)
            i = i + h / 6.0 * (k1i + 2 * k2i + 2 * k3i + k4i)
            w = w + h / 6.0 * (k1w + 2 * k2w + 2 * k3w + k4w)
        out[k, 0], out[k, 1], out[k, 2] = i.imag, i.real, w
        v_old = v_new   # what the plant sees during the next tick's delay
    return out


def reference(params, cmd, substep_s):
    m, d = params.motor, params.drive
    from bldc_actuator.frames import voltage_limit_q   # the inverter's circle: a documented conversion

    tick = 1.0 / d.current_loop_rate
    wc = 2 * math.pi * d.current_loop_bandwidth
    substeps = max(1, int(round(tick / substep_s)))
    return _reference(np.asarray(cmd, float), tick, substeps, m.phase_resistance,
                      m.q_inductance, m.torque_constant_q, m.rotor_inertia, m.viscous_damping, m.pole_pairs,
                      voltage_limit_q(d.bus_voltage, m.winding) * d.modulation_limit, wc * m.q_inductance,
                      wc * m.phase_resistance, bool(d.decoupling_enabled), d.current_limit,
                      int(round(d.current_loop_delay / tick * substeps)))


def kernel(params, cmd):
    from bldc_actuator.model import Actuator

    act = Actuator(params)
    tick = 1.0 / params.drive.current_loop_rate
    out = np.zeros((len(cmd), 3))
    for k, c in enumerate(cmd):
        act.set_current_command(float(c))
        act.step(tick)
        s = act.state
        out[k] = s.i_q, s.i_d, s.omega
    return out


def scenarios(params, seconds):
    rate = params.drive.current_loop_rate
    t = np.arange(int(round(seconds * rate))) / rate
    chirp = 3.0 * np.sin(2 * np.pi * (5.0 + 100.0 * t) * t) * (t < seconds)
    step = np.where(t > 0.01, 0.4 * params.drive.current_limit, 0.0)
    return {"chirp 5-85 Hz, 3 A (below the voltage limit)": chirp,
            "current step into the voltage limit": step}


def compare(params, cmd, substep):
    ref, ker = reference(params, cmd, substep), kernel(params, cmd)
    e = np.abs(ker - ref)
    return {"i_q_max": e[:, 0].max(), "i_q_rms": float(np.sqrt(np.mean(e[:, 0] ** 2))), "i_d_max": e[:, 1].max(),
            "omega_max": e[:, 2].max(), "omega_range": float(np.ptp(ref[:, 2])),
            "i_q_range": float(np.ptp(ref[:, 0]))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=0.4)
    ap.add_argument("--substep", type=float, default=0.5e-6, help="RK4 step of the reference [s]")
    ap.add_argument("--preset", default="ak80_9")
    args = ap.parse_args()
    from bldc_actuator.params import load_preset

    # the reference plant has no friction, cogging, load or temperature terms: switch them off in both
    base = load_preset(args.preset).replace(**{
        "effects.coulomb_friction": 0.0, "effects.friction_asymmetry": 0.0, "effects.stribeck_friction": 0.0,
        "effects.cogging_order": 0, "effects.cogging_cos": (), "effects.cogging_sin": (),
        "load.load_torque": 0.0, "load.gravity_torque": 0.0, "load.spring_stiffness": 0.0,
        "motor.resistance_temperature_enabled": False, "motor.magnet_temperature_enabled": False})
    print(f"preset {args.preset}; reference: RK4 at {args.substep * 1e6:g} us, same discrete PI at the same ticks\n")
    print("| scenario (10 kHz loop) | max abs i_q error [A] | RMS i_q error [A] | max abs i_d error [A] | "
          "max abs speed error [rad/s] (of range) |")
    print("|---|---|---|---|---|")
    p10 = base.replace(**{"drive.current_loop_rate": 10000.0})
    for name, cmd in scenarios(p10, args.seconds).items():
        r = compare(p10, cmd, args.substep)
        print(f"| {name} | {r['i_q_max']:.2e} | {r['i_q_rms']:.2e} | {r['i_d_max']:.2e} | "
              f"{r['omega_max']:.2e} ({r['omega_max'] / max(r['omega_range'], 1e-12):.1e}) |")
    print("\norder of convergence in the loop period (chirp and voltage-limit step, max |i_q error|):")
    print("| loop rate [kHz] | chirp [A] | voltage limit [A] |")
    print("|---|---|---|")
    prev = None
    errs = []
    for rate in (5000.0, 10000.0, 20000.0, 40000.0):
        p = base.replace(**{"drive.current_loop_rate": rate, "drive.current_loop_bandwidth": 500.0})
        sc = scenarios(p, args.seconds)
        e = [compare(p, cmd, args.substep)["i_q_max"] for cmd in sc.values()]
        errs.append(e)
        print(f"| {rate / 1e3:g} | {e[0]:.2e} | {e[1]:.2e} |")
    errs = np.array(errs)
    orders = np.log2(errs[:-1] / errs[1:])
    print(f"observed order (log2 of successive error ratios): chirp {', '.join(f'{o:.2f}' for o in orders[:, 0])}; "
          f"voltage limit {', '.join(f'{o:.2f}' for o in orders[:, 1])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
