"""Issue #14, symptom 4 (real formats without surgery), on generated data with known truth: a millisecond /
microsecond clock, a current held at the drive's limit, a multi-joint CSV with a joint-torque sensor column
(through a profile and through --joint with --map), a 0.27 V "supply voltage", a measured/commanded current
ratio that is a frame factor, and cogging from a dyno run that covers less than one revolution."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bldc_actuator.diagnosis.io import cleaning, loaders
from bldc_actuator.diagnosis import torque_balance as tb
from bldc_actuator.diagnosis.io.mapping import Mapping
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.params import ActuatorParams
from issue14_generators import NOMINAL, dyno_run, limited_run, short_span_w, write_csv


def _motion(n=4000, rate=1000.0, seed=3):
    """Rotor angle and speed of a smooth motion both ways (rad, rad/s) at ``rate``."""
    t = np.arange(n) / rate
    w = 5 * np.sin(2 * np.pi * 0.7 * t) + 2 * np.sin(2 * np.pi * 2.1 * t)
    th = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) / rate)])
    rng = np.random.default_rng(seed)
    return t, th, w + 0.01 * rng.standard_normal(n), 0.5 * w + 0.02 * rng.standard_normal(n)


@pytest.mark.parametrize("scale,name", [(1e3, "milliseconds"), (1e6, "microseconds")])
def test_ms_and_us_clocks_are_recognised_and_said(tmp_path, scale, name):
    t, th, w, i = _motion()
    path = tmp_path / "log.csv"
    write_csv(path, {"time": np.round(t * scale), "position": th, "velocity": w, "current": i})
    sig = cleaning.clean(loaders.load(path, params=NOMINAL), params=NOMINAL)
    assert sig.meta["rate_hz"] == pytest.approx(1000.0, rel=1e-6)       # read as seconds: 1 Hz / 0.001 Hz
    assert sig.time[-1] == pytest.approx(t[-1], rel=1e-6)
    issue = next(i for i in sig.issues if i.channel == "time" and i.kind == "unit_suspect")
    assert name in issue.detail and "rescaled to seconds" in issue.action
    assert not any(i.kind == "gap" for i in sig.issues)


def test_a_seconds_clock_is_left_alone(tmp_path):
    t, th, w, i = _motion()
    path = tmp_path / "log.csv"
    write_csv(path, {"time": t, "position": th, "velocity": w, "current": i})
    sig = cleaning.clean(loaders.load(path, params=NOMINAL), params=NOMINAL)
    assert not any(i.channel == "time" and i.kind == "unit_suspect" for i in sig.issues)
    assert sig.meta["rate_hz"] == pytest.approx(1000.0, rel=1e-6)


def test_current_at_the_drive_limit_is_flagged_with_its_level_and_share():
    sig = cleaning.clean(limited_run(NOMINAL, duration=4.0), params=NOMINAL)
    rec = sig.meta["clipped"]["current"]
    assert rec["levels"] == [-2.0] and rec["fraction"] > 0.95
    assert any(i.kind == "clipped" and i.channel == "current" for i in sig.issues)


def test_supply_voltage_of_a_fraction_of_a_volt_is_flagged_and_masked():
    t, th, w, i = _motion()
    sig = cleaning.clean(Signals(t, {"position": th, "velocity": w, "current": i,
                                     "bus_voltage": 0.27 + 0.001 * np.sin(t)}, "x"), params=NOMINAL)
    issue = next(x for x in sig.issues if x.channel == "bus_voltage")
    assert issue.kind == "unit_suspect" and "0.27" in issue.detail and "masked" in issue.action
    assert not np.isfinite(sig.channels["bus_voltage"]).any()
    ok = cleaning.clean(Signals(t, {"position": th, "velocity": w, "current": i, "bus_voltage": 24.0 + 0 * t}, "x"),
                        params=NOMINAL)
    assert not any(x.channel == "bus_voltage" and x.kind == "unit_suspect" for x in ok.issues)


def test_measured_to_commanded_current_ratio_is_matched_against_the_frame_factors():
    t, th, w, i = _motion()
    cmd = i / math.sqrt(2 / 3)
    sig = cleaning.clean(Signals(t, {"position": th, "velocity": w, "current": i, "current_command": cmd}, "x"),
                         params=NOMINAL)
    issue = next(x for x in sig.issues if x.channel == "current" and "its command" in x.detail)
    assert "sqrt(2/3)" in issue.detail
    same = cleaning.clean(Signals(t, {"position": th, "velocity": w, "current": i, "current_command": i * 1.0}, "x"),
                          params=NOMINAL)
    assert not any("its command" in x.detail for x in same.issues)


# -- a multi-joint CSV with a joint-torque sensor column -------------------------------------------

def _wide(tmp_path, sensor_name="Torque"):
    t, th, w, i = _motion(n=2000)
    cols = {"time": t}
    for j in (1, 2):
        cols[f"Position{j}"] = th / 9 * j
        cols[f"Velocity{j}"] = w / 9 * j
        cols[f"Cur{j}"] = i * j
        cols[f"{sensor_name}{j}"] = 0.3 * j + 0.01 * t
    path = tmp_path / "arm.csv"
    write_csv(path, cols)
    return path, cols


def test_torque_sensor_column_through_a_profile(tmp_path):
    path, cols = _wide(tmp_path)
    default = loaders.load(path, params=NOMINAL, joint="joint2")
    assert default.meta["profile"] == "wide_joints" and "torque" not in default.channels   # the drive's estimate
    sig = loaders.load(path, params=NOMINAL, joint="joint2", profile="wide_joints_torque_sensor")
    np.testing.assert_allclose(sig.channels["torque"], cols["Torque2"])
    np.testing.assert_allclose(sig.channels["position"], cols["Position2"] * 9.0, rtol=1e-6)   # output side x N


def test_joint_torque_sensor_column_is_read_by_the_default_profile(tmp_path):
    path, cols = _wide(tmp_path, sensor_name="JointTorque")
    sig = loaders.load(path, params=NOMINAL, joint="joint1")
    np.testing.assert_allclose(sig.channels["torque"], cols["JointTorque1"])


@pytest.mark.parametrize("expr", ["Torque2", "Torque{j}"])
def test_joint_with_map_over_the_profile(tmp_path, expr):
    path, cols = _wide(tmp_path)
    sig = loaders.load(path, params=NOMINAL, joint="joint2", mapping=Mapping.parse([f"torque={expr}*2"]))
    np.testing.assert_allclose(sig.channels["torque"], 2 * cols["Torque2"])
    np.testing.assert_allclose(sig.channels["current"], cols["Cur2"])                   # the rest from the profile
    np.testing.assert_allclose(sig.channels["position"], cols["Position2"] * 9.0, rtol=1e-6)
    with pytest.raises(loaders.LoadError, match="no such column"):
        loaders.load(path, params=NOMINAL, joint="joint2", mapping=Mapping.parse(["torque=Nope2"]))


# -- cogging from less than one revolution -----------------------------------------------------------

@pytest.fixture(scope="module")
def short_span():
    """Cogging order 18 (0.0135 N*m) with compensation off, and a residual 0.005 N*m with it on, each over
    0.75 revolution of a dyno run in one direction (speed loop 0.05 N*m/(rad/s), 5 N*m/rad: a stiff dyno)."""
    out = {}
    for label, amp in (("off", 0.0135), ("on", 0.005)):
        p = ActuatorParams().replace(**{"effects.cogging_order": 18, "effects.cogging_cos": (amp,),
                                        "effects.cogging_sin": (0.0,), "effects.coulomb_friction": 0.01,
                                        "gear.gear_ratio": 1.0, "motor.rotor_inertia": 1e-4})
        t, w, tau = dyno_run(p, duration=12.0, w_ref=short_span_w(0.75, 12.0), noise=0.001, kp=0.05, ki=5.0)
        sig = cleaning.clean(Signals(t, {"torque": tau, "velocity": w}, "dyno", meta={"gear_ratio": 1.0}), params=p)
        out[label] = tb.diagnose(sig, ActuatorParams().replace(**{"gear.gear_ratio": 1.0,
                                                                 "motor.rotor_inertia": 1e-4}))
    return out


def test_short_span_cogging_peak_is_reported_with_its_order_uncertainty(short_span):
    off, on = short_span["off"], short_span["on"]
    for res in (off, on):
        s = res.spectrum
        assert s["revolutions"] == pytest.approx(0.75, rel=0.05)
        assert abs(s["order"] - 18) <= max(s["order_sd"], 0.5)
        assert 0.3 < s["order_sd"] < 1.5               # ~ 1/(revolutions covered), not an integer claim
        assert 18 in s["integer_orders"]
        assert not any(x["effect"] == "cogging_torque" for x in res.not_checkable)
    assert off.spectrum["amplitude"] == pytest.approx(0.0135, rel=0.25)
    assert on.spectrum["amplitude"] == pytest.approx(0.005, rel=0.35)
    cog = next(f for f in off.findings if f.effect == "cogging_torque")
    assert cog.parameters["cogging_order"] == 18 and cog.uncertainty["cogging_order"] == off.spectrum["order_sd"]
