"""Torque-sensor-only logs (issue #9): a motor turned by a dynamometer with no current logged — cogging and
friction from the torque balance, the angle integrated from the speed when there is no encoder column.

The truth comes from the project's simulator (implicit-midpoint kernel with stick-slip friction and the
interval-mean cogging torque), not from the fitted equation: the actuator holds zero current while an
external torque at its output turns it both ways; that torque is what the sensor reads."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bldc_actuator.diagnosis import torque_balance as tb
from bldc_actuator.diagnosis.io.cleaning import clean
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams

TRUE = {"effects.coulomb_friction": 0.02, "motor.viscous_damping": 2e-4, "effects.cogging_order": 12,
        "effects.cogging_cos": (0.008,), "effects.cogging_sin": (-0.004,), "motor.rotor_inertia": 6e-5}


def _dyno_run(p: ActuatorParams, duration=20.0, rate=1000.0, noise=0.002, seed=1):
    """A speed-controlled dynamometer (PI on speed, as a dyno in speed mode) turns the unpowered actuator
    (zero current held) slowly both ways along a speed profile; the dyno's torque is what the sensor reads."""
    rng = np.random.default_rng(seed)
    a = Actuator(p)
    a.set_current_command(0.0)
    n = int(duration * rate)
    t, w, tau = np.empty(n), np.empty(n), np.empty(n)
    kp, ki, integ, load = 0.02, 0.4, 0.0, 0.0
    for k in range(n):
        tk = k / rate
        w_ref = 3.0 * math.sin(2 * math.pi * 0.1 * tk) + 1.0 * math.sin(2 * math.pi * 0.43 * tk)
        o = a.outputs()
        err = w_ref - o["omega"]
        integ += err / rate
        load = -(kp * err + ki * integ)            # the external torque opposing + motion is positive
        a.set_load_torque(load)
        a.step_ns(int(1e9 / rate))
        o = a.outputs()
        t[k], w[k], tau[k] = o["t"], o["omega"], load
    return t, w, tau + rng.normal(0, noise, n)


@pytest.fixture(scope="module")
def run():
    p = ActuatorParams().replace(**TRUE)
    t, w, tau = _dyno_run(p)
    sig = clean(Signals(t, {"torque": tau, "velocity": w}, "dyno", meta={"gear_ratio": 1.0}), params=p)
    return p, sig


def test_recovers_friction_and_cogging_with_angle_from_speed(run):
    p, sig = run
    assert tb.applicable(sig)
    nominal = ActuatorParams().replace(**{"motor.viscous_damping": 1e-5})
    res = tb.diagnose(sig, nominal)
    assert "integrated from the speed" in res.angle_source
    by = {f.effect: f for f in res.findings}
    assert set(by) >= {"coulomb_friction", "viscous_friction", "cogging_torque"}, res.to_dict()
    assert by["coulomb_friction"].parameters["coulomb_friction"] == pytest.approx(0.02, rel=0.1)
    assert by["viscous_friction"].parameters["viscous_damping"] == pytest.approx(2e-4, rel=0.2)
    cog = by["cogging_torque"].parameters
    assert cog["cogging_order"] == 12
    assert cog["amplitude_1"] == pytest.approx(math.hypot(0.008, 0.004), rel=0.15)
    for f in res.findings:
        assert f.held_out["after"] < f.held_out["before"]
    assert res.r2 > 0.9
    assert res.held_out["after"] < 0.5 * res.held_out["nominal"]      # better than the given parameters
    upd = tb.updated_params(nominal, res)
    assert upd.effects.cogging_order == 12 and upd.effects.coulomb_friction == pytest.approx(0.02, rel=0.1)


def test_null_no_cogging_no_extra_terms():
    p = ActuatorParams().replace(**{**TRUE, "effects.cogging_order": 0, "effects.cogging_cos": (),
                                    "effects.cogging_sin": ()})
    t, w, tau = _dyno_run(p, duration=12.0, seed=3)
    sig = clean(Signals(t, {"torque": tau, "velocity": w}, "dyno", meta={"gear_ratio": 1.0}), params=p)
    res = tb.diagnose(sig, p)
    assert "cogging_torque" not in {f.effect for f in res.findings}


def test_powered_motor_is_not_identifiable():
    """A torque the balance cannot explain (the motor's own, unlogged current) -> not identifiable."""
    rng = np.random.default_rng(0)
    t = np.arange(5000) / 500.0
    w = 5 * np.sin(2 * np.pi * 0.2 * t)
    tau = rng.normal(0, 1.0, len(t)) + 2 * np.sign(np.sin(2 * np.pi * 1.3 * t))   # unrelated to the motion
    sig = clean(Signals(t, {"torque": tau, "velocity": w}, "x", meta={"gear_ratio": 1.0}))
    res = tb.diagnose(sig, ActuatorParams())
    assert res.r2 < 0.5 and not res.findings
    assert any("not identifiable" in n for n in res.notes)
