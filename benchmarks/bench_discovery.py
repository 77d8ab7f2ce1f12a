#!/usr/bin/env python3
"""How long a second process needs to discover ``actuator_node`` (a script, not a test): prints figures.

    .venv/bin/python benchmarks/bench_discovery.py [--tries 4] [--load 4] [--joints 12] [--timeout 60]
                                                   [--profile config/fastdds_localhost.xml | --profile '']
                                                   [--node-arg ...] [--pythonpath DIR]

Per try: ``--load`` busy-loop processes (``python -c 'while True: pass'``, nice 0) run for the try's duration
only; ``actuator_node`` starts with ``--joints`` ak80_9 joints (the 12-joint robot of docs/node.md) at real
time; once it logs ``running`` (its loop is stepping), a second process (a plain rclpy node) starts and polls
the graph every 20 ms until it sees the node (``get_node_names_and_namespaces``) and a publisher on
``/joint_states`` (``count_publishers``). Printed per try: the time from the probe's node creation to the
node's name and to its publisher (0.0: known by its first look), and the probe's own start-up (imports,
``rclpy.init``, node) before that; then min/median/max over the tries. A try
that does not find them within ``--timeout`` s counts as not found.

The environment: ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, ``ROS_DOMAIN_ID`` (``--domain``, default 21, outside the test suite's domains 40-101),
and the Fast DDS profile ``--profile`` (default ``config/fastdds_localhost.xml``; ``''`` = none, the rmw's own
transports) for every process. ``--pythonpath DIR`` runs the node from another checkout (before/after).
The load average (``/proc/loadavg``) is printed before and after: the machine is shared.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from bench_node_floor import CONTROLLER, node_command  # noqa: E402  (the floor benchmark's node and controller)

PROBE = r"""
import json, sys, time
t_start = time.monotonic()
import rclpy
from rclpy.node import Node
name, topic, timeout = sys.argv[1], sys.argv[2], float(sys.argv[3])
rclpy.init()
node = Node("discovery_probe")
t0 = time.monotonic()
found = {}
deadline = t0 + timeout
while time.monotonic() < deadline and len(found) < 2:
    now = time.monotonic() - t0
    if "node" not in found and any(n == name for n, _ in node.get_node_names_and_namespaces()):
        found["node"] = now
    if "publisher" not in found and node.count_publishers(topic) > 0:
        found["publisher"] = now
    time.sleep(0.02)
