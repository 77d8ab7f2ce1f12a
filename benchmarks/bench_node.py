#!/usr/bin/env python3
"""Benchmark of actuator_node (a script, not a test): prints figures.

    .venv/bin/python benchmarks/bench_node.py [--seconds 3] [--executor single|events|both]

Measures, in one process (no DDS subscriber unless stated):
* real time (time_factor 1) at 1 kHz publish / 10 kHz physics: achieved publish rate, timer tick interval
  p50/p99, lateness of each period's publication behind its ideal wall time p50/p99/max, CPU use
  (process CPU time / wall; includes the DDS threads);
* the same while recording to MCAP;
* as fast as possible (time_factor 0), with and without recording: the maximum real-time factor and the
  MCAP write throughput (messages/s, MB/s);
* lock-step round trips with an in-process controller node (one command -> one period -> joint_states):
  periods per wall second;
* the physics alone (Actuator.step_ns per 1 ms period) for reference.
Timing depends on the machine and its load: the load average is printed with the figures.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", "97")


def make_executor(kind: str, context):
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor(context=context)


def pct(xs, q):
    return float(np.percentile(np.asarray(xs), q)) if len(xs) else float("nan")


def run_free(context, executor_kind: str, seconds: float, time_factor: float, record: Path | None) -> dict:
    from rclpy.parameter import Parameter

    from bldc_actuator.node import ActuatorNode

    overrides = [Parameter("node.time_factor", value=time_factor)]
    if record is not None:
        overrides.append(Parameter("node.record", value=str(record)))
    node = ActuatorNode(context=context, parameter_overrides=overrides, start=False)
    ticks: list[int] = []
    pubs: list[int] = []
    orig_tick, orig_pub = node._on_tick, node._publish_state

    def tick():
        ticks.append(time.monotonic_ns())
        orig_tick()

    def pub():
        orig_pub()
        pubs.append(time.monotonic_ns())

    node._on_tick = tick
    node._publish_state = pub
    ex = make_executor(executor_kind, context)
    ex.add_node(node)
    node.start()
    pubs.clear()
    wall0, cpu0, sim0 = time.monotonic_ns(), time.process_time(), node.t_ns
    anchor_wall, anchor_sim = node._anchor_wall, node._anchor_sim
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.05)
    wall = (time.monotonic_ns() - wall0) * 1e-9
    cpu = time.process_time() - cpu0
    sim = (node.t_ns - sim0) * 1e-9
    rec = node.recorder
    written = rec.messages_written if rec is not None else 0
    nbytes = rec.bytes_written if rec is not None else 0
    slips = node.slips
    node.close()
    ex.remove_node(node)
    node.destroy_node()
    ex.shutdown()
    out = {"wall": wall, "sim": sim, "rtf": sim / wall, "cpu": cpu / wall, "periods": len(pubs),
           "rate": len(pubs) / wall, "messages": written, "bytes": nbytes, "slips": slips}
    if 0 < time_factor < float("inf"):
        intervals = np.diff(ticks) * 1e-6
        period_ns = node.period_ns
        # ideal wall time of the publication of period k (ends at sim time anchor_sim + k*period)
        ideal = [anchor_wall + (anchor_sim + (k + 1) * period_ns - anchor_sim) / time_factor for k in range(len(pubs))]
        late = (np.array(pubs) - np.array(ideal)) * 1e-6
        late -= late.min() if len(late) else 0.0   # the anchor has an arbitrary half-period offset
        out.update(tick_p50=pct(intervals, 50), tick_p99=pct(intervals, 99),
                   late_p50=pct(late, 50), late_p99=pct(late, 99), late_max=float(late.max()) if len(late) else 0)
    return out


def run_lock_step(context, executor_kind: str, seconds: float) -> dict:
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    from bldc_actuator.node import ActuatorNode

    node = ActuatorNode(context=context, parameter_overrides=[Parameter("node.lock_step", value=True)],
                        start=False)
    ctl = Node("bench_controller", context=context)
    pub = ctl.create_publisher(Float64, "/bldc_actuator/current_command", 10)
    count = [0]

    def on_state(msg):
        count[0] += 1
        pub.publish(Float64(data=2.0))

    ctl.create_subscription(JointState, "/joint_states", on_state, 10)
    ex = make_executor(executor_kind, context)
    ex.add_node(node)
    ex.add_node(ctl)
    t0 = time.monotonic()
    while pub.get_subscription_count() == 0 or node.pub_joint.get_subscription_count() == 0:
        ex.spin_once(timeout_sec=0.01)
        if time.monotonic() - t0 > 20:
            raise RuntimeError("no discovery")
    wall0, sim0, cpu0 = time.monotonic(), node.t_ns, time.process_time()
    pub.publish(Float64(data=2.0))
    deadline = wall0 + seconds
    while time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.05)
    wall = time.monotonic() - wall0
    out = {"periods_per_s": node.periods / wall, "rtf": (node.t_ns - sim0) * 1e-9 / wall,
           "cpu": (time.process_time() - cpu0) / wall}
    for n in (node, ctl):
        ex.remove_node(n)
        n.destroy_node()
    ex.shutdown()
    return out


def physics_alone(seconds: float = 1.0) -> float:
    from bldc_actuator.model import Actuator

    act = Actuator()
    act.set_current_command(5.0)
    t0 = time.perf_counter()
    n = 0
    while time.perf_counter() - t0 < seconds:
        act.step_ns(1_000_000)
        n += 1
    return n * 1e-3 / (time.perf_counter() - t0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="wall seconds per measurement")
    ap.add_argument("--executor", choices=("single", "events", "both"), default="both")
    args = ap.parse_args()
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    kinds = ["single", "events"] if args.executor == "both" else [args.executor]
    if "events" in kinds:
        try:
            from rclpy.experimental import EventsExecutor  # noqa: F401
        except ImportError:
            kinds.remove("events")
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    load = os.getloadavg()
    print(f"bench_node: {os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; "
          f"{args.seconds:g} s per measurement; publish 1 kHz, physics 10 kHz (defaults)")
    print(f"physics alone (Actuator.step_ns, 1 ms periods): {physics_alone():.1f}x real time")
    tmp = Path(tempfile.mkdtemp(prefix="bench_node_"))
    try:
        for kind in kinds:
            print(f"\n[{kind} executor]")
            for label, rec in (("real time (factor 1)", None),
                               ("real time, recording MCAP", tmp / f"rt_{kind}.mcap")):
                r = run_free(context, kind, args.seconds, 1.0, rec)
                print(f"  {label:<28} rate {r['rate']:7.1f} Hz   tick p50/p99 {r['tick_p50']:.3f}/"
                      f"{r['tick_p99']:.3f} ms   publish lateness p50/p99/max {r['late_p50']:.3f}/"
                      f"{r['late_p99']:.3f}/{r['late_max']:.2f} ms   CPU {r['cpu'] * 100:5.1f} %   slips {r['slips']}")
            for label, rec in (("as fast as possible", None),
                               ("as fast as possible, recording", tmp / f"fast_{kind}.mcap")):
                r = run_free(context, kind, args.seconds, 0.0, rec)
                extra = (f"   MCAP {r['messages'] / r['wall']:8.0f} msg/s {r['bytes'] / r['wall'] / 1e6:5.2f} MB/s"
                         if rec is not None else "")
                print(f"  {label:<28} max real-time factor {r['rtf']:5.2f}x ({r['rate']:7.0f} periods/s, "
                      f"CPU {r['cpu'] * 100:5.1f} %){extra}")
            r = run_lock_step(context, kind, args.seconds)
            print(f"  {'lock-step, in-process ctl':<28} {r['periods_per_s']:7.0f} round trips/s = "
                  f"{r['rtf']:.2f}x real time (CPU {r['cpu'] * 100:5.1f} %)")
    finally:
        rclpy.try_shutdown(context=context)
        for f in tmp.glob("*"):
            f.unlink()
        tmp.rmdir()
    return 0


if __name__ == "__main__":
    sys.exit(main())
