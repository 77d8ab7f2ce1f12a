"""Generated recordings for the issue-14 format and verdict tests (test_issue14_formats*.py): each reproduces
one real-log symptom with known truth, from the project's own simulator (no hidden data)."""

from __future__ import annotations

import math

import numpy as np

from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams
from test_issue14_judge_helpers import closed_loop_recording, triangle_then_sines

NOMINAL = ActuatorParams().replace(**{"gear.gear_ratio": 9.0})


def pd_run(truth: ActuatorParams, *, duration=16.0, rate=1000.0, seed=0, disturbance=None, limit=15.0,
           report_limit=False, ref=None, noise_i=0.03, noise_v=0.02):
    """Closed-loop PD (15 Hz) position run of ``truth`` at ``rate`` (gains from NOMINAL; the tests' one recorder,
    :func:`test_issue14_judge_helpers.closed_loop_recording`): current command clamped at ``limit``;
    ``disturbance(t)`` an unlogged external torque at the output; ``report_limit``: the drive reports the
    current as exactly its limit while the command is clamped (as real drives log a limited current); ``ref(t)``
    the rotor angle [rad], by default the slow triangle then sines."""
    return closed_loop_recording(truth, NOMINAL, ref if ref is not None else triangle_then_sines, duration=duration,
                                 rate=rate, seed=seed, noise_i=noise_i, noise_v=noise_v, cmd_limit=limit,
                                 disturbance=disturbance, report_limit=report_limit)


def dyno_run(p: ActuatorParams, *, duration=20.0, rate=1000.0, noise=0.002, seed=1, w_ref=None, kp=0.02, ki=0.4):
    """A speed-controlled dynamometer (PI on speed) turns the unpowered actuator (zero current held) along
    ``w_ref(t)`` [rad/s]; the dyno's torque is what the sensor reads (as test_torque_balance)."""
    rng = np.random.default_rng(seed)
    a = Actuator(p)
    a.set_current_command(0.0)
    n = int(duration * rate)
    t, w, tau = np.empty(n), np.empty(n), np.empty(n)
    integ = 0.0
    for k in range(n):
        tk = k / rate
        wr = w_ref(tk)
        o = a.outputs()
        err = wr - o["omega"]
        integ += err / rate
        load = -(kp * err + ki * integ)
        a.set_load_torque(load)
        a.step_ns(int(1e9 / rate))
        o = a.outputs()
        t[k], w[k], tau[k] = o["t"], o["omega"], load
    return t, w, tau + rng.normal(0, noise, n)


def write_csv(path, columns: dict[str, np.ndarray], fmt="%.9g") -> None:
    names = list(columns)
    data = np.column_stack([np.asarray(columns[c], float) for c in names])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt=fmt)


def short_span_w(revs: float, duration: float):
    """A one-direction speed profile that covers ``revs`` revolutions in ``duration`` s (smooth start/stop)."""
    w0 = 2 * math.pi * revs / duration

    def w(t):
        ramp = min(1.0, t / 0.5, max(0.0, (duration - t) / 0.5))
        return w0 * ramp / (1 - 0.5 / duration)
    return w


def limited_run(p: ActuatorParams, *, limit=2.0, duration=16.0, rate=1000.0, seed=2, noise_i=0.03):
    """A torque rig: the actuator's drive holds its current at -``limit`` (reported exactly, as a drive logs its
    limit) after a 0.1 s ramp, while a speed-controlled antagonist (PI) turns it slowly both ways; the
    antagonist's torque at the output is logged as ``load_torque``. K_t is right: nothing is missing."""
    rng = np.random.default_rng(seed)
    a = Actuator(p)
    n = int(duration * rate)
    dt = 1.0 / rate
    out = {k: np.zeros(n) for k in ("current_command", "current", "position", "velocity", "load_torque")}
    kp, ki, integ = 0.05, 1.0, 0.0
    for k in range(n):
        tk = k * dt
        cmd = -limit * min(1.0, tk / 0.1)
        wr = 4.0 * math.sin(2 * math.pi * 0.25 * tk) + 1.5 * math.sin(2 * math.pi * 0.9 * tk)
        o = a.outputs()
        err = wr - o["omega"]
        integ += err * dt
        load = -(kp * err + ki * integ) * p.gear.gear_ratio + (-limit * p.motor.torque_constant_q * p.gear.gear_ratio
                                                               * min(1.0, tk / 0.1))
        st = a.state
        out["current_command"][k] = cmd
        out["current"][k] = cmd if tk >= 0.1 else st.i_q + noise_i * rng.standard_normal()
        out["position"][k] = st.theta
        out["velocity"][k] = st.omega
        out["load_torque"][k] = load
        a.set_load_torque(load)
        a.set_current_command(cmd)
        a.step(dt)
    out["position"] = np.round(out["position"] / (2 * np.pi / 2 ** 14)) * (2 * np.pi / 2 ** 14)
    out["velocity"] = out["velocity"] + 0.01 * rng.standard_normal(n)
    return Signals(np.arange(n) * dt, out, source="synthetic")
