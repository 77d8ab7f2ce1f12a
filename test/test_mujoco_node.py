"""actuator_node driving a robot model (issue #17): ``-p mujoco.model:=robot.xml -p joint.<name>.preset:=...``
puts the actuators under MuJoCo bodies; ros2_control's topic contract (JointState effort commands by name)
moves the MJCF joint, the published joint state is the body's, and the recording holds the body's state."""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy")

from conftest import wait_for  # noqa: E402
from node_helpers import Probe, make_node  # noqa: E402

from bldc_actuator.params import load_preset  # noqa: E402
from bldc_actuator.recording import read_recording  # noqa: E402

T = 10.0
FLYWHEEL = """<mujoco><option timestep="0.001" gravity="0 0 0"/><worldbody><body name="disc">
<joint name="wheel" type="hinge" axis="0 0 1"/><inertial pos="0 0 0" mass="1" diaginertia="0.002 0.002 0.002"/>
</body></worldbody></mujoco>"""


def test_a_ros2_control_effort_command_moves_the_mjcf_joint(ros_context, ros_executor, tmp_path):
    """Lock-step, 1 kHz: 60 JointState effort commands of 2 N·m on /robot_joint_command turn the flywheel by
    ½ (τ - τ_c N) t² / (I + J N²) (the rotor inertia through the gear as the joint's armature), to 3 %."""
    from sensor_msgs.msg import JointState

    from bldc_actuator.node import layout_labels

    model = tmp_path / "robot.xml"
    model.write_text(FLYWHEEL)
    node = make_node(ros_context, ros_executor, params={
        "mujoco.model": str(model), "joint.wheel.preset": "ak80_9", "node.lock_step": True,
        "node.watchdog_timeout": 0.0, "node.joint_commands_topic": "/robot_joint_command",
        "node.joint_states_topic": "/robot_joint_states", "node.record": str(tmp_path / "run.mcap")})
    assert [j.name for j in node.joints] == ["wheel"]
    assert node.plant.model.dof_armature[0] > 0.0                     # the body carries the rotor
    probe = Probe(ros_context, ros_executor).listen("/robot_joint_states", JointState)
    probe.connect("/robot_joint_command", JointState)
    n = 60
    for k in range(n):
        before = node.periods
        probe.publish("/robot_joint_command", JointState(name=["wheel"], effort=[2.0]))
        assert wait_for(lambda: node.periods > before, T), "no period after the command"
    t = node.plant.t
    assert t == pytest.approx(n * 1e-3)
    p = load_preset("ak80_9")
    N = p.gear.gear_ratio
    expected = 0.5 * (2.0 - p.effects.coulomb_friction * N) / (0.002 + p.motor.rotor_inertia * N * N) * t * t
    q_body = float(node.plant.data.qpos[0])
    assert q_body == pytest.approx(expected, rel=0.03)
    assert wait_for(lambda: any(m.position[0] == pytest.approx(q_body) for m in probe.get("/robot_joint_states")),
                    T), "the published joint state is not the body's"
    # the recording holds the run, the body's whole state included
    node.close()
    rec = read_recording(tmp_path / "run.mcap")
    assert rec.finalized and not rec.issues, rec.issues
    body = rec.topics["/bldc_actuator/mujoco/body_state"]
    assert len(body) == n + 1                                        # every period and the initial state
    labels = layout_labels(body[-1][1])
    assert labels == ["qpos.wheel", "qvel.wheel"]
    assert body[-1][1].data[0] == pytest.approx(q_body) and body[-1][0] == node.plant.t_ns
    assert rec.topics["/robot_joint_states"][-1][1].position[0] == pytest.approx(q_body)


def test_a_joint_the_model_does_not_have_is_a_parameter_error(ros_context, ros_executor, tmp_path):
    from bldc_actuator.params import ParameterError

    model = tmp_path / "robot.xml"
    model.write_text(FLYWHEEL)
    with pytest.raises(ParameterError, match="mujoco.model.*no joint named 'knee'"):
        make_node(ros_context, ros_executor, params={"mujoco.model": str(model), "joint.knee.preset": "ak80_9"})
    with pytest.raises(ParameterError, match="name the robot's joints"):
        make_node(ros_context, ros_executor, params={"mujoco.model": str(model)}, name="second")
