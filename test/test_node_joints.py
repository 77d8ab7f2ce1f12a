"""Several joints in one actuator_node: each joint is its own actuator (preset, overrides), follows its own
command, a bad command for one joint leaves the others running, ros2_control's topic_based hardware interface
can drive it (sensor_msgs/JointState commands by name), and one recording diagnoses per joint."""

from __future__ import annotations

import json
import math

import pytest

pytest.importorskip("rclpy")

from conftest import wait_for  # noqa: E402
from node_helpers import Probe, make_node, wait_heard  # noqa: E402

from bldc_actuator.params import load_preset  # noqa: E402

T = 10.0
JOINTS = ["hip", "knee", "ankle"]
PRESETS = {"hip": "ak80_9", "knee": "odrive_d5065", "ankle": "tmotor_u8"}


def _robot(ros_context, ros_executor, **extra):
    params = {"joints": JOINTS, "node.lock_step": True, "node.watchdog_timeout": 0.0,
              "joint.ankle.drive.bus_voltage": 36.0, **{f"joint.{j}.preset": p for j, p in PRESETS.items()}}
    params.update(extra)
    return make_node(ros_context, ros_executor, params=params)


def _send(probe, node, topic, msg, periods_before):
    probe.publish(topic, msg)
    assert wait_for(lambda: node.periods > periods_before, T), f"no period after {topic}"


def test_three_joints_each_follow_their_own_command(ros_context, ros_executor):
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    node = _robot(ros_context, ros_executor)
    assert [j.name for j in node.joints] == JOINTS
    for j in node.joints:   # each joint is its own motor (its preset), the override applied to one only
        want = load_preset(PRESETS[j.name])
        assert node.plant.params(j.name).motor.torque_constant_q == want.motor.torque_constant_q
        assert node.plant.params(j.name).gear.gear_ratio == want.gear.gear_ratio
    assert node.plant.params("ankle").drive.bus_voltage == 36.0 != load_preset("tmotor_u8").drive.bus_voltage
    probe = Probe(ros_context, ros_executor).listen("/joint_states", JointState)
    probe.connect("/bldc_actuator/commands", Float64MultiArray)
    wait_heard(node.pub_joint)
    tau = [0.8, 0.05, -0.4]                                  # effort [N*m] at each output, joints order
    for _ in range(50):
        _send(probe, node, "/bldc_actuator/commands", Float64MultiArray(data=tau), node.periods)
    for j, t in zip(node.joints, tau):
        p = node.plant.params(j.name)
        assert j.kind == "torque" and j.value == t
        assert math.isclose(node.plant.actuator(j.name).state.i_q_ref, t / (p.motor.torque_constant_q * p.gear.gear_ratio),
                            rel_tol=1e-12)
    assert wait_for(lambda: len(probe.get("/joint_states")) >= 40, T)
    last = probe.get("/joint_states")[-1]
    assert list(last.name) == JOINTS
    # effort = K_t i_q N follows each joint's own command (current loop settled after 50 ms)
    for name, t, e in zip(last.name, tau, last.effort):
        assert math.isclose(e, t, rel_tol=0.02, abs_tol=1e-3), name
    # and the three rotors move as three different motors: signs follow the commands
    assert last.velocity[0] > 0 and last.velocity[2] < 0


