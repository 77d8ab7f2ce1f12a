"""Generated recordings for issue #24's timestamp-jitter miss (test_jitter_inertia.py): a position-controlled joint
with Coulomb friction whose rotor inertia may be off, logged by a logger whose clock is not the drive's. The
sample instants scatter around the nominal period, t_k = k T + e_k, with e_k white jitter (a share of T) plus a
slowly wandering clock (a random walk, low-passed); the joint controller acts at those instants. The log's time
column is either the true t_k (a logger that stamps each sample when taken) or the nominal k T (a logger that
counts samples). Recorded through the project's own simulator (:class:`bldc_actuator.model.Actuator`), logged like
a drive logs: q/d current and voltage with noise, a 14-bit encoder angle, a backward-difference speed."""

from __future__ import annotations

import math

import numpy as np

from bldc_actuator import voltage_timing
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams

#: the nominal joint: Coulomb friction 0.02 N*m known to the model
NOMINAL = ActuatorParams().replace(**{"effects.coulomb_friction": 0.02})


def sample_instants(n: int, period: float, *, white: float, wander: float, seed: int) -> np.ndarray:
    """[s] t_k = k T + e_k: ``white`` x T of white (uniform, its sd ``white`` T) jitter plus a wandering clock of
    sd ``wander`` x T (an integrated random walk low-passed over ~0.2 s); strictly increasing."""
    rng = np.random.default_rng(seed)
    e_white = white * period * math.sqrt(12.0) * (rng.random(n) - 0.5)
    walk = np.cumsum(rng.standard_normal(n))
    k = max(1, int(0.2 / period))
    slow = np.convolve(walk - np.linspace(walk[0], walk[-1], n), np.ones(k) / k, mode="same")
    slow = wander * period * slow / max(float(np.std(slow)), 1e-12)
    t = np.arange(n) * period + e_white + slow
    t -= t[0]
    if not np.all(np.diff(t) > 0):
        raise ValueError("sample_instants: jitter too large for a monotonic clock")
    return t


def record(truth: ActuatorParams, *, duration: float = 20.0, rate: float = 500.0, white: float = 0.2,
           wander: float = 0.5, stamps: str = "true", seed: int = 0, noise_i: float = 0.03,
           noise_v: float = 0.03, enc_bits: int = 14) -> Signals:
    """The joint (``truth``) tracking a multisine with steps under a PD position loop run at the sample instants.
    ``stamps``: "true" (sampled at the jittered t_k, logged with t_k), "nominal" (sampled at t_k, logged with k T:
    a logger that counts samples) or "receipt" (sampled at k T, logged with t_k: a logger that stamps a sample when
    it receives it). ``white``/``wander``: jitter sizes as a share of the period T = 1/``rate`` (0: a uniform
    clock)."""
    if stamps not in ("true", "nominal", "receipt"):
        raise ValueError(f"stamps: expected 'true', 'nominal' or 'receipt', got {stamps!r}")
    rng = np.random.default_rng(seed + 1000)
    n = int(round(duration * rate))
    T = 1.0 / rate
    t_jit = sample_instants(n, T, white=white, wander=wander, seed=seed) if (white or wander) else np.arange(n) * T
    t = np.arange(n) * T if stamps == "receipt" else t_jit
    m = NOMINAL.motor
    J, K = m.rotor_inertia, m.torque_constant_q
    wn = 2 * math.pi * 12.0
    kp, kd = J * wn ** 2 / K, 2 * 0.7 * J * wn / K

    def ref(x):
        steps = 3.0 * np.sign(np.sin(2 * np.pi * 0.37 * x))
        return steps + 15.0 * np.sin(2 * np.pi * 0.5 * x) + 5.0 * np.sin(2 * np.pi * 2.3 * x) \
            + 1.5 * np.sin(2 * np.pi * 6.1 * x)

    act = Actuator(truth)
    qstep = 2 * math.pi / 2 ** enc_bits
    names = ("current_command", "current", "current_d", "position", "velocity", "voltage_q", "voltage_d")
    out = {k: np.zeros(n) for k in names}
    prev_pos, prev_err = 0.0, 0.0
    for k in range(n):
        s = act.state
        pos = round(s.theta / qstep) * qstep
        vel = (pos - prev_pos) / (t[k] - t[k - 1]) if k else 0.0
        prev_pos = pos
        err = float(ref(t[k])) - pos
        derr = (err - prev_err) / (t[k] - t[k - 1]) if k else 0.0
        prev_err = err
        cmd = max(-15.0, min(15.0, kp * err + kd * derr))
        out["current_command"][k] = cmd
        out["current"][k] = s.i_q + noise_i * rng.standard_normal()
        out["current_d"][k] = s.i_d + noise_i * rng.standard_normal()
        out["position"][k], out["velocity"][k] = pos, vel
        out["voltage_q"][k] = s.v_q + noise_v * rng.standard_normal()
        out["voltage_d"][k] = s.v_d + noise_v * rng.standard_normal()
        act.set_current_command(cmd)
        if k + 1 < n:
            act.step(float(t[k + 1] - t[k]))
    time = np.arange(n) * T if stamps == "nominal" else t_jit
    timing = voltage_timing.from_metadata(voltage_timing.kernel_declaration(truth, T), "jitter_generators")
    return Signals(time, out, source="synthetic", meta={"voltage_timing": timing})


def inertia_case(j_ratio: float = 1.4, **kw):
    """(recording, nominal, truth): the rotor inertia ``j_ratio`` x the nominal's (1: no error)."""
    truth = NOMINAL.replace(**{"motor.rotor_inertia": NOMINAL.motor.rotor_inertia * j_ratio})
    return record(truth, **kw), NOMINAL, truth
