"""Issue #7's symptoms, each reproduced as a recording from the concealed benchmark's independent truth generator
(benchmarks/concealed: its own three-phase plant, drive, sensors and logger) and shown fixed: the simulated
actuator with the fitted parameters must reproduce held-out data better, and nothing is named on a correct model.

1. false alarms on a correct model: a long thermal duty cycle logged at 100 Hz by an averaging logger (no false
   alarm even without the gate: a regression guard), and the same with a drive whose 20 Hz speed estimator makes
   the loop ring (the symptom as reported: equation error names four effects, the simulation shows none helps);
2. right finding, worse simulation: K_t off by sqrt(3/2) with Coulomb friction (friction was simulated 1/kappa too
   small), and copper R(T) left out (thermal network also accepted; held-out temperature worse);
3. unidentifiable findings: a short run with a few kelvin of temperature span;
4. wrong motor: see test_diagnosis_significance.py::test_a_recording_of_another_motor_says_the_base_model_is_far_off;
5. named but not simulated: every effect writes its simulator term (docs/physics.md table, test_model.py,
   test_voltage_limit.py).
Durations are cut to what still shows the symptom; the benchmark runs the full-length cases."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.concealed import cases as C  # noqa: E402
from benchmarks.concealed import truth as T  # noqa: E402
from concealed_helpers import diagnose_case  # noqa: E402

pytestmark = pytest.mark.skipif(T._c_library() is None, reason="no C compiler for the truth generator")


def _diagnose(case, tmp_path):
    rep = diagnose_case(case, tmp_path).to_dict()
    return rep, json.loads(json.dumps(rep, default=float))


def _replay(rep, key):
    ho = rep["compare"]["replay"]["holdout"]
    return ho["before"][key], ho["after"][key]


def _thermal(rep, ch):
    th = rep["compare"]["thermal"]
    return th["before"][ch]["holdout_rms"], th["after"][ch]["holdout_rms"]


@pytest.mark.slow
def test_symptom1_no_false_alarm_on_a_correct_model_logged_at_100hz(tmp_path):
    case = replace(C.get_case("null_thermal_100hz"), train=C.Excitation("gait", 180.0, 41, {"amplitude": 0.35}),
                   heldout=C.Excitation("gait", 90.0, 42, {"amplitude": 0.3, "freq": 0.9}))
    rep, _ = _diagnose(case, tmp_path)
    assert [f["effect"] for f in rep["findings"]] == []
    assert rep["nothing_missing"]


@pytest.mark.slow
def test_symptom1_no_false_alarm_when_the_simulation_cannot_follow_a_100hz_log(tmp_path):
    """The symptom itself: the same duty cycle with a drive whose speed estimator is tuned to 20 Hz (the joint loop
    rings against the current limit) logged at 100 Hz. The model is exactly right, yet equation error names
    R, magnetic saturation, a position-dependent load and J, and its own replay shows none helps (139 -> 127 rad/s
    velocity error on a recorded 10 rad/s RMS; temperature 0.7 -> 3 K). With the simulation as the gate nothing
    is named, and the verdict says why."""
    case = replace(C.get_case("null_thermal_100hz"), train=C.Excitation("gait", 60.0, 41, {"amplitude": 0.35}),
                   heldout=C.Excitation("gait", 30.0, 42, {"amplitude": 0.3, "freq": 0.9}),
                   environment={"pll_bandwidth": 20.0})
    eq_only = diagnose_case(case, tmp_path, simulation_gate=False)
    assert len(eq_only.findings) >= 2                  # the false alarms, as reported
    rep = diagnose_case(case, tmp_path).to_dict()
    # nothing named, and the verdict says the recording cannot decide (not "nothing missing": issue #24 symptom 10)
    assert rep["findings"] == [] and rep["verdict_kind"] == "not decidable" and rep["nothing_missing"] is False
    assert "does not reproduce" in rep["verdict"]
    assert {f["effect"] for f in eq_only.findings} <= {r["effect"] for r in rep["rejected"]}


@pytest.mark.slow
def test_symptom2_kt_frame_with_coulomb_simulates_better(tmp_path):
    rep, _ = _diagnose(C.get_case("kt_frame+coulomb"), tmp_path)
    by = {f["effect"]: f for f in rep["findings"]}
    assert set(by) == {"torque_constant_error", "coulomb_friction"}
    assert by["coulomb_friction"]["parameters"]["coulomb_friction"] == pytest.approx(C.F_C, rel=0.15)
    for f in by.values():
        assert f["simulation"]["verdict"] == "confirmed", f["simulation"]
    before, after = _replay(rep, "velocity_rms")
    assert after < 0.5 * before                      # was worse than nominal before the fix (3.5 -> 4.8 rad/s)


@pytest.mark.slow
def test_symptom2_copper_rt_without_a_spurious_thermal_network(tmp_path):
    case = replace(C.get_case("r_thermal"), train=C.Excitation("gait", 60.0, 11, {"amplitude": 0.35}),
                   heldout=C.Excitation("multisine", 30.0, 12))
    rep, _ = _diagnose(case, tmp_path)
    names = [f["effect"] for f in rep["findings"]]
    assert names == ["resistance_temperature"]
    rt = rep["findings"][0]["parameters"]["copper_temperature_coefficient"]
    assert rt == pytest.approx(0.00393, rel=0.15)
    for ch in ("winding_temperature", "housing_temperature"):
        before, after = _thermal(rep, ch)
        assert after <= before * 1.01, (ch, before, after)
    vb, va = _replay(rep, "velocity_rms")
    assert va <= vb * 1.01                           # R(T) no longer judged to worsen the simulated speed


@pytest.mark.slow
def test_symptom3_short_run_names_no_thermal_network(tmp_path):
    case = replace(C.get_case("null_short_thermal"), train=C.Excitation("gait", 45.0, 45, {"amplitude": 0.35}))
    rep, _ = _diagnose(case, tmp_path)
    assert "thermal_parameters" not in [f["effect"] for f in rep["findings"]]
    assert [f["effect"] for f in rep["findings"]] == []


@pytest.mark.slow
def test_symptom5_sensor_offset_ripple_is_written_back_and_simulated(tmp_path):
    """An order-p electrical-angle ripple from current-sensor offsets was 'named but not simulated': now the
    offsets are written to drive.current_sensor_offset_a/_b, the simulated controller acts on them and the
    replay compares the simulated SENSOR current with the recorded one."""
    case = C.get_case("electrical_ripple")
    rep = diagnose_case(case, tmp_path)
    doc = rep.to_dict()
    assert [f["effect"] for f in doc["findings"]] == ["electrical_angle_ripple"]
    assert doc["findings"][0]["simulation"]["verdict"] == "confirmed"
    assert "electrical_angle_ripple" not in (doc.get("not_simulated") or [])
    off_a, off_b = case.plant["sensor:offset_a"], case.plant["sensor:offset_b"]
    assert rep.updated_params.drive.current_sensor_offset_a == pytest.approx(off_a, abs=0.1 * abs(off_a))
    assert rep.updated_params.drive.current_sensor_offset_b == pytest.approx(off_b, abs=0.1 * abs(off_b))
    before, after = _replay(doc, "velocity_rms")
    assert after < 0.5 * before
    cb, ca = _replay(doc, "current_rms")
    assert ca <= cb * 1.01