def test_a_bad_command_for_one_joint_leaves_the_others_running(ros_context, ros_executor):
    from std_msgs.msg import Float64, Float64MultiArray

    node = _robot(ros_context, ros_executor)
    probe = Probe(ros_context, ros_executor)
    probe.connect("/bldc_actuator/commands", Float64MultiArray)
    probe.connect("/bldc_actuator/knee/torque_command", Float64)
    _send(probe, node, "/bldc_actuator/commands", Float64MultiArray(data=[0.5, math.nan, -0.2]), node.periods)
    hip, knee, ankle = node.joints
    assert hip.value == 0.5 and ankle.value == -0.2     # applied
    assert knee.commands_rejected == 1 and hip.commands_rejected == 0
    assert "knee" in knee.last_rejection and "finite" in knee.last_rejection
    # per-joint topic: an absurd torque for the knee only; the knee keeps its last good command
    probe.publish("/bldc_actuator/knee/torque_command", Float64(data=1e6))
    assert wait_for(lambda: knee.commands_rejected == 2, T)
    probe.publish("/bldc_actuator/knee/torque_command", Float64(data=0.04))
    assert wait_for(lambda: knee.value == 0.04, T)
    before = node.periods
    for _ in range(20):
        _send(probe, node, "/bldc_actuator/commands", Float64MultiArray(data=[0.5, 0.04, -0.2]), node.periods)
    assert node.periods == before + 20
    status = {s.hardware_id: s for s in node.diagnostic_statuses()}
    assert set(status) == set(JOINTS)
    assert node.plant.actuator("hip").state.omega > 0 and node.plant.actuator("ankle").state.omega < 0
    # wrong length: rejected for all, still one lock-step period (a waiting controller never stalls)
    n = node.periods
    _send(probe, node, "/bldc_actuator/commands", Float64MultiArray(data=[0.1]), n)
    assert "expected 3 element(s)" in node.last_rejection


def test_ros2_control_topic_based_interface_contract(ros_context, ros_executor):
    """What ros2_control's joint_state_topic_hardware_interface sends: sensor_msgs/JointState on
    /robot_joint_command with every joint name and ``effort`` for the effort command interfaces, in name
    order (not necessarily the node's order); it reads /robot_joint_states."""
    from sensor_msgs.msg import JointState

    node = _robot(ros_context, ros_executor, **{"node.joint_commands_topic": "/robot_joint_command",
                                                 "node.joint_states_topic": "/robot_joint_states"})
    assert node.pub_joint.topic_name == "/robot_joint_states"
    probe = Probe(ros_context, ros_executor).listen("/robot_joint_states", JointState)
    probe.connect("/robot_joint_command", JointState)
    cmd = JointState(name=["ankle", "hip", "knee"], effort=[-0.3, 0.6, 0.02])
    for _ in range(30):
        _send(probe, node, "/robot_joint_command", cmd, node.periods)
    by = {j.name: j for j in node.joints}
    assert by["ankle"].value == -0.3 and by["hip"].value == 0.6 and by["knee"].value == 0.02
    assert wait_for(lambda: len(probe.get("/robot_joint_states")) > 10, T)
    # position / velocity command interfaces: a clear rejection, nothing applied
    _send(probe, node, "/robot_joint_command", JointState(name=["hip"], position=[1.0]), node.periods)
    assert "position/velocity commands are not supported" in node.last_rejection
    assert by["hip"].value == 0.6
    # position AND effort (a joint with both command interfaces): rejected as a whole, with the reason; the
    # efforts it carries are not applied either
    i_q_ref = {j: node.plant.outputs(j)["i_q_ref"] for j in JOINTS}
    _send(probe, node, "/robot_joint_command",
          JointState(name=["hip", "knee"], position=[1.0, 0.0], effort=[0.1, 0.01]), node.periods)
    assert "position/velocity commands are not supported" in node.last_rejection
    assert "position" in node.last_rejection.split("(this message carries", 1)[1]
    assert by["hip"].value == 0.6 and by["knee"].value == 0.02
    assert all(node.plant.outputs(j)["i_q_ref"] == i_q_ref[j] for j in JOINTS)
    assert (by["hip"].commands_rejected, by["knee"].commands_rejected, by["ankle"].commands_rejected) == (2, 1, 0)


