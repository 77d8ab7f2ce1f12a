#!/usr/bin/env python3
"""The floor node: what ANY rclpy node with actuator_node's topic contract costs, without physics.

    .venv/bin/python benchmarks/floor_node.py [--joints 12] [--rate 1000] [--executor events|single]

It publishes the same ``sensor_msgs/JointState`` (every joint: position, velocity, effort; stamped) at
``--rate`` Hz from a steady-clock timer and takes the same commands (``~/commands``,
``std_msgs/Float64MultiArray``, one value per joint, node name ``bldc_actuator``), with the same executor and
the same ``gc.freeze()`` as ``actuator_node``. The efforts echo the commands, position and velocity are a
trivial integration: no simulation. ``benchmarks/bench_node_floor.py`` runs it side by side with
``actuator_node`` to quote the node's CPU as a multiple of this floor. Stops on SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import array
import gc
import signal
import sys
import time


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--joints", type=int, default=12)
    ap.add_argument("--rate", type=float, default=1000.0, help="JointState rate [Hz]")
    ap.add_argument("--executor", choices=("events", "single"), default="events")
    args = ap.parse_args(argv)

    import rclpy
    from rclpy.clock import Clock, ClockType
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile
    from rclpy.task import Future
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    rclpy.init()
    node = Node("bldc_actuator")
    n = args.joints
    period_ns = int(round(1e9 / args.rate))
    pub = node.create_publisher(JointState, "joint_states", QoSProfile(depth=10))
    msg = JointState(name=[f"j{k}" for k in range(n)])
    msg.position = array.array("d", [0.0] * n)
    msg.velocity = array.array("d", [0.0] * n)
    msg.effort = array.array("d", [0.0] * n)
    command = [0.0] * n
    published = [0]
    anchor = [0]

    def on_commands(m: Float64MultiArray) -> None:
        if len(m.data) == n:
            command[:] = m.data

    def tick() -> None:
        # every period due by the steady clock is published (as actuator_node does): a late wake-up
        # catches up instead of thinning the stream, and stamps are wall-clock periods since the start
        now = time.monotonic_ns()
        if not anchor[0]:
            anchor[0] = now - period_ns // 2
        due = min((now - anchor[0]) // period_ns - published[0], 20)
        for _ in range(due):
            published[0] += 1
            sec, nsec = divmod(published[0] * period_ns, 1_000_000_000)
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
            pos, vel, eff = msg.position, msg.velocity, msg.effort
            for k in range(n):
                eff[k] = command[k]
                vel[k] += 1e-3 * command[k]
                pos[k] += 1e-3 * vel[k]
            pub.publish(msg)
        if due == 20:   # too far behind: drop the debt (as actuator_node does)
            published[0] = (now - anchor[0]) // period_ns

    node.create_subscription(Float64MultiArray, "~/commands", on_commands, QoSProfile(depth=100))
    node.create_timer(period_ns * 1e-9, tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
    if args.executor == "events":
        from rclpy.experimental import EventsExecutor

        executor = EventsExecutor()
    else:
        executor = SingleThreadedExecutor()
    executor.add_node(node)
    signal.signal(signal.SIGTERM, lambda *a: rclpy.try_shutdown())
    gc.collect()
    gc.freeze()
    never = Future()   # spun exactly as actuator_node's main() spins (same executor call, same timeout)
    try:
        while rclpy.ok():
            executor.spin_until_future_complete(never, timeout_sec=0.25)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
