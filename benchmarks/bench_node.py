#!/usr/bin/env python3
"""Benchmark of actuator_node (a script, not a test): prints figures.

    .venv/bin/python benchmarks/bench_node.py [--seconds 3] [--executor single|events|both]

Measures, in one process (no DDS subscriber unless stated):
* real time (time_factor 1) at 1 kHz publish / 10 kHz physics: achieved publish rate, lateness of each
  period's publication behind its ideal wall time p50/p99/max (``node.scheduler.timing``), CPU use
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
os.environ.setdefault("ROS_DOMAIN_ID", "23")   # outside the test suite's domains 40-101


def make_executor(kind: str, context):
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor(context=context)


def pct(xs, q):
    return float(np.percentile(np.asarray(xs), q)) if len(xs) else float("nan")


CONTROLLER = """
import os, sys, time, rclpy
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
n, rate, seconds = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
rclpy.init()
node = Node("bench_controller_process")
pub = node.create_publisher(Float64MultiArray, "/bldc_actuator/commands", 10)
msg = Float64MultiArray(data=[0.5] * n)
k = [0]
def send():
    k[0] += 1
    msg.data = [0.5 if (k[0] // 250) % 2 else -0.5] * n
    pub.publish(msg)
node.create_timer(1.0 / rate, send)
end = time.monotonic() + seconds
while time.monotonic() < end and rclpy.ok():
    rclpy.spin_once(node, timeout_sec=0.1)
"""


def start_controller(joints: int, rate: float, seconds: float):
    """A controller in ANOTHER process sending ~/commands (one effort per joint) at ``rate`` Hz."""
    import subprocess

    env = dict(os.environ)
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    return subprocess.Popen([sys.executable, "-c", CONTROLLER, str(joints), str(rate), str(seconds)], env=env)


def proc_cpu_seconds() -> float:
    """utime + stime of this process from /proc (all threads: executor, DDS)."""
    fields = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def joint_overrides(joints: int, detail_rate: float, named: bool = False):
    from rclpy.parameter import Parameter

    if joints <= 1 and not named:
        return []
    names = [f"j{k}" for k in range(joints)]
    return ([Parameter("joints", value=names), Parameter("node.detail_rate", value=detail_rate)]
            + [Parameter(f"joint.{n}.preset", value="ak80_9") for n in names])


def run_free(context, executor_kind: str, seconds: float, time_factor: float, record: Path | None,
             joints: int = 1, detail_rate: float = 0.0, controller_rate: float = 0.0, named: bool = False) -> dict:
    from rclpy.parameter import Parameter

    from bldc_actuator.node import ActuatorNode

    overrides = [Parameter("node.time_factor", value=time_factor)] + joint_overrides(joints, detail_rate, named)
    if record is not None:
        overrides.append(Parameter("node.record", value=str(record)))
    node = ActuatorNode(context=context, parameter_overrides=overrides, start=False)
    ctl = None
    if controller_rate > 0:
        ctl = start_controller(len(node.joints), controller_rate, seconds + 30.0)
        t0 = time.monotonic()
        while node.sub_commands.get_publisher_count() == 0:
            time.sleep(0.05)
            if time.monotonic() - t0 > 20:
                ctl.kill()
                raise RuntimeError("controller process not discovered")
    node.scheduler.timing = []     # (ideal wall time, wall time after publication) of every clocked period
    ex = make_executor(executor_kind, context)
    ex.add_node(node)
    node.start()
    received0, periods0 = node.commands_received, node.periods
    wall0, cpu0, sim0 = time.monotonic_ns(), proc_cpu_seconds(), node.t_ns
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.05)
    wall = (time.monotonic_ns() - wall0) * 1e-9
    cpu = proc_cpu_seconds() - cpu0
    received = node.commands_received - received0
    if ctl is not None:
        ctl.kill()
        ctl.wait()
    sim = (node.t_ns - sim0) * 1e-9
    rec = node.recorder
    written = rec.messages_written if rec is not None else 0
    nbytes = rec.bytes_written if rec is not None else 0
    slips = node.slips
    node.close()
    ex.remove_node(node)
    node.destroy_node()
    ex.shutdown()
    periods = node.periods - periods0
    timing = node.scheduler.timing
    out = {"wall": wall, "sim": sim, "rtf": sim / wall, "cpu": cpu / wall, "periods": periods,
           "rate": periods / wall, "messages": written, "bytes": nbytes, "slips": slips,
           "commands_per_s": received / wall / max(1, joints)}
    if 0 < time_factor < float("inf") and timing:
        late = np.array([done - ideal for ideal, done in timing]) * 1e-6
        late -= late.min()   # the anchor leads the wake-ups by a tenth of a period: relative lateness
        out.update(late_p50=pct(late, 50), late_p99=pct(late, 99), late_max=float(late.max()))
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


def robot_figures(context, kinds, args) -> None:
    """Issue #8's figures: N joints at 1 kHz publish / 10 kHz physics in real time with commands from another
    process (500 Hz); as fast as possible for N joints and for one; lock-step for one joint."""
    n = args.robot
    import gc
    gc.collect()
    gc.freeze()      # as actuator_node's main() does: the node's long-lived objects out of the collector's way
    for kind in kinds:
        print(f"\n[robot, {kind} executor]")
        r = run_free(context, kind, args.seconds, 1.0, None, joints=n, detail_rate=args.detail_rate,
                     controller_rate=500.0)
        print(f"  {n} joints real time, controller process 500 Hz: rate {r['rate']:7.1f} Hz   publish lateness "
              f"p50/p99/max {r['late_p50']:.3f}/{r['late_p99']:.3f}/{r['late_max']:.2f} ms   node CPU "
              f"{r['cpu'] * 100:5.1f} % of one core (/proc)   commands {r['commands_per_s']:.0f}/s per joint   "
              f"slips {r['slips']}   detail topics {args.detail_rate:g} Hz")
        r = run_free(context, kind, args.seconds, 0.0, None, joints=n, detail_rate=args.detail_rate)
        print(f"  {n} joints as fast as possible: {r['rtf']:6.2f}x real time (CPU {r['cpu'] * 100:5.1f} %)")
        r = run_free(context, kind, args.seconds, 0.0, None)
        print(f"  1 joint as fast as possible:   {r['rtf']:6.2f}x real time (CPU {r['cpu'] * 100:5.1f} %; every "
              "topic every period, the single-joint default)")
        r = run_free(context, kind, args.seconds, 0.0, None, joints=1, detail_rate=args.detail_rate, named=True)
        print(f"  1 joint as fast as possible:   {r['rtf']:6.2f}x real time (CPU {r['cpu'] * 100:5.1f} %; "
              f"joints:=[j0], detail topics {args.detail_rate:g} Hz)")
        r = run_lock_step(context, kind, args.seconds)
        print(f"  1 joint lock-step, in-process controller: {r['rtf']:.2f}x real time "
              f"({r['periods_per_s']:.0f} round trips/s)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="wall seconds per measurement")
    ap.add_argument("--executor", choices=("single", "events", "both"), default="both")
    ap.add_argument("--robot", type=int, default=12, metavar="N",
                    help="also the whole-robot figures for N joints (ak80_9 each; 0 skips)")
    ap.add_argument("--detail-rate", type=float, default=100.0,
                    help="per-joint detail topics rate for the robot figures [Hz]")
    ap.add_argument("--only-robot", action="store_true", help="only the whole-robot figures")
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
        if args.robot:
            robot_figures(context, kinds, args)
        for kind in ([] if args.only_robot else kinds):
            print(f"\n[{kind} executor]")
            for label, rec in (("real time (factor 1)", None),
                               ("real time, recording MCAP", tmp / f"rt_{kind}.mcap")):
                r = run_free(context, kind, args.seconds, 1.0, rec)
                print(f"  {label:<28} rate {r['rate']:7.1f} Hz   publish lateness p50/p99/max {r['late_p50']:.3f}/"
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
