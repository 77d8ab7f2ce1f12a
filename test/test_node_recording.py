"""actuator_node recording: the MCAP holds the commands received, everything published and the parameters
(updated on runtime changes), decodes to the values that went over the wire, and re-simulates the run."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("mcap")

from conftest import wait_for  # noqa: E402
from node_helpers import Probe, make_node, wait_heard  # noqa: E402

from bldc_actuator.node import Q_AXIS_FIELDS  # noqa: E402
from bldc_actuator.params import ActuatorParams  # noqa: E402
from bldc_actuator.recording import as_level, read_recording, summarize  # noqa: E402
from bldc_actuator.replay import resimulate  # noqa: E402

T = 10.0


def t_of(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def test_recording_round_trip_and_resimulation(ros_context, ros_executor, tmp_path):
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Empty, Float64, Float64MultiArray

    path = tmp_path / "run.mcap"
    node = make_node(ros_context, ros_executor, params={
        "node.lock_step": True, "node.record": str(path), "node.publish_clock": True,
        "node.diagnostics_rate": 100.0, "node.watchdog_timeout": 0.0, "node.joint_name": "elbow"})
    ns = "/bldc_actuator/"
    probe = Probe(ros_context, ros_executor).listen("/joint_states", JointState)
    for topic, mtype in (("current_command", Float64), ("torque_command", Float64), ("load_torque", Float64),
                         ("commands", Float64MultiArray), ("reset_fault", Empty)):
        probe.connect(ns + topic, mtype)
    wait_heard(node.pub_joint)

    def send(topic, msg):
        n = len(probe.get("/joint_states"))
        probe.publish(ns + topic, msg)
        assert wait_for(lambda: len(probe.get("/joint_states")) > n, T)

    for k in range(20):
        send("current_command", Float64(data=2.0 + 0.1 * k))
    probe.publish(ns + "load_torque", Float64(data=0.05))
    assert wait_for(lambda: node.joints[0].load_torque_extra == 0.05, T)
    assert node.set_parameters([Parameter("drive.bus_voltage", value=12.0)])[0].successful
    for k in range(15):
        send("torque_command", Float64(data=0.3))
    send("current_command", Float64(data=math.nan))          # rejected, still recorded and one period
    send("commands", Float64MultiArray(data=[-0.2]))
    probe.publish(ns + "reset_fault", Empty())
    send("current_command", Float64(data=1.0))
    node.close()
    live = probe.get("/joint_states")

    rec = read_recording(path)
    assert rec.finalized and not rec.issues, rec.issues
    # every topic is there, with the node's resolved names
    for topic in ("/joint_states", ns + "phase_currents", ns + "q_axis_state", ns + "winding_temperature",
                  ns + "housing_temperature", "/diagnostics", "/clock", ns + "current_command",
                  ns + "torque_command", ns + "commands", ns + "load_torque", ns + "reset_fault",
                  "/parameter_events"):
        assert rec.topics.get(topic), topic
    js = rec.topics["/joint_states"]
    assert len(js) == node.periods + 1             # + the initial state at t = 0
    assert len(rec.topics[ns + "current_command"]) == 22 and len(rec.topics[ns + "torque_command"]) == 15
    # decoded values equal what went over the wire (values, never bytes)
    recorded = {t: m for t, m in js}
    for m in live:
        r = recorded[t_of(m.header.stamp)]
        assert list(r.position) == list(m.position) and list(r.velocity) == list(m.velocity)
        assert list(r.effort) == list(m.effort) and list(r.name) == ["elbow"]
    # log times are simulation times: equal to the header stamps
    assert all(t == t_of(m.header.stamp) for t, m in js)
    q = rec.topics[ns + "q_axis_state"][-1][1]
    assert q.layout.dim[0].label.split(",") == list(Q_AXIS_FIELDS)
    assert all(as_level(s.level) in (0, 1, 2) for _, a in rec.topics["/diagnostics"] for s in a.status)
    # parameters: initial record = start values, final = after the runtime change; node.* ride along
    initial = [d for n, d in rec.metadata_records if n == "bldc_actuator"][0]
    assert "bus_voltage: 24.0" in initial["parameters_yaml"]
    assert rec.parameters["drive.bus_voltage"] == 12.0 and rec.params() == ActuatorParams().replace(
        **{"drive.bus_voltage": 12.0})
    assert rec.parameters["node.joint_name"] == "elbow" and rec.parameters["node.lock_step"] is True
    (t_ev, ev), = rec.topics["/parameter_events"]
    assert [p.name for p in ev.changed_parameters] == ["drive.bus_voltage"] and t_ev == 20 * node.period_ns
    # the recording alone re-simulates the run, to the last bit
    replayed = resimulate(rec)
    assert [t for t, _ in replayed] == [t for t, _ in js]
    for (t, o), (_, m) in zip(replayed, js):
        assert (o["position_out"], o["velocity_out"], o["effort_out"]) == (m.position[0], m.velocity[0], m.effort[0])
    info = summarize(path)
    assert info["topics"]["/joint_states"]["count"] == len(js) and info["parameters_present"]


def test_recording_is_finalized_when_the_node_is_destroyed(ros_context, ros_executor, tmp_path):
    path = tmp_path / "short.mcap"
    node = make_node(ros_context, ros_executor, params={"node.time_factor": 0.0, "node.record": str(path),
                                                        "node.max_sim_time": 0.05})
    assert wait_for(lambda: node.finished, T)
    ros_executor.remove_node(node)
    node.destroy_node()
    info = summarize(path)
    assert info["finalized"] and info["topics"]["/joint_states"]["count"] == 51
    assert info["end_ns"] == 50_000_000
