"""A logged voltage that acts later acts on LATER states (issue #14, motulator's resistance found 6-7 % high).

A drive computes its d/q voltage from the sample at ``t_k`` and applies it one computation period later, held for
one period in stator coordinates: it acts, on average, ``d`` = 1.5 periods after ``t_k``, in a frame the rotor has
turned by ``p ω d`` since (motulator's drive: 150 µs). The voltage equation read the turned-back voltage against the
states (current, speed) of ``t_k``: its back-EMF term then misses ``K d dω/dt``, and in free motion
``dω/dt ≈ K i_q / J`` makes that a resistance ``K² d / J`` too high (0.0743² · 150e-6 / 6e-5 = +0.0138 Ω: R 0.182
found as 0.193 on every motulator seed, and +0.0135 Ω on the case without a hidden effect).

The recording here is built by hand, exactly: a speed trajectory of a free rotor (``J dω/dt + b ω = K i_q``), the
q/d voltages of the continuous-time winding (``v = R i + L di/dt + j p ω L i + j K ω``) evaluated ``d`` after each
sample and turned forward by ``p ω d`` (as the drive logs what it computed), 1 kHz, sensor noise and a 14-bit
encoder. The equation-error fit of the resistance (the search's column, with the current command as instrument)
must recover the true R.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bldc_actuator.diagnosis.frame import candidates as cands
from bldc_actuator.diagnosis.frame import equation_error as ee
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.params import ActuatorParams

#: motulator's case joint (benchmarks' third-party set): K 0.0743 N·m/A, J 6e-5 kg·m², L 80 µH, p 21
NOMINAL = ActuatorParams().replace(**{
    "motor.pole_pairs": 21, "motor.phase_resistance": 0.13, "motor.q_inductance": 8.0e-5,
    "motor.torque_constant_q": 0.0743, "motor.rotor_inertia": 6.0e-5, "motor.viscous_damping": 1.0e-5,
    "motor.resistance_temperature_enabled": False, "motor.magnet_temperature_enabled": False,
    "drive.current_loop_rate": 10000.0, "drive.current_loop_bandwidth": 500.0, "drive.current_loop_delay": 1.0e-4,
    "gear.gear_ratio": 1.0})
R_TRUE = 0.182          # [ohm] 40 % above the nominal file's
D = 1.5e-4              # [s] one period of computation delay plus half the held period (10 kHz loop)


def _speed(t: np.ndarray, seed: int):
    """ω(t) [rad/s] and dω/dt of a multisine (0.4-13 Hz, up to about 30 rad/s; about 0.2 A RMS of q current), analytic."""
    rng = np.random.default_rng(seed)
    f = np.array([0.4, 1.1, 2.3, 3.7, 5.9, 9.0, 13.0])
    a = np.array([12.0, 6.0, 4.0, 3.0, 2.5, 2.0, 1.6])
    ph = rng.uniform(0, 2 * math.pi, len(f))
    arg = 2 * math.pi * f[None, :] * t[:, None] + ph
    w = (a * np.sin(arg)).sum(axis=1)
    dw = (a * 2 * math.pi * f * np.cos(arg)).sum(axis=1)
    d2w = -(a * (2 * math.pi * f) ** 2 * np.sin(arg)).sum(axis=1)
    th = (-a / (2 * math.pi * f) * np.cos(arg)).sum(axis=1)
    return w, dw, d2w, th - th[0]


def _states(p: ActuatorParams, t: np.ndarray, seed: int, R: float):
    m = p.motor
    w, dw, d2w, th = _speed(t, seed)
    i_q = (m.rotor_inertia * dw + m.viscous_damping * w) / m.torque_constant_q     # free rotor
    di_q = (m.rotor_inertia * d2w + m.viscous_damping * dw) / m.torque_constant_q
    pw = m.pole_pairs * w
    v_q = R * i_q + m.q_inductance * di_q + m.torque_constant_q * w                 # i_d = 0
    v_d = -pw * m.q_inductance * i_q
    return w, th, i_q, v_q, v_d


def recording(p: ActuatorParams, *, R: float = R_TRUE, d: float = D, seed: int = 1, duration: float = 8.0,
              rate: float = 1000.0, turned: bool = True) -> Signals:
    """The states at each sample ``t_k``; the voltage the drive computed there, which acts at ``t_k + d`` (the
    winding's voltage at that instant) in the frame of ``t_k`` (turned forward by ``p ω d``); ``turned=False``: in
    the frame of ``t_k + d`` (a drive that advances its angle by the whole delay: no turn on the d axis shows it)."""
    rng = np.random.default_rng(100 + seed)
    t = np.arange(int(round(duration * rate))) / rate
    w, th, i_q, _, _ = _states(p, t, seed, R)
    w_l, _, _, v_q, v_d = _states(p, t + d, seed, R)          # the voltage acting d later
    v = (v_d + 1j * v_q) * (np.exp(1j * p.motor.pole_pairs * w_l * d) if turned else 1.0)
    n = len(t)
    q = 2 * math.pi / 2 ** 14
    ch = {"current_command": i_q.copy(),
          "current": i_q + 0.03 * rng.standard_normal(n), "current_d": 0.03 * rng.standard_normal(n),
          "position": np.round(th / q) * q, "velocity": w + 0.01 * rng.standard_normal(n),
          "voltage_q": v.imag + 0.01 * rng.standard_normal(n), "voltage_d": v.real + 0.01 * rng.standard_normal(n),
          "bus_voltage": np.full(n, 24.0)}
    return Signals(t, ch, source="hand-built: voltage acting d after its sample", segments=[(0, n)])


def resistance_by_equation_error(sig: Signals, p: ActuatorParams,
                                 voltage_timing: str = "auto") -> tuple[float, float, ee.Context]:
    """R [ohm] and its sd from the search's resistance column (nuisance columns included), as the search fits it."""
    ctx = ee.prepare([(sig, False)], p, holdout=0.3, voltage_timing=voltage_timing)
    cols = {k: ctx.column(k, b) for k, b in ctx.nuisance.items()}
    cols["r_err"] = ctx.column("r_err", cands.col_r_err)
    keys = list(cols)
    fit = ee.fit_columns(ctx, cols, keys, {"electrical": 1.0}, blocks=["electrical"])
    return p.motor.phase_resistance + float(fit.beta[-1]), float(math.sqrt(fit.cov[-1, -1])), ctx


def test_the_bias_this_reproduces_is_the_one_seen():
    """The missed term's size, stated: K² d / J is 7.6 % of the true R here (motulator: R 0.182 found 0.193)."""
    m = NOMINAL.motor
    assert m.torque_constant_q ** 2 * D / m.rotor_inertia / R_TRUE == pytest.approx(0.076, abs=0.002)


@pytest.mark.parametrize("seed", [1, 2])
def test_resistance_behind_a_delayed_turned_voltage_is_recovered(seed):
    """R x 1.4 recovered within 2.5 % (its sd is 0.7 %; over 12 noise draws of the nominal motor the fit's mean error
    was +0.0004 ± 0.0004 ohm); read against the states of the voltage's own sample it came out 7-8 % high (0.198,
    0.195). The frame delay is read from the d axis as the 150 µs the log was built with."""
    R, sd, ctx = resistance_by_equation_error(recording(NOMINAL, seed=seed), NOMINAL)
    assert float(ctx.sig["frame_delay"]) == pytest.approx(D, rel=0.03)
    assert sd < 0.01 * R_TRUE
    assert R == pytest.approx(R_TRUE, rel=0.025), (R, sd)


def test_nominal_motor_behind_the_same_log_shows_no_resistance_error():
    """The same log of the nominal motor: R within 0.004 ohm (3 sd) of the nominal 0.13 ohm (it was 0.146: +0.016)."""
    R, sd, _ = resistance_by_equation_error(recording(NOMINAL, R=0.13, seed=3), NOMINAL)
    assert R == pytest.approx(0.13, abs=0.004), (R, sd)


def test_a_voltage_the_log_cannot_place_is_placed_by_the_user():
    """A drive that advances its angle by the whole delay (gym-electric-motor's, written for the benchmark): no frame
    turn on the d axis and, noise-free inside the loop, no pairing signature: the log cannot say when its voltage acts.
    Read at its sample, R comes out K² d / J high (the GEM seed-4 extra: 0.139 for 0.130); told the log holds the
    voltage computed from each sample (``voltage_timing="command"``: it acts the nominal 100 µs computation delay +
    half the 100 µs period later), R is recovered; an unknown timing value is refused naming the field."""
    sig = recording(NOMINAL, seed=2, turned=False)
    R_auto, _, ctx = resistance_by_equation_error(sig, NOMINAL)
    assert "frame_delay" not in ctx.sig and "voltage_alignment" not in ctx.sig
    m = NOMINAL.motor
    assert R_auto - R_TRUE == pytest.approx(m.torque_constant_q ** 2 * D / m.rotor_inertia, rel=0.3)
    R_cmd, sd, ctx = resistance_by_equation_error(sig, NOMINAL, voltage_timing="command")
    assert float(ctx.sig["voltage_alignment"]) == pytest.approx(D)
    assert R_cmd == pytest.approx(R_TRUE, rel=0.025), (R_cmd, sd)
    with pytest.raises(ValueError, match="voltage_timing"):
        ee.prepare([(sig, False)], NOMINAL, voltage_timing="late")