def test_an_unknown_joint_name_is_rejected_for_that_name_only(ros_context, ros_executor):
    """A joint command naming a joint this node does not have: that name is rejected (logged, counted at the
    node), the named joints that exist are applied, and no joint's diagnostics turn WARN."""
    from sensor_msgs.msg import JointState

    node = _robot(ros_context, ros_executor, **{"node.joint_commands_topic": "/robot_joint_command"})
    probe = Probe(ros_context, ros_executor)
    probe.connect("/robot_joint_command", JointState)
    node.diagnostic_statuses()                                   # start a fresh window
    _send(probe, node, "/robot_joint_command",
          JointState(name=["hip", "elbow", "knee"], effort=[0.2, 5.0, 0.01]), node.periods)
    by = {j.name: j for j in node.joints}
    assert by["hip"].value == 0.2 and by["knee"].value == 0.01            # the known names applied
    assert node.commands_rejected == 1 and "unknown joint 'elbow'" in node.last_rejection
    assert all(j.commands_rejected == 0 for j in node.joints)
    levels = {s.hardware_id: s.level for s in node.diagnostic_statuses()}
    assert levels == {j: b"\x00" for j in JOINTS}, levels


def test_one_recording_diagnoses_per_joint(ros_context, ros_executor, tmp_path):
    from std_msgs.msg import Float64MultiArray

    from bldc_actuator.diagnosis.io import loaders
    from bldc_actuator.diagnosis.cli import register  # noqa: F401 - the CLI that takes --joint
    from bldc_actuator.recording import read_recording

    path = tmp_path / "robot.mcap"
    node = _robot(ros_context, ros_executor, **{"node.record": str(path)})
    for k in range(400):   # a different torque pattern per joint
        t = k * 1e-3
        msg = Float64MultiArray(data=[0.6 * math.sin(2 * math.pi * 3 * t), 0.05 * math.sin(2 * math.pi * 5 * t),
                                      0.3 * math.cos(2 * math.pi * 2 * t)])
        node._on_commands(msg)  # noqa: SLF001 - lock-step: one period per command, same path as a message
    node.close()
    rec = read_recording(path)
    assert rec.finalized
    for j in JOINTS:
        assert len(rec.topics[f"/bldc_actuator/{j}/q_axis_state"]) == node.periods + 1
    with pytest.raises(ValueError, match="several joints.*--joint"):
        loaders.load(path)
    for j in node.joints:
        sig = loaders.load(path, joint=j.name)
        p = sig.meta["params_from_recording"]
        assert p.motor.torque_constant_q == node.plant.params(j.name).motor.torque_constant_q
        assert sig.meta["voltage_timing"].convention == "applied"     # the node declares its held voltage
        # ... and the motor values its drive's current loop is tuned with (the joint's own motor)
        from bldc_actuator import drive_tuning
        from bldc_actuator.params import CONTROLLER_FIELDS, controller_motor
        assert drive_tuning.from_metadata(sig.meta["declared"], "test") == dict(
            zip(CONTROLLER_FIELDS, controller_motor(node.plant.params(j.name))))
        assert p.drive.bus_voltage == node.plant.params(j.name).drive.bus_voltage
        # the joint's own current and motor-side angle (output angle x ITS gear ratio)
        assert abs(sig.channels["current"][-1] - node.plant.actuator(j.name).state.i_q) < 1e-9
        assert abs(sig.channels["position"][-1] - node.plant.actuator(j.name).state.theta) < 1e-6 * max(1.0, abs(node.plant.actuator(j.name).state.theta))
    # the diagnose command runs on one joint with the parameters stored for it
    from bldc_actuator import cli

    out = tmp_path / "knee.json"
    assert cli.main(["diagnose", str(path), "--joint", "knee", "--params", "recording", "--json", str(out),
                     "--quiet"]) == 0
    report = json.loads(out.read_text())
    # the knee's own stored parameters are the truth of that joint: nothing is missing
    # (a short run: "not decidable: held-out too short" or "nothing missing"; never a finding)
    assert not report["findings"] and report["verdict_kind"] in ("nothing missing", "not decidable")
    assert report["nothing_missing"] is (report["verdict_kind"] == "nothing missing")
