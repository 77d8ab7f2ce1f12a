#!/usr/bin/env python3
"""Recording soak through the real node process (a script, not a test): does ``actuator_node``'s memory stay flat
while it records, under a controller's 1 kHz command stream from another process?

    .venv/bin/python benchmarks/soak_node.py [--duration 1800] [--joints 12] [--sample 10] [--warmup 120]
                                             [--out DIR] [--keep] [--command-rate 1000]

What runs: ``actuator_node`` (``--joints`` ak80_9 joints, its defaults, ``--record`` into ``--out``) started as
``bench_node_floor.py`` starts it, and that benchmark's controller process sending ``~/commands`` (a 2 Hz sine per
joint, every message different) at ``--command-rate``. The node records every topic it records by default.
``benchmarks/soak_recording.py`` is the same work in one process without the ROS graph (a cleaner clock); this one
adds what only the node process has: rclpy publishers and subscriptions, the DDS threads, the executor.

Printed: the node process's RSS every ``--sample`` wall seconds (``/proc/<pid>/statm``), the RSS slope by least
squares after ``--warmup`` seconds [kB/s] with its standard error, the recording's size, and at the end (from the
finalized MCAP's statistics) the messages of each kind: ``joint_states`` per wall second is the rate the node held,
``commands`` per wall second the stream it received. The load average at start and end.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_node_floor import CONTROLLER, child_env, node_command  # noqa: E402
from soak_recording import slope  # noqa: E402

PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_of(pid: int) -> int:
    with open(f"/proc/{pid}/statm") as f:
        return int(f.read().split()[1]) * PAGE


def load() -> str:
    return " ".join(open("/proc/loadavg").read().split()[:3])


def message_counts(path: Path) -> dict[str, int]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    counts = summary.statistics.channel_message_counts if summary and summary.statistics else {}
    return {summary.channels[c].topic: n for c, n in counts.items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=1800.0, help="wall seconds [1800]")
    ap.add_argument("--joints", type=int, default=12)
    ap.add_argument("--sample", type=float, default=10.0, help="wall seconds between RSS samples [10]")
    ap.add_argument("--warmup", type=float, default=120.0, help="wall seconds left out of the slope fit [120]")
    ap.add_argument("--command-rate", type=float, default=1000.0, help="controller commands per second [1000]")
    ap.add_argument("--out", type=Path, default=None, help="directory for the recording [a temporary one]")
    ap.add_argument("--keep", action="store_true", help="keep the recording file")
    args = ap.parse_args()
    if args.duration <= args.warmup:
        ap.error("--duration must exceed --warmup")

    out_dir = args.out or Path(tempfile.mkdtemp(prefix="soak_node_"))
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "soak_node.mcap"
    if path.exists():
        path.unlink()
    env = child_env()
    cmd = node_command(args.joints, [f"--record={path}"])
    print(f"soak_node: actuator_node, {args.joints} joints (ak80_9), recording to {path}; controller at "
          f"{args.command_rate:g} Hz (sine); ROS_DOMAIN_ID {env['ROS_DOMAIN_ID']}; duration {args.duration:.0f} s, "
          f"RSS every {args.sample:g} s, warm-up {args.warmup:g} s; load average at start {load()}", flush=True)
    log_path = out_dir / "soak_node.log"   # a file, not a pipe: a pipe nobody reads would block the node's logging
    log = open(log_path, "w")
    node = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, text=True, cwd=HERE.parent)
    ctl = subprocess.Popen([sys.executable, "-c", CONTROLLER, str(args.joints), str(args.command_rate), "sine"],
                           env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    samples: list[tuple[float, int, int]] = []   # (wall s, rss B, file B)
    t0 = time.monotonic()
    try:
        while True:
            now = time.monotonic() - t0
            if node.poll() is not None:
                print(f"soak_node: the node exited early (rc {node.returncode}):\n{log_path.read_text()[-2000:]}")
                return 1
            size = path.stat().st_size if path.exists() else 0
            samples.append((now, rss_of(node.pid), size))
            if len(samples) % max(1, int(60 / args.sample)) == 1:
                print(f"  t={now:7.1f} s  node rss={samples[-1][1] / 1e6:8.2f} MB  file={size / 1e6:9.2f} MB",
                      flush=True)
            if now >= args.duration:
                break
            time.sleep(max(0.0, t0 + len(samples) * args.sample - time.monotonic()))
    finally:
        wall = time.monotonic() - t0
        ctl.send_signal(signal.SIGINT)
        node.send_signal(signal.SIGINT)
        try:
            node.wait(timeout=120)
        except subprocess.TimeoutExpired:
            node.kill()
            node.wait()
        log.close()
        try:
            ctl.wait(timeout=30)
        except subprocess.TimeoutExpired:
            ctl.kill()
    fit = [s for s in samples if s[0] >= args.warmup]
    b, se = slope([s[0] for s in fit], [s[1] for s in fit])
    fb, _ = slope([s[0] for s in fit], [s[2] for s in fit])
    counts = message_counts(path)
    js = next((n for t, n in counts.items() if t.endswith("/joint_states")), 0)
    cm = next((n for t, n in counts.items() if t.endswith("/commands")), 0)
    print(f"soak_node: {wall:.0f} s wall; node exit code {node.returncode}; {sum(counts.values())} messages "
          f"recorded: joint_states {js} ({js / wall:.1f} per wall second, {js / wall / 10:.2f} % of 1 kHz), "
          f"commands {cm} ({cm / wall:.1f} per wall second)")
    print(f"  node RSS {samples[0][1] / 1e6:.2f} MB at start, {fit[0][1] / 1e6:.2f} MB after warm-up, "
          f"{samples[-1][1] / 1e6:.2f} MB at end")
    print(f"  RSS slope after {args.warmup:g} s warm-up: {b / 1e3:+.3f} kB/s (standard error {se / 1e3:.3f} kB/s, "
          f"{len(fit)} samples) = {b * 3600 / 1e6:+.2f} MB per hour")
    print(f"  file: {path.stat().st_size / 1e6:.1f} MB ({fb / 1e6:.3f} MB/s); RSS growth per MB written "
          f"{b / fb * 1e3 if fb else float('nan'):+.2f} kB/MB")
    print(f"  load average at end {load()}")
    tail = [line for line in log_path.read_text().splitlines() if "recording" in line][-2:]
    for line in tail:
        print(f"  node: {line[:200]}")
    if not args.keep:
        path.unlink(missing_ok=True)
        log_path.unlink(missing_ok=True)
        if args.out is None:
            out_dir.rmdir()
    else:
        print(f"  kept {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
