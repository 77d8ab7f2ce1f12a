"""Generated recordings for issue #24's base-model symptom (test_issue24_base_model.py): a current-commanded
thermal duty cycle under a viscous brake (the speed follows the current, so R and K_t are collinear in the voltage
equation), and a well-excited recording (position-controlled swings, no brake) of a motor whose R and K_t are off.
Recorded through the project's own simulator (:class:`bldc_actuator.model.Actuator`), logged like a drive logs:
q/d current and voltage with noise, encoder angle, backward-difference speed, winding/housing temperatures."""

from __future__ import annotations

import math

import numpy as np

from bldc_actuator import voltage_timing
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams

#: a small motor that warms quickly (winding 3 J/K, housing 15 J/K: 25 -> ~110 C in two minutes) under a viscous
#: brake of 0.02 N*m*s/rad (mechanical time constant J/b = 3 ms: the speed is the current's, omega = K i / b);
#: copper R(T) modelled
BRAKE_NOMINAL = ActuatorParams().replace(**{
    "motor.viscous_damping": 0.02, "thermal.winding_heat_capacity": 3.0, "thermal.housing_heat_capacity": 15.0,
    "thermal.housing_to_ambient_resistance": 4.0})


def duty_cycle_command(t: np.ndarray) -> np.ndarray:
    """q current [A]: 12 s at ~11 A, 6 s at ~3 A, repeated, each with a 1.3 Hz and a 7 Hz ripple."""
    high = (t % 18.0) < 12.0
    base = np.where(high, 11.0, 3.0)
    return base + 1.5 * np.sin(2 * np.pi * 1.3 * t) + 0.6 * np.sin(2 * np.pi * 7.0 * t)


def record(truth: ActuatorParams, command, *, duration: float, rate: float = 1000.0, seed: int = 0,
           noise_i: float = 0.03, noise_v: float = 0.02, noise_T: float = 0.05, enc_bits: int = 14) -> Signals:
    """``command(t, state)`` -> q current command [A], played into ``truth`` and logged at ``rate``."""
    rng = np.random.default_rng(seed)
    act = Actuator(truth)
    n = int(round(duration * rate))
    dt = 1.0 / rate
    q = 2 * math.pi / 2 ** enc_bits
    names = ("current_command", "current", "current_d", "position", "velocity", "voltage_q", "voltage_d",
             "winding_temperature", "housing_temperature")
    out = {k: np.zeros(n) for k in names}
    prev = 0.0
    t = np.arange(n) * dt
    for k in range(n):
        s = act.state
        pos = round(s.theta / q) * q
        vel = (pos - prev) / dt if k else 0.0
        prev = pos
        cmd = float(command(t[k], pos, vel))
        out["current_command"][k] = cmd
        out["current"][k] = s.i_q + noise_i * rng.standard_normal()
        out["current_d"][k] = s.i_d + noise_i * rng.standard_normal()
        out["position"][k], out["velocity"][k] = pos, vel
        out["voltage_q"][k] = s.v_q + noise_v * rng.standard_normal()
        out["voltage_d"][k] = s.v_d + noise_v * rng.standard_normal()
        out["winding_temperature"][k] = s.T_winding + noise_T * rng.standard_normal()
        out["housing_temperature"][k] = s.T_housing + noise_T * rng.standard_normal()
        act.set_current_command(cmd)
        act.step(dt)
    timing = voltage_timing.from_metadata(voltage_timing.kernel_declaration(truth, dt), "issue24_generators")
    return Signals(t, out, source="synthetic", meta={"voltage_timing": timing})


def thermal_brake_case(duration: float = 120.0, rate: float = 1000.0, seed: int = 1):
    """(recording, nominal, truth): the magnet's flux coefficient -0.1 %/K hidden (nominal: disabled)."""
    truth = BRAKE_NOMINAL.replace(**{"motor.magnet_temperature_enabled": True,
                                     "motor.magnet_temperature_coefficient": -0.001})
    cmd = duty_cycle_command
    sig = record(truth, lambda t, pos, vel: cmd(np.asarray(t)), duration=duration, rate=rate, seed=seed)
    return sig, BRAKE_NOMINAL, truth


def wrong_core_case(r_ratio: float = 1.5, k_ratio: float = 1.3, duration: float = 30.0, rate: float = 1000.0,
                    seed: int = 2):
    """(recording, nominal, truth): position-controlled swings of several speeds and loads (speed and current
    independent) of a motor whose R and K_t are ``r_ratio`` and ``k_ratio`` x the nominal's."""
    nominal = ActuatorParams()
    m = nominal.motor
    truth = nominal.replace(**{"motor.phase_resistance": m.phase_resistance * r_ratio,
                               "motor.torque_constant_q": m.torque_constant_q * k_ratio})
    J, K = m.rotor_inertia, m.torque_constant_q
    wn = 2 * math.pi * 15.0
    kp, kd = J * wn ** 2 / K, 2 * 0.7 * J * wn / K

    def ref(t):
        return 20.0 * math.sin(2 * math.pi * 0.5 * t) + 6.0 * math.sin(2 * math.pi * 2.3 * t) \
            + 2.0 * math.sin(2 * math.pi * 6.1 * t)

    def dref(t):
        return (20.0 * 2 * math.pi * 0.5 * math.cos(2 * math.pi * 0.5 * t)
                + 6.0 * 2 * math.pi * 2.3 * math.cos(2 * math.pi * 2.3 * t)
                + 2.0 * 2 * math.pi * 6.1 * math.cos(2 * math.pi * 6.1 * t))

    def cmd(t, pos, vel):
        return max(-15.0, min(15.0, kp * (ref(t) - pos) + kd * (dref(t) - vel)))

    sig = record(truth, cmd, duration=duration, rate=rate, seed=seed)
    return sig, nominal, truth
