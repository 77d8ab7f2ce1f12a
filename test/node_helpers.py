"""Helpers shared by test/test_node*.py: create the actuator node on the test's context, a probe node that
records what it hears and publishes with discovery waits."""

from __future__ import annotations

import threading
from collections import defaultdict

from conftest import wait_for

DISCOVERY_TIMEOUT = 10.0


def make_node(ros_context, ros_executor, *, name="bldc_actuator", namespace=None, params=None, cli_args=None,
              start=True):
    """An ActuatorNode on ``ros_context`` added to ``ros_executor``; ``params`` is a dict of overrides."""
    from rclpy.parameter import Parameter

    from bldc_actuator.node import ActuatorNode

    overrides = [Parameter(k, value=v) for k, v in (params or {}).items()]
    node = ActuatorNode(name, namespace=namespace, context=ros_context, parameter_overrides=overrides,
                        cli_args=cli_args, start=start)
    ros_executor.add_node(node)
    return node


class Probe:
    """A plain node that subscribes to topics (messages kept per topic) and publishes commands."""

    def __init__(self, ros_context, ros_executor, name="probe", use_sim_time=False):
        from rclpy.node import Node
        from rclpy.parameter import Parameter

        self.node = Node(name, context=ros_context,
                         parameter_overrides=[Parameter("use_sim_time", value=use_sim_time)])
        self.msgs: dict[str, list] = defaultdict(list)
        self._lock = threading.Lock()
        self._pubs = {}
        self._subs = {}
        ros_executor.add_node(self.node)

    def listen(self, topic: str, msg_type, depth: int = 1000):
        def cb(msg, topic=topic):
            with self._lock:
                self.msgs[topic].append(msg)

        self._subs[topic] = self.node.create_subscription(msg_type, topic, cb, depth)
        return self

    def publisher(self, topic: str, msg_type):
        if topic not in self._pubs:
            self._pubs[topic] = self.node.create_publisher(msg_type, topic, 100)
        return self._pubs[topic]

    def connect(self, topic: str, msg_type) -> None:
        """Create the publisher and wait until a subscriber has been discovered."""
        pub = self.publisher(topic, msg_type)
        assert wait_for(lambda: pub.get_subscription_count() > 0, DISCOVERY_TIMEOUT), f"no subscriber on {topic}"

    def publish(self, topic: str, msg) -> None:
        self.publisher(topic, type(msg)).publish(msg)

    def get(self, topic: str) -> list:
        with self._lock:
            return list(self.msgs[topic])

    def clear(self, topic: str | None = None) -> None:
        with self._lock:
            if topic is None:
                self.msgs.clear()
            else:
                self.msgs[topic].clear()


def wait_heard(node_publisher, count: int = 1, timeout: float = DISCOVERY_TIMEOUT) -> None:
    """Wait until the node's publisher has discovered ``count`` subscribers."""
    assert wait_for(lambda: node_publisher.get_subscription_count() >= count, timeout), \
        f"{node_publisher.topic_name}: subscriber not discovered"