print(json.dumps({"import_s": t0 - t_start, **{k: round(v, 3) for k, v in found.items()}}), flush=True)
node.destroy_node()
rclpy.try_shutdown()
"""

BUSY = "while True: pass"


def loadavg() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def env_for(args) -> dict:
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(args.domain)
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    # (Fast DDS 3 reads FASTDDS_...; rmw_fastrtps warns at every start where the old FASTRTPS_... name is set)
    env.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
    env.pop("FASTDDS_DEFAULT_PROFILES_FILE", None)
    if args.profile:
        env["FASTDDS_DEFAULT_PROFILES_FILE"] = str(Path(args.profile).resolve())
    if args.pythonpath:
        env["PYTHONPATH"] = args.pythonpath + os.pathsep + env.get("PYTHONPATH", "")
    return env


def one_try(args) -> dict:
    env = env_for(args)
    if args.cold_cache:   # a fresh clone's first start: the kernel compiles (numba's on-disk cache is empty)
        env["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="bench_discovery_numba_")
    busy = [subprocess.Popen([sys.executable, "-c", BUSY], env=env) for _ in range(args.load)]
    if args.controller:   # a controller process streaming ~/commands (bench_node_floor.py's) from the start
        busy.append(subprocess.Popen([sys.executable, "-c", CONTROLLER, str(args.joints), str(args.controller),
                                      "sine"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
    probe_cmd = [sys.executable, "-c", PROBE, "bldc_actuator", "/joint_states", str(args.timeout)]
    early = subprocess.Popen(probe_cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) \
        if args.probe_first else None
    node = subprocess.Popen(node_command(args.joints, args.node_arg), env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, cwd=args.pythonpath or None)
    log: list[str] = []
    running = threading.Event()

    def read():
        for line in node.stdout:
            log.append(line)
            if "running:" in line:
                running.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        if early is not None:   # the probe looks from the node's start on, whether or not its loop runs yet
            load0 = loadavg()
            stdout, stderr = early.communicate(timeout=args.timeout + 120)
            returncode = early.returncode
            node_running = running.is_set()
        else:
            if not running.wait(120):
                raise RuntimeError("the node did not start within 120 s:\n" + "".join(log))
            load0 = loadavg()
            node_running = True
            time.sleep(args.delay)
            out = subprocess.run(probe_cmd, env=env, capture_output=True, text=True, timeout=args.timeout + 120)
            stdout, stderr, returncode = out.stdout, out.stderr, out.returncode
        if returncode != 0:
            raise RuntimeError(f"probe failed: {stderr}")
        result = json.loads(stdout.strip().splitlines()[-1])
        result["load"] = load0
        result["node_running_when_found"] = node_running
        return result
    finally:
        node.send_signal(signal.SIGINT)
        try:
            node.wait(timeout=20)
        except subprocess.TimeoutExpired:
            node.kill()
            node.wait()
        for b in busy:
            b.kill()
            b.wait()
        reader.join(timeout=5)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tries", type=int, default=4)
    ap.add_argument("--load", type=int, default=4, help="busy-loop processes during each try (default 4)")
    ap.add_argument("--joints", type=int, default=12)
    ap.add_argument("--timeout", type=float, default=60.0, help="give up a try after this many seconds")
    ap.add_argument("--delay", type=float, default=1.0, help="seconds between the node's 'running' and the probe")
    ap.add_argument("--cold-cache", action="store_true",
                    help="an empty numba cache for the node (a fresh clone's first start: the kernel compiles)")
    ap.add_argument("--probe-first", action="store_true",
                    help="start the probe before the node (a controller waiting for it); times from the probe's start")
    ap.add_argument("--controller", type=float, default=0.0,
                    help="also run a controller process sending ~/commands at this rate [Hz] (0 = none)")
    ap.add_argument("--domain", type=int, default=21, help="ROS_DOMAIN_ID of every process (default 21)")
    ap.add_argument("--profile", default=str(ROOT / "config" / "fastdds_localhost.xml"),
                    help="Fast DDS XML profile for every process; '' = none")
    ap.add_argument("--node-arg", action="append", default=[], help="extra argument for actuator_node")
    ap.add_argument("--pythonpath", default="", help="run the node's bldc_actuator from this checkout")
    args = ap.parse_args()
    print(f"discovery of actuator_node ({args.joints} joints, real time) by a second process; {args.load} busy "
          f"loop(s); controller {args.controller:g} Hz; profile {args.profile or 'none'}; domain {args.domain}; load average {loadavg()}; "
          f"{os.cpu_count()} CPUs", flush=True)
    times_node, times_pub, missed = [], [], 0
    for k in range(args.tries):
        r = one_try(args)
        ok = "node" in r and "publisher" in r
        missed += not ok
        if ok:
            times_node.append(r["node"])
            times_pub.append(r["publisher"])
        print(f"try {k + 1}: node {r.get('node', 'NOT FOUND')} s, /joint_states publisher "
              f"{r.get('publisher', 'NOT FOUND')} s after the probe's node existed (its own start-up before: "
              f"{r['import_s']:.2f} s; load average {r['load']}; the node's loop "
              f"{'running' if r['node_running_when_found'] else 'not yet running: kernel compiling'} then)", flush=True)
    for label, xs in (("node name", times_node), ("publisher", times_pub)):
        if xs:
            print(f"{label}: min {min(xs):.2f} s, median {statistics.median(xs):.2f} s, max {max(xs):.2f} s "
                  f"over {len(xs)} found")
    print(f"not found within {args.timeout:g} s: {missed} of {args.tries}; load average after {loadavg()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
