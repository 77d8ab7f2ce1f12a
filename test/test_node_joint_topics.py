"""``node.joint_topics``: a robot's per-joint topics are created on demand (a command subscription once a
publisher appears, a detail publisher once a subscriber appears), yet a user who publishes to
``/bldc_actuator/<joint>/current_command`` after the node started is obeyed: the physics follows the command."""

from __future__ import annotations

import math
import time

import pytest

pytest.importorskip("rclpy")

from conftest import scaled, wait_for  # noqa: E402
from node_helpers import Probe, make_node  # noqa: E402

T = 10.0
JOINTS = ["hip", "knee"]


def _robot(ros_context, ros_executor, **extra):
    params = {"joints": JOINTS, "node.watchdog_timeout": 0.0, "node.lock_step": True,
              **{f"joint.{j}.preset": "ak80_9" for j in JOINTS}, **extra}
    return make_node(ros_context, ros_executor, params=params)


def test_per_joint_command_topic_created_when_a_publisher_appears_and_obeyed(ros_context, ros_executor):
    from std_msgs.msg import Float64, Float64MultiArray

    node = _robot(ros_context, ros_executor)
    assert node.joint_topics_on_demand      # joints given, default auto: on demand
    topic = "/bldc_actuator/knee/current_command"
    # nothing per joint exists yet: no subscription in the graph, none in the node
    assert node.topics[1].sub_current is None and node.topics[1].pub_q is None
    assert node.count_subscribers(topic) == 0
    # the whole-robot command topic is always there
    assert node.count_subscribers("/bldc_actuator/commands") == 1
    probe = Probe(ros_context, ros_executor)
    t0 = time.monotonic()
    probe.connect(topic, Float64)           # waits until the node subscribed (graph poll + discovery)
    waited = time.monotonic() - t0
    # 5 s on a quiet machine (the graph is polled every second), scaled by the load
    assert waited < scaled(5.0), f"subscription took {waited:.1f} s (poll every second)"
    assert node.topics[1].sub_current is not None and node.topics[0].sub_current is None   # only that topic
    probe.publish(topic, Float64(data=3.0))
    knee, hip = node.joints[1], node.joints[0]
    assert wait_for(lambda: knee.value == 3.0 and knee.kind == "current", T), "command not applied"
    node.advance(20)                         # 20 ms: the current loop (10 kHz, ~1 kHz bandwidth) settles
    out_knee, out_hip = node.plant.outputs("knee"), node.plant.outputs("hip")
    assert out_knee["i_q_ref"] == 3.0 and math.isclose(out_knee["i_q"], 3.0, rel_tol=0.02)
    assert out_hip["i_q_ref"] == 0.0 and abs(out_hip["i_q"]) < 1e-6 and hip.commands_received == 0
    assert node.plant.outputs("knee")["omega"] > 0.0      # positive q current accelerates the free rotor
    # the whole-robot array still works alongside
    probe.connect("/bldc_actuator/commands", Float64MultiArray)
    probe.publish("/bldc_actuator/commands", Float64MultiArray(data=[0.1, -0.2]))
    assert wait_for(lambda: knee.value == -0.2 and knee.kind == "torque", T)


def test_detail_topic_published_once_subscribed(ros_context, ros_executor):
    from std_msgs.msg import Float64MultiArray

    from bldc_actuator.node import Q_AXIS_FIELDS, layout_labels

    node = _robot(ros_context, ros_executor, **{"node.lock_step": False})
    topic = "/bldc_actuator/hip/q_axis_state"
    assert node.count_publishers(topic) == 0
    probe = Probe(ros_context, ros_executor).listen(topic, Float64MultiArray)
    assert wait_for(lambda: len(probe.get(topic)) >= 5, T), "no q_axis_state after subscribing"
    assert node.topics[0].pub_q is not None and node.topics[1].pub_q is None
    msg = probe.get(topic)[-1]
    assert layout_labels(msg) == list(Q_AXIS_FIELDS)
    values = dict(zip(Q_AXIS_FIELDS, msg.data))
    # no command: no current, the bus voltage of the preset
    assert values["i_q_ref"] == 0.0 and abs(values["i_q"]) < 1e-9
    assert values["bus_voltage"] == node.plant.params("hip").drive.bus_voltage


def test_always_creates_every_joint_topic_up_front(ros_context, ros_executor):
    node = _robot(ros_context, ros_executor, **{"node.joint_topics": "always"})
    assert not node.joint_topics_on_demand
    for jt in node.topics:
        assert None not in (jt.sub_current, jt.sub_torque, jt.sub_load, jt.sub_reset,
                            jt.pub_phase, jt.pub_q, jt.pub_tw, jt.pub_th)
    assert node.count_subscribers("/bldc_actuator/knee/current_command") == 1
    assert node.count_publishers("/bldc_actuator/knee/winding_temperature") == 1


def test_single_joint_default_and_bad_value(ros_context, ros_executor):
    from bldc_actuator.params import ParameterError

    node = make_node(ros_context, ros_executor, params={"node.lock_step": True})
    assert not node.joint_topics_on_demand and node.topics[0].sub_current is not None
    with pytest.raises(ParameterError, match="node.joint_topics.*always, on_demand"):
        make_node(ros_context, ros_executor, name="bad", params={"node.joint_topics": "sometimes"})
