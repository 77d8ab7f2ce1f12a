"""The robot route (issue #26): a body's mass error on a 3-link arm in CoupledSim is named as a mass, jointly over
every joint, not as a per-joint gravity load; a null arm names nothing; the body's torque is MuJoCo's inverse
dynamics (checked against the analytic gravity torque of the arm)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import robot_cases as rc  # noqa: E402

from bldc_actuator.diagnosis.body.inverse import BodyModel  # noqa: E402
from bldc_actuator.diagnosis.body.joints import parse_joint_map  # noqa: E402
from bldc_actuator.diagnosis.body.robot import diagnose_robot_file  # noqa: E402

SECONDS = 6.0


def test_the_body_torque_is_the_arms_gravity_torque_at_rest():
    """Held still, the shoulder pitch carries every outboard mass at its lever arm (analytic, g = 9.81)."""
    body = BodyModel(rc.MJCF, list(rc.JOINT_MAP), rc.JOINT_MAP)
    q2, q3 = 0.4, -0.7
    q = np.array([[0.3, q2, q3]])
    z = np.zeros_like(q)
    tau = body.torques(q, z, z)[0]
    g = 9.81
    # upper arm 1.0 kg at 0.15 m; forearm 0.6 kg at 0.3 m + 0.125 m; payload 0.5 kg at 0.3 m + 0.25 m (x-z plane)
    elbow = g * (0.6 * 0.125 + 0.5 * 0.25) * math.cos(q2 + q3)
    shoulder = g * (1.0 * 0.15 + (0.6 + 0.5) * 0.3) * math.cos(q2) + elbow
    assert tau[0] == pytest.approx(0.0, abs=1e-9)
    assert -tau[1] == pytest.approx(shoulder, rel=1e-9)
    assert -tau[2] == pytest.approx(elbow, rel=1e-9)
    # the payload's column: the same lever arms per kg, exact (inverse dynamics is linear in a body's inertia)
    col = body.mass_column(body.body("payload"), q, z, z)[0]
    assert -col[1] == pytest.approx(g * (0.3 * math.cos(q2) + 0.25 * math.cos(q2 + q3)), rel=1e-9)


def test_a_joint_map_names_the_bad_entry():
    assert parse_joint_map("joint1=shoulder_yaw, joint2=elbow") == {"joint1": "shoulder_yaw", "joint2": "elbow"}
    with pytest.raises(ValueError, match="RECORDING_JOINT=MJCF_JOINT"):
        parse_joint_map("joint1")
    with pytest.raises(ValueError, match="no joint 'knee'.*its joints: shoulder_yaw"):
        BodyModel(rc.MJCF, ["knee"])


@pytest.fixture(scope="module")
def arm_logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("arm")
    return {case: rc.simulate(case, SECONDS).write_csv(d / f"{case}.csv") for case in ("null", "payload", "all")}


def test_a_payload_error_is_named_as_a_mass_within_5_percent_not_as_per_joint_gravity_loads(arm_logs):
    report = diagnose_robot_file(arm_logs["payload"], rc._nominal(), rc.MJCF, joint_map=rc.JOINT_MAP,
                                 joints_diagnosed=False)
    (found,) = report.body.findings
    truth = rc.truth("payload").body_mass["payload"]
    assert found.body == "payload"
    assert found.delta_mass == pytest.approx(truth, rel=0.05)
    assert found.delta_mass_sd < 0.1 * truth
    assert found.held_out["change"] < -0.1                     # the held-out equation error falls
    # one mass explains every joint better than a gravity load per joint (2 parameters each) would
    assert found.per_joint_load["delta_bic"] < found.delta_bic
    assert found.per_joint_load["change"] > found.held_out["change"]


def test_a_null_arm_names_no_body(arm_logs):
    report = diagnose_robot_file(arm_logs["null"], rc._nominal(), rc.MJCF, joint_map=rc.JOINT_MAP,
                                 joints_diagnosed=False)
    assert report.body.findings == []


def test_the_payload_is_read_apart_from_a_joints_torque_constant_and_friction(arm_logs):
    """With the elbow's K_t 12 % low and a different Coulomb friction per joint the payload is still read within
    5 %: the elbow's K_t competes with the bodies in the same selection, so it does not lend its torque to a mass."""
    report = diagnose_robot_file(arm_logs["all"], rc._nominal(), rc.MJCF, joint_map=rc.JOINT_MAP,
                                 joints_diagnosed=False)
    assert [f.body for f in report.body.findings] == ["payload"]
    assert report.body.findings[0].delta_mass == pytest.approx(rc.truth("all").body_mass["payload"], rel=0.05)


def test_the_command_line_names_a_bad_joint_map_entry(arm_logs, capsys):
    from bldc_actuator.cli import main

    rc_ = main(["diagnose", str(arm_logs["null"]), "--params", "ak80_9", "--mujoco-model", str(rc.MJCF),
                "--joint-map", "joint1=shoulder_yaw,joint9=elbow", "--quiet"])
    assert rc_ == 2
    assert "--joint-map: no joint 'joint9' in the recording (it holds: joint1, joint2, joint3)" in capsys.readouterr().err


def test_the_command_line_writes_one_report_for_the_robot(arm_logs, tmp_path, capsys):
    """``diagnose --mujoco-model``: the body's finding and a section per joint, in the JSON and the markdown."""
    import json

    from bldc_actuator.cli import main

    out = tmp_path / "robot.json"
    assert main(["diagnose", str(arm_logs["payload"]), "--params", "ak80_9", "--mujoco-model", str(rc.MJCF),
                 "--joint-map", ",".join(f"{a}={b}" for a, b in rc.JOINT_MAP.items()), "--json", str(out),
                 "--report", str(tmp_path / "rep"), "--updated-params", str(tmp_path / "fitted.yaml"), "--no-plots",
                 "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("body: body 'payload' is 0.2")
    d = json.loads(out.read_text())
    assert [f["body"] for f in d["body"]["findings"]] == ["payload"]
    assert set(d["joints"]) == set(rc.JOINT_MAP) and d["joint_map"]["joints"] == rc.JOINT_MAP
    for j in rc.JOINT_MAP:       # the per-joint diagnosis knows the arm's gravity: no per-joint load named
        assert not any(f["effect"] == "position_dependent_load" for f in d["joints"][j]["findings"])
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "## The body" in md and all(f"### {j}" in md for j in rc.JOINT_MAP)
    assert (tmp_path / "rep" / "joint1" / "report.md").is_file()
    # each joint's parameter file is the actuator's: the body's inertia, moved onto the rotor for the joint's own
    # equations and replays, is not written into it
    from bldc_actuator.params import load_preset

    for j in rc.JOINT_MAP:
        fitted = load_preset(tmp_path / f"fitted.{j}.yaml")
        assert fitted.motor.rotor_inertia == pytest.approx(rc._nominal().motor.rotor_inertia, rel=1e-9)
