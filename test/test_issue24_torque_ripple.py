"""Issue #24, symptom 9: an angle-locked ripple in a measured torque is decidable without the motor's own torque.

A torque-sensor dyno log of a POWERED motor turning slowly (no motor current logged): the torque balance explains
little of the torque (the motor's own torque is not logged), and the diagnosis said only "not decidable". The
ripple locked to the angle (order 18 per revolution, 0.0135 N*m with cogging compensation off, ~0.005 on) is
measurable all the same: reported with its order and amplitude (and their uncertainties), and for two files the
off/on contrast. Generated data (no hidden data); the real AK80-9 pair is used only where ../shared has it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bldc_actuator.diagnosis import torque_balance as tb
from bldc_actuator.diagnosis.io.cleaning import clean
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.params import ActuatorParams

ORDER, AMP, PHASE = 18, 0.0135, 0.8


def _powered_dyno_log(amp: float, *, seed: int = 1, duration: float = 120.0, rate: float = 100.0,
                      noise: float = 0.02):
    """A powered motor turned slowly (~12 motor revolutions in ``duration``, speed wandering 0.3-0.9 rad/s); the
    sensor reads the motor's own (unlogged) torque, a slow random wander of ~0.05 N*m, plus an angle-locked ripple
    ``amp`` cos(18 theta + phase) and white noise ``noise`` N*m. Speed logged (motor side), no angle, no current."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate)
    w = 0.6 + 0.3 * np.sin(2 * np.pi * t / 37.0) + 0.01 * rng.standard_normal(len(t))
    th = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
    own = np.convolve(rng.standard_normal(len(t)), np.ones(300) / 300, mode="same") * 0.05 / 0.058
    tau = own + amp * np.cos(ORDER * th + PHASE) + noise * rng.standard_normal(len(t))
    sig = clean(Signals(t, {"torque": tau, "velocity": w}, "dyno", meta={"gear_ratio": 1.0}),
                params=ActuatorParams())
    return sig


@pytest.fixture(scope="module")
def logs():
    return {"off": _powered_dyno_log(AMP, seed=1), "on": _powered_dyno_log(0.005, seed=2),
            "none": _powered_dyno_log(0.0, seed=3)}


def test_the_ripple_is_reported_with_order_and_amplitude_though_the_balance_explains_little(logs):
    res = tb.diagnose(logs["off"], ActuatorParams())
    assert res.r2 < 0.5                                       # the case: the motor's own torque is not logged
    rip = res.ripple
    assert rip is not None and rip["angle_locked"]
    assert round(rip["order"]) == ORDER
    assert abs(rip["order"] - ORDER) <= 3 * rip["order_sd"] + 1e-3
    assert abs(rip["amplitude"] - AMP) <= 3 * rip["amplitude_sd"]
    assert 0 < rip["amplitude_sd"] < 0.3 * AMP
    assert rip["p_value"] < 1e-3
    found = [f for f in res.findings if f.effect == "angle_locked_ripple"]
    assert found and found[0].parameters["order"] == pytest.approx(rip["order"])


def test_the_report_says_it_instead_of_not_decidable(logs):
    from bldc_actuator.diagnosis.pipeline import diagnose

    rep = diagnose(logs["off"], ActuatorParams())
    assert rep.method.startswith("torque balance")
    assert not rep.verdict.startswith("not decidable")
    assert "angle_locked_ripple" in rep.verdict
    f = [x for x in rep.findings if x["effect"] == "angle_locked_ripple"][0]
    assert any("order 18" in e for e in f["evidence"])


def test_no_ripple_no_finding(logs):
    res = tb.diagnose(logs["none"], ActuatorParams())
    assert not [f for f in res.findings if f.effect == "angle_locked_ripple"]
    assert res.ripple is None or not res.ripple["angle_locked"]


def test_the_off_on_contrast(logs):
    c = tb.ripple_contrast({"off": logs["off"], "on": logs["on"]}, ActuatorParams())
    assert round(c.order) == ORDER
    off, on = c.amplitude["off"], c.amplitude["on"]
    assert abs(off - AMP) <= 3 * c.amplitude_sd["off"] and abs(on - 0.005) <= 3 * c.amplitude_sd["on"]
    assert c.difference == pytest.approx(off - on)
    assert c.difference > 3 * c.difference_sd                   # the compensation's effect is resolved
    assert "order 18" in c.message and "off" in c.message and "on" in c.message


AK = Path(__file__).resolve().parents[2] / "shared" / "data" / "ak80-9" / "no_torque_tests"


@pytest.mark.skipif(not (AK / "no_comp.csv").exists(), reason="needs ../shared/data/ak80-9 (GPL data, not in the repo)")
def test_the_ak80_9_pair_runs():
    from bldc_actuator.diagnosis.io import loaders
    from bldc_actuator.params import load_preset

    p = load_preset("ak80_9")
    sigs = {}
    for label, name in (("off", "no_comp.csv"), ("on", "comp.csv")):
        s = clean(loaders.load(AK / name), params=p)
        # the dyno view: torque and motion only (the current is the drive's, near zero here)
        sigs[label] = Signals(s.time, {k: v for k, v in s.channels.items() if k in ("torque", "velocity")},
                              s.source, meta=s.meta, segments=s.segments)
    c = tb.ripple_contrast(sigs, p)
    assert math.isfinite(c.amplitude["off"]) and math.isfinite(c.amplitude["on"])
