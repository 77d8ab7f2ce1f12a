#!/usr/bin/env python3
"""Recording soak (a script, not a test): does the recording process's memory stay flat over hours?

    .venv/bin/python benchmarks/soak_recording.py [--duration 3600] [--joints 12] [--sample 5] [--warmup 60]
                                                  [--out DIR] [--keep] [--tracemalloc N]

What runs: the node's per-period work without the ROS graph, in one process: a
:class:`~bldc_actuator.scheduler.Scheduler` over ``--joints`` ak80_9 joints against the wall clock (1 kHz, time
factor 1), one ``~/commands`` array per period (a +-0.5 N*m square wave at 2 Hz, recorded as the node records its
subscriptions), and on every period what ``actuator_node`` publishes while recording, serialised with rclpy and
handed to :class:`~bldc_actuator.recording.McapRecorder` as CDR bytes (``write_serialized``, as the node does):
``/bldc_actuator/joint_states`` (one JointState of every joint), per joint ``phase_currents``, ``q_axis_state``
(labelled Float64MultiArray), ``winding_temperature`` and ``housing_temperature`` (Temperature) every period,
``/diagnostics`` (one status of ~20 key values per joint) at 10 Hz. The recorder's defaults (256 KiB zstd chunks,
1 s flush interval). The topics are registered up front as the node does (command topics included).

Printed: the RSS every ``--sample`` wall seconds (from /proc/self/statm), the RSS slope by least squares after
``--warmup`` seconds [kB/s] (with its standard error), the loop rate held (simulated periods per wall second),
the scheduler's slips (wake-ups that found more than a batch due and dropped the debt), the file written
(bytes, chunks, messages) and the load average at start and end. ``--tracemalloc N``: also take a tracemalloc
snapshot every N samples and print the biggest growths between the first and the last snapshot (by allocation
site): how the recorder's memory was traced to its source (tracemalloc slows the loop: figures for rate/slips
are then not representative, and the RSS includes tracemalloc's own tables).
"""

from __future__ import annotations

import argparse
import logging
import os
import resource
import sys
import tempfile
import time
from array import array
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from sensor_msgs.msg import JointState, Temperature  # noqa: E402
from std_msgs.msg import Empty, Float64, Float64MultiArray, MultiArrayDimension  # noqa: E402

from bldc_actuator.params import load_preset, to_flat  # noqa: E402
from bldc_actuator.plant import ActuatorPlant  # noqa: E402
from bldc_actuator.recording import McapRecorder  # noqa: E402
from bldc_actuator.scheduler import Scheduler, SchedulerConfig  # noqa: E402

NS = "/bldc_actuator"
Q_AXIS_FIELDS = ("i_q", "i_d", "i_q_ref", "v_q", "v_d", "v_limit_q", "bus_voltage", "v_magnitude_q",
                 "omega", "torque_em", "current_limit_effective", "joule_power", "resistance_phase",
                 "voltage_saturated", "tripped")
PHASE_FIELDS = ("i_phase_a", "i_phase_b", "i_phase_c")
PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE


def labelled(labels) -> Float64MultiArray:
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=",".join(labels), size=len(labels), stride=len(labels))]
    return msg


