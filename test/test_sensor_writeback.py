"""Current-sensor errors named by diagnose are written back as drive parameters the simulated controller acts on
(issue #7, "simulate every effect you can name"): the order-p ripple as sensor offsets, the order-2p ripple as a
gain mismatch. The maps from the fitted ripple to the sensor parameters (bldc_actuator/diagnosis/frame/simulate.py, built
on frames.abc_to_dq) are checked against the kernel's own sensor model (kernel.measured_current_dq), and the
gain mismatch end to end: a recording of an actuator whose phase-a/b sensors read 5 % high / 5 % low under a known 1 N·m load, logged as
its drive logs it (the measured current), is diagnosed, and the written gains reproduce the truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bldc_actuator.diagnosis.pipeline import diagnose
from bldc_actuator.diagnosis.frame.writeback import sensor_gains_for_q_ripple, sensor_offsets_for_q_ripple
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.kernel import measured_current_dq
from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams

TH = np.linspace(0.0, 2 * math.pi, 360, endpoint=False)


def _components(err, order):
    return (2 * np.mean(err * np.cos(order * TH)), 2 * np.mean(err * np.sin(order * TH)))


def test_offset_map_inverts_the_kernel_sensor_model():
    o_a, o_b = 0.08, -0.05
    err = np.array([measured_current_dq(0.0, 0.0, th, o_a, o_b, 1.0, 1.0)[1] for th in TH])
    assert sensor_offsets_for_q_ripple(*_components(err, 1)) == pytest.approx((o_a, o_b), rel=1e-9)


def test_gain_map_inverts_the_kernel_sensor_model():
    """Only the difference of the two gains shows in the order-2p ripple (its phase is fixed); the common part is
    a constant scale (the kernel's mean q error is (δ_a + δ_b) / 2), so a 1.07 / 0.97 pair is recovered as its
    difference, split evenly, and explains the whole ripple; a ripple at another phase is only partly a gain."""
    g_a, g_b, i_q = 1.07, 0.97, 3.0
    err = np.array([measured_current_dq(0.0, i_q, th, 0.0, 0.0, g_a, g_b)[1] - i_q for th in TH]) / i_q
    assert np.mean(err) == pytest.approx(((g_a - 1) + (g_b - 1)) / 2, abs=1e-12)
    d_a, d_b, share = sensor_gains_for_q_ripple(*_components(err, 2))
    assert (d_a, d_b) == pytest.approx((0.05, -0.05), rel=1e-9) and share == pytest.approx(1.0, abs=1e-12)
    c, s = _components(err, 2)
    assert sensor_gains_for_q_ripple(-s, c)[2] < 0.5      # the same ripple turned 45° (90° at order 2)


def _recording(truth, duration=16.0, rate=1000.0, seed=2):
    """Closed-loop PD joint (15 Hz) on the quantised angle; the drive logs its MEASURED d/q current."""
    rng = np.random.default_rng(seed)
    act = Actuator(truth)
    n, dt = int(duration * rate), 1.0 / rate
    J, K = truth.motor.rotor_inertia, truth.motor.torque_constant_q
    wn = 2 * np.pi * 15
    kp, kd = J * wn ** 2 / K, 2 * 0.7 * J * wn / K
    q = 2 * np.pi / 2 ** 14
    t = np.arange(n) * dt
    ref = 3.0 * np.sin(2 * np.pi * 0.3 * t) + 1.5 * np.sin(2 * np.pi * 1.1 * t) + 0.02 * t ** 2
    dref = np.gradient(ref, dt)
    out = {k: np.zeros(n) for k in ("current_command", "current", "current_d", "position", "velocity",
                                     "voltage_q", "voltage_d")}
    prev = 0.0
    for k in range(n):
        s, o = act.state, act.outputs()
        pos = round(s.theta / q) * q
        vel = (pos - prev) / dt if k else 0.0
        prev = pos
        cmd = min(15.0, max(-15.0, kp * (ref[k] - pos) + kd * (dref[k] - vel)))
        out["current_command"][k] = cmd
        out["current"][k] = o["i_q_measured"] + 0.03 * rng.standard_normal()
        out["current_d"][k] = o["i_d_measured"] + 0.03 * rng.standard_normal()
        out["position"][k], out["velocity"][k] = pos, vel
        out["voltage_q"][k] = s.v_q + 0.02 * rng.standard_normal()
        out["voltage_d"][k] = s.v_d + 0.02 * rng.standard_normal()
        act.set_current_command(cmd)
        act.step(dt)
    return Signals(t, out, source="synthetic")


def test_gain_mismatch_is_named_written_back_and_simulated():
    nominal = ActuatorParams().replace(**{"gear.gear_ratio": 9.0, "motor.resistance_temperature_enabled": False,
                                          "load.load_torque": 1.0})     # a known load: amperes to mis-measure
    truth = nominal.replace(**{"drive.current_sensor_gain_a": 1.05, "drive.current_sensor_gain_b": 0.95})
    rep = diagnose(_recording(truth), nominal)
    d = rep.to_dict()
    assert [(f["effect"], "gain mismatch" in f["form"]) for f in d["findings"]] == [("electrical_angle_ripple", True)], \
        d["verdict"]
    dr = rep.updated_params.drive
    assert dr.current_sensor_gain_a - dr.current_sensor_gain_b == pytest.approx(0.10, abs=0.005)
    sim = d["findings"][0]["simulation"]    # the simulated speed, with and without the written gains
    assert sim["verdict"] == "confirmed" and sim["with"] < 0.2 * sim["without"]
    ho = d["compare"]["replay"]["holdout"]
    assert ho["after"]["current_rms"] < ho["before"]["current_rms"]
