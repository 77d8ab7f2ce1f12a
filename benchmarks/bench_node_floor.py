#!/usr/bin/env python3
"""actuator_node against the rclpy floor, side by side (a script, not a test): prints figures.

    .venv/bin/python benchmarks/bench_node_floor.py [--joints 12] [--seconds 10] [--rounds 3]
                                                    [--node-arg -p --node-arg node.detail_rate:=100.0]
                                                    [--baseline DIR]

Conditions (what a user has under ros2_control): a controller in ANOTHER process sends ``~/commands`` (one
effort per joint, a 2 Hz sine so every message differs as a controller's do; ``--command-wave square`` for
nearly all repeats) at ``--command-rate`` (1 kHz), and a subscriber in a third process listens to
``joint_states`` and ``/diagnostics``. Under that same command stream, in the same run, the benchmark
alternates ``--rounds`` times between

* the floor: ``benchmarks/floor_node.py`` — the same 12-joint JointState at 1 kHz, the same command topic,
  the same executor and spin loop, no physics (what any rclpy node with this contract costs), and
* ``actuator_node`` with ``--joints`` ak80_9 joints and its defaults (plus ``--node-arg`` extras),

and, with ``--baseline DIR`` (a source checkout of another commit, e.g. made by ``git worktree add``), the
same ``actuator_node`` from that checkout ("base", its ``bldc_actuator`` first on ``PYTHONPATH``): before and
after a change, side by side under the same load. Each is a fresh process, measured after ``--warmup`` seconds for ``--seconds``: CPU of the process from
``/proc/<pid>/stat`` (utime + stime, all threads: executor and DDS) per wall second, the JointState rate and
the lateness of each message as the subscriber receives it (arrival time minus stamp, minus the run's
smallest such difference: p50/p99/max; the node's stamps are simulation time, which real time ties to the
steady clock), and the node's slips as its /diagnostics report them. The ratio node/floor is quoted per
round (each node run against the floor run next to it; with ``--baseline`` also base/floor and node/base) with
its spread; a ratio whose processes did not both keep 1 kHz (slips, or fewer than 990 messages/s) is shown but
not counted (a starved process does less work).
The load average is printed: the machine is shared, so only the ratio of neighbouring runs means much.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

CONTROLLER = r"""
import math, sys, rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import Float64MultiArray
n, rate, wave = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
rclpy.init()
node = Node("bench_controller")
pub = node.create_publisher(Float64MultiArray, "/bldc_actuator/commands", 10)
msg = Float64MultiArray(data=[0.0] * n)
k = [0]
def send():
    k[0] += 1
    if wave == "sine":   # what a joint controller sends: every message differs (0.5 N*m, 2 Hz, phase per joint)
        msg.data = [0.5 * math.sin(2 * math.pi * 2.0 * k[0] / rate + 0.5 * j) for j in range(n)]
    else:                # +-0.5 N*m square wave, 2 Hz: 249 of 250 messages repeat the last one
        msg.data = [0.5 if (k[0] // 250) % 2 else -0.5] * n
    pub.publish(msg)
node.create_timer(1.0 / rate, send)
ex = EventsExecutor()
ex.add_node(node)
try:
    while rclpy.ok():
        ex.spin_until_future_complete(Future(), timeout_sec=0.25)
except BaseException:
    pass
"""

SUBSCRIBER = r"""
import json, sys, time, rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from diagnostic_msgs.msg import DiagnosticArray
start, stop = float(sys.argv[1]), float(sys.argv[2])     # monotonic window [s]
rclpy.init()
node = Node("bench_subscriber")
late, diag, count = [], [], [0]
def on_js(m):
    now = time.monotonic_ns()
    if start * 1e9 <= now < stop * 1e9:
        count[0] += 1
        late.append(now - (m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec))
def on_diag(m):
    now = time.monotonic_ns()
    if start * 1e9 <= now < stop * 1e9:
        diag.extend(s.message for s in m.status if s.level != b"\x00")
node.create_subscription(JointState, "/joint_states", on_js, QoSProfile(depth=100))
node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, QoSProfile(depth=100))
ex = EventsExecutor()
ex.add_node(node)
while time.monotonic() < stop + 0.5:
    ex.spin_once(timeout_sec=0.1)
m = min(late) if late else 0
print(json.dumps({"count": count[0], "late_ms": sorted((x - m) * 1e-6 for x in late), "diag": diag}))
"""


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def thread_cpu(pid: int) -> dict[str, float]:
    """CPU seconds per thread name (``/proc/<pid>/task/*``; threads of one name summed)."""
    out: dict[str, float] = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return out


def pct(xs: list[float], q: float) -> float:
    if not xs:
        return float("nan")
    return xs[min(len(xs) - 1, int(round(q / 100 * (len(xs) - 1))))]


def child_env() -> dict:
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env.setdefault("ROS_DOMAIN_ID", "24")   # outside the test suite's domains 40-101
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    return env


def node_command(joints: int, extra: list[str]) -> list[str]:
    names = [f"j{k}" for k in range(joints)]
    ros = ["--ros-args", "-p", f"joints:=[{', '.join(names)}]"]
    for n in names:
        ros += ["-p", f"joint.{n}.preset:=ak80_9"]
    own = [a for a in extra if a.startswith(("--executor", "--record"))]   # the node's own options go before --ros-args
    return [sys.executable, "-c", "import sys; from bldc_actuator.node import main; sys.exit(main(sys.argv))",
            *own, *ros, *[a for a in extra if a not in own]]


def niced(args):
    """``preexec_fn`` giving a child the nice value ``--nice`` (the same for every process of the benchmark)."""
    if not args.nice:
        return None
    return lambda: os.setpriority(os.PRIO_PROCESS, 0, args.nice)


def measure(cmd: list[str], label: str, args, pythonpath: str | None = None) -> dict:
    env = child_env()
    if pythonpath:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            preexec_fn=niced(args), cwd=pythonpath)   # (python -c puts its cwd first on sys.path)
    t_start = time.monotonic() + args.warmup
    t_stop = t_start + args.seconds
    sub = subprocess.Popen([sys.executable, "-c", SUBSCRIBER, repr(t_start), repr(t_stop)], env=env,
                           stdout=subprocess.PIPE, text=True, preexec_fn=niced(args))
    try:
        time.sleep(max(0.0, t_start - time.monotonic()))
        if proc.poll() is not None:
            raise RuntimeError(f"{label} exited early: {proc.communicate()[0]}")
        c0 = cpu_seconds(proc.pid)
        th0 = thread_cpu(proc.pid)
        w0 = time.monotonic()
        spy = None
        if args.py_spy and label == "node" and not args.py_spy_done:
            args.py_spy_done = True
            spy = subprocess.Popen(["py-spy", "record", "--native", "-r", "200", "-d", str(int(args.seconds)),
                                    "-f", "raw" if args.py_spy.endswith(".txt") else "speedscope",
                                    "-o", args.py_spy, "-p", str(proc.pid)],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(max(0.0, t_stop - time.monotonic()))
        c1 = cpu_seconds(proc.pid)
        th1 = thread_cpu(proc.pid)
        w1 = time.monotonic()
        if spy is not None:
            spy.wait(timeout=60)
        out, _ = sub.communicate(timeout=30)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            log, _ = proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            log, _ = proc.communicate()
        if sub.poll() is None:
            sub.kill()
    r = json.loads(out)
    late = r["late_ms"]
    slips = sum("cannot keep" in d for d in r["diag"])
    return {"label": label, "cpu": (c1 - c0) / (w1 - w0), "rate": r["count"] / (w1 - w0),
            "late_p50": pct(late, 50), "late_p99": pct(late, 99), "late_max": late[-1] if late else float("nan"),
            "slip_reports": slips, "warn": len(r["diag"]), "log": log,
            "threads": {k: (v - th0.get(k, 0.0)) / (w1 - w0) for k, v in th1.items() if v - th0.get(k, 0.0) > 0}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--joints", type=int, default=12)
    ap.add_argument("--seconds", type=float, default=10.0, help="measured wall seconds per run")
    ap.add_argument("--warmup", type=float, default=5.0, help="seconds after start before measuring")
    ap.add_argument("--rounds", type=int, default=3, help="floor/node pairs")
    ap.add_argument("--command-rate", type=float, default=1000.0, help="controller's command rate [Hz]")
    ap.add_argument("--command-wave", choices=("sine", "square"), default="sine",
                    help="sine: every command differs, as a joint controller's do (default); square: a 2 Hz square "
                         "wave, nearly every message a repeat (the node's held-command shortcut)")
    ap.add_argument("--node-arg", action="append", default=[], help="extra argument for actuator_node "
                    "(after its --ros-args), e.g. --node-arg=-p --node-arg=node.detail_rate:=100.0")
    ap.add_argument("--py-spy", metavar="OUT", help="profile the first node run with py-spy (on PATH) into OUT "
                    "(.txt: collapsed stacks, else speedscope JSON); its sampling adds to that run's CPU")
    ap.add_argument("--nice", type=int, default=0, help="nice value of every process of the benchmark (floor, node, "
                    "controller, subscriber alike; negative needs root): keeps a shared machine's other jobs from "
                    "starving them")
    ap.add_argument("--threads", action="store_true", help="print each process's CPU per thread")
    ap.add_argument("--show-log", action="store_true", help="print the node's console output")
    ap.add_argument("--baseline", metavar="DIR", help="a source checkout of another commit: its actuator_node runs "
                    "too in every round (label base), for before/after figures under the same load")
    args = ap.parse_args()
    args.py_spy_done = False
    env = child_env()
    ctl = subprocess.Popen([sys.executable, "-c", CONTROLLER, str(args.joints), str(args.command_rate),
                            args.command_wave], env=env,
                           preexec_fn=niced(args))
    floor_cmd = [sys.executable, str(HERE / "floor_node.py"), "--joints", str(args.joints)]
    node_cmd = node_command(args.joints, args.node_arg)
    base_dir = None
    if args.baseline:
        base_dir = str(Path(args.baseline).resolve())
        if not (Path(base_dir) / "bldc_actuator" / "node.py").is_file():
            ap.error(f"--baseline: expected a source checkout with bldc_actuator/node.py, got {args.baseline}")
    load0 = os.getloadavg()
    print(f"bench_node_floor: {os.cpu_count()} CPUs, load average {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}; "
          f"{args.joints} joints (ak80_9), controller process at {args.command_rate:g} Hz on ~/commands ({args.command_wave}), subscriber "
          f"process on joint_states + /diagnostics; EventsExecutor; {args.rounds} rounds of floor/node, "
          f"{args.seconds:g} s each after {args.warmup:g} s warm-up; node extras: {' '.join(args.node_arg) or 'none'}; "
          f"nice {args.nice}" + (f"; baseline {base_dir}" if base_dir else ""))
    rows, ratios, base_ratios, node_base = [], [], [], []
    try:
        for k in range(args.rounds):
            order = [(floor_cmd, "floor", None), (node_cmd, "node", None)]
            if base_dir:
                order.append((node_cmd, "base", base_dir))
            order = order[k % len(order):] + order[:k % len(order)]   # rotate: none always runs first
            pair = [measure(cmd, label, args, path) for cmd, label, path in order]
            for r in pair:
                rows.append(r)
                print(f"  round {k + 1} {r['label']:<5} CPU {r['cpu'] * 100:5.1f} % of a core   rate "
                      f"{r['rate']:7.1f} Hz   lateness p50/p99/max {r['late_p50']:.3f}/{r['late_p99']:.3f}/"
                      f"{r['late_max']:.2f} ms   slip reports {r['slip_reports']}   non-OK diagnostics "
                      f"{r['warn']}", flush=True)
                if args.threads:
                    print("    threads: " + ", ".join(f"{k} {v * 100:.1f} %" for k, v in
                                                      sorted(r["threads"].items(), key=lambda kv: -kv[1])))
                if args.show_log and r["label"] != "floor":
                    print("    " + r["log"].strip().replace("\n", "\n    "))
            by = {r["label"]: r for r in pair}
            f, n, b = by["floor"], by["node"], by.get("base")
            starved = [r["label"] for r in pair if r["slip_reports"] or r["rate"] < 990.0]
            if starved:   # a process that could not keep 1 kHz did less work: its CPU is no measure
                print(f"  round {k + 1}: {' and '.join(starved)} starved of CPU (slips or < 990 Hz): its ratios "
                      "not counted")
            # each ratio of two processes that both kept 1 kHz counts (a starved third does not void it)
            ok = lambda *rs: all(r is not None and r["label"] not in starved for r in rs)  # noqa: E731
            if ok(f, n):
                ratios.append(n["cpu"] / f["cpu"])
            if ok(f, b):
                base_ratios.append(b["cpu"] / f["cpu"])
            if ok(n, b):
                node_base.append(n["cpu"] / b["cpu"])
    finally:
        ctl.send_signal(signal.SIGINT)
        try:
            ctl.wait(timeout=10)
        except subprocess.TimeoutExpired:
            ctl.kill()
    load1 = os.getloadavg()
    if not ratios:
        print("no round without starvation: the machine is too loaded for a figure")
        return 1
    fl = [r["cpu"] for r in rows if r["label"] == "floor"]
    nd = [r["cpu"] for r in rows if r["label"] == "node"]
    print(f"floor CPU {min(fl) * 100:.1f}-{max(fl) * 100:.1f} %, node CPU {min(nd) * 100:.1f}-{max(nd) * 100:.1f} %; "
          f"node/floor per round: {', '.join(f'{x:.2f}' for x in ratios)} (median {statistics.median(ratios):.2f}, "
          f"range {min(ratios):.2f}-{max(ratios):.2f}); load average at the end {load1[0]:.2f} {load1[1]:.2f} "
          f"{load1[2]:.2f}")
    med = lambda xs: f"median {statistics.median(xs):.2f}, range {min(xs):.2f}-{max(xs):.2f}" if xs else "none"  # noqa: E731
    if base_dir:
        bs = [r["cpu"] for r in rows if r["label"] == "base"]
        print(f"base CPU {min(bs) * 100:.1f}-{max(bs) * 100:.1f} %; base/floor per round: "
              f"{', '.join(f'{x:.2f}' for x in base_ratios)} ({med(base_ratios)}); node/base per round: "
              f"{', '.join(f'{x:.2f}' for x in node_base)} ({med(node_base)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