class NodeLikeRecording:
    """The node's recording work per period (see the module docstring), over a scheduler and a recorder."""

    def __init__(self, joints: int, path: Path):
        names = [f"j{k}" for k in range(joints)]
        self.plant = ActuatorPlant({n: load_preset("ak80_9") for n in names})
        self.sched = Scheduler(self.plant, SchedulerConfig(name_joints=joints > 1),
                               log=logging.getLogger("soak_recording"), on_period=self.on_period)
        self.rec = McapRecorder(path, parameters=to_flat(self.plant.params(names[0])),
                                metadata={"node": NS, "joints": ",".join(names)})
        self.t_joint = f"{NS}/joint_states"
        self.t_cmd = f"{NS}/commands"
        self.rec.add_topic(self.t_joint, JointState)
        self.rec.add_topic("/diagnostics", DiagnosticArray)
        self.rec.add_topic(self.t_cmd, Float64MultiArray)
        self.detail = []
        for k, n in enumerate(names):
            ph, q = labelled(PHASE_FIELDS), labelled(Q_AXIS_FIELDS)
            tw, th = Temperature(), Temperature()
            tw.header.frame_id = th.header.frame_id = n
            for suffix, typ in (("phase_currents", Float64MultiArray), ("q_axis_state", Float64MultiArray),
                                ("winding_temperature", Temperature), ("housing_temperature", Temperature),
                                ("current_command", Float64), ("torque_command", Float64),
                                ("load_torque", Float64), ("reset_fault", Empty)):
                self.rec.add_topic(f"{NS}/{n}/{suffix}", typ)
            self.detail.append((k, f"{NS}/{n}/", ph, q, tw, th))
        self.m_joint = JointState(name=names)
        self.m_joint.header.frame_id = ""
        self.m_diag: DiagnosticArray | None = None
        self.m_cmd = Float64MultiArray()
        self.sched.detail_wanted = True

    def on_period(self, t_ns: int, outs, detail: bool, diag: bool) -> None:
        rec, sched = self.rec, self.sched
        sec, nsec = divmod(t_ns, 1_000_000_000)
        m = self.m_joint
        m.header.stamp.sec, m.header.stamp.nanosec = sec, nsec
        m.position, m.velocity, m.effort = sched.position, sched.velocity, sched.effort
        rec.write_serialized(self.t_joint, serialize_message(m), t_ns)
        if detail:
            if outs is None:
                outs = self.plant.all_outputs()
            for k, prefix, ph, q, tw, th in self.detail:
                o = outs[k]
                ph.data = array("d", [o[f] for f in PHASE_FIELDS])
                q.data = array("d", [o[f] for f in Q_AXIS_FIELDS])
                tw.header.stamp.sec = th.header.stamp.sec = sec
                tw.header.stamp.nanosec = th.header.stamp.nanosec = nsec
                tw.temperature = float(o["T_winding"])
                th.temperature = float(o["T_housing"])
                rec.write_serialized(prefix + "phase_currents", serialize_message(ph), t_ns)
                rec.write_serialized(prefix + "q_axis_state", serialize_message(q), t_ns)
                rec.write_serialized(prefix + "winding_temperature", serialize_message(tw), t_ns)
                rec.write_serialized(prefix + "housing_temperature", serialize_message(th), t_ns)
        if diag:
            health = sched.health(outs, values={"recording": str(rec.path)})
            if self.m_diag is None:
                self.m_diag = DiagnosticArray(status=[
                    DiagnosticStatus(name=f"{NS}: {h.joint}", hardware_id=h.joint,
                                     values=[KeyValue(key=key, value=v) for key, v in h.values.items()])
                    for h in health])
            for st, h in zip(self.m_diag.status, health):
                st.level = bytes([h.level])
                st.message = h.message
                for kv, v in zip(st.values, h.values.values()):
                    kv.value = v
            self.m_diag.header.stamp.sec, self.m_diag.header.stamp.nanosec = sec, nsec
            rec.write_serialized("/diagnostics", serialize_message(self.m_diag), t_ns)

    def command(self, values: list[float]) -> None:
        self.m_cmd.data = values
        self.rec.write_serialized(self.t_cmd, serialize_message(self.m_cmd), self.sched.t_ns)
        self.sched.commands(values, "~/commands")


def slope(ts, ys) -> tuple[float, float]:
    """Least-squares slope and its standard error."""
    t, y = np.asarray(ts, float), np.asarray(ys, float)
    if len(t) < 3:
        return float("nan"), float("nan")
    A = np.vstack([t - t.mean(), np.ones_like(t)]).T
    coef, res, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ coef
    s2 = float(resid @ resid) / (len(t) - 2)
    return float(coef[0]), float(np.sqrt(s2 / float(((t - t.mean()) ** 2).sum())))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="wall seconds [3600]")
    ap.add_argument("--joints", type=int, default=12)
    ap.add_argument("--sample", type=float, default=5.0, help="wall seconds between RSS samples [5]")
    ap.add_argument("--warmup", type=float, default=60.0, help="wall seconds left out of the slope fit [60]")
    ap.add_argument("--out", type=Path, default=None, help="directory for the recording [a temporary one]")
    ap.add_argument("--keep", action="store_true", help="keep the recording file")
    ap.add_argument("--tracemalloc", type=int, default=0, metavar="N",
                    help="tracemalloc snapshot every N samples; print the growth by allocation site")
    args = ap.parse_args()
    if args.duration <= args.warmup:
        ap.error("--duration must exceed --warmup")

    out_dir = args.out or Path(tempfile.mkdtemp(prefix="soak_recording_"))
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "soak.mcap"
    run = NodeLikeRecording(args.joints, path)
    sched, rec = run.sched, run.rec
    high, low = [0.5] * args.joints, [-0.5] * args.joints
    snaps = []
    if args.tracemalloc:
        import tracemalloc

        tracemalloc.start(1)

    uptime0 = open("/proc/loadavg").read().split()[:3]
    print(f"soak_recording: {args.joints} joints (ak80_9), 1 kHz against the wall clock, recording every "
          f"node topic to {path}; duration {args.duration:.0f} s, RSS every {args.sample:g} s, warm-up "
          f"{args.warmup:g} s; pid {os.getpid()}, nice {os.nice(0)}; load average at start {' '.join(uptime0)}",
          flush=True)
    samples = []   # (wall s, rss B, file B, periods, slips)
    period_ns = sched.config.period_ns
    sched.start()
    t0 = time.monotonic_ns()
    next_wake = t0
    next_sample = t0
    end = t0 + int(args.duration * 1e9)
    k = 0
    late_wakes = 0
    while True:
        now = time.monotonic_ns()
        if now >= next_sample:
            samples.append(((now - t0) * 1e-9, rss_bytes(), rec.bytes_written, sched.periods, sched.slips))
            s = samples[-1]
            if len(samples) % max(1, int(60 / args.sample)) == 1:
                print(f"  t={s[0]:7.1f} s  rss={s[1] / 1e6:8.2f} MB  file={s[2] / 1e6:9.2f} MB  "
                      f"periods={s[3]}  slips={s[4]}", flush=True)
            if args.tracemalloc and (len(samples) - 1) % args.tracemalloc == 0 and s[0] >= args.warmup:
                snaps[1 if snaps else 0:] = [(s[0], tracemalloc.take_snapshot())]   # the first and the latest
            next_sample += int(args.sample * 1e9)
            if now >= end:
                break
        run.command(high if (k // 250) % 2 else low)
        k += 1
        sched.tick()
        next_wake += period_ns
        now = time.monotonic_ns()
        if next_wake > now:
            time.sleep((next_wake - now) * 1e-9)
        elif now - next_wake > 10 * period_ns:   # far behind: re-base the wake-ups (the scheduler drops debt)
            late_wakes += 1
            next_wake = now
    wall = (time.monotonic_ns() - t0) * 1e-9
    rec.close()
    uptime1 = open("/proc/loadavg").read().split()[:3]
    size = path.stat().st_size
    fit = [s for s in samples if s[0] >= args.warmup]
    b, se = slope([s[0] for s in fit], [s[1] for s in fit])
    fb, _ = slope([s[0] for s in fit], [s[2] for s in fit])
    bp, _ = slope([s[3] * period_ns * 1e-9 for s in fit], [s[1] for s in fit])   # per simulated second
    rate = sched.periods / wall
    print(f"soak_recording: {wall:.0f} s wall, {sched.periods} periods: {rate:.1f} periods per wall second "
          f"({rate / 1e3 * 100:.2f} % of 1 kHz), {sched.slips} scheduler slips, {late_wakes} loop re-bases")
    print(f"  RSS {samples[0][1] / 1e6:.2f} MB at start, {fit[0][1] / 1e6:.2f} MB after warm-up, "
          f"{samples[-1][1] / 1e6:.2f} MB at end; max RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e6:.2f} MB")
    print(f"  RSS slope after {args.warmup:g} s warm-up: {b / 1e3:+.3f} kB/s (standard error {se / 1e3:.3f} kB/s, "
          f"{len(fit)} samples) = {b * 3600 / 1e6:+.2f} MB per hour; per simulated second {bp / 1e3:+.3f} kB "
          f"(the slope at 1 kHz held)")
    print(f"  file: {size / 1e6:.1f} MB written ({fb / 1e6:.3f} MB/s), {rec.messages_written} messages; "
          f"RSS growth per MB written {b / fb * 1e3 if fb else float('nan'):+.2f} kB/MB")
    print(f"  load average at end {' '.join(uptime1)}")
    if snaps and len(snaps) >= 2:
        (ta, a), (tb, bsnap) = snaps[0], snaps[-1]
        diff = bsnap.compare_to(a, "lineno")
        total = sum(st.size_diff for st in diff)
        print(f"  tracemalloc: traced memory grew {total / 1e3:+.1f} kB from {ta:.0f} s to {tb:.0f} s "
              f"({total / (tb - ta) / 1e3:+.3f} kB/s); top 8 allocation lines:")
        for stat in diff[:8]:
            frame = stat.traceback[0]
            print(f"    {stat.size_diff / 1e3:+9.1f} kB  {stat.count_diff:+7d} blocks  "
                  f"{frame.filename.split('site-packages/')[-1]}:{frame.lineno}")
    if not args.keep:
        path.unlink()
        if args.out is None:
            out_dir.rmdir()
    else:
        print(f"  kept {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
