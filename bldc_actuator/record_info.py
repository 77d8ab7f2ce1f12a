"""``bldc-actuator record-info FILE [--json] [--foxglove-layout OUT]``: what an MCAP recording holds.

Prints the topics (type, message count, rate), start time, duration and message totals, the key
parameters of the run (motor preset values: winding, K_t_q, R_phase, L_q, pole pairs, ...; bus voltage;
gear ratio) and whose they are (the joint's name; a recording of several joints shows them per joint), and
any issues: an unfinalized file (a crashed or killed recorder) is said so clearly and still read up to its
last complete chunk; a missing parameters record, lost messages (sequence gaps), time going backwards,
topics without a schema. Reads without decoding messages (no rclpy needed).

``--foxglove-layout OUT`` also writes a Foxglove layout for the joints and topics this recording holds (one
tab per joint for a robot; only topics that are in the file), see :mod:`bldc_actuator.recording.foxglove`.

Exit status: 0 when the file could be read (issues are printed, not fatal), 2 for a missing or non-MCAP
file (message on stderr). ``--json`` prints :func:`bldc_actuator.recording.summarize` as JSON instead.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
from pathlib import Path
from typing import Any, TextIO

#: parameters shown in the text report, in this order (all of them are in --json)
KEY_PARAMETERS = (
    "preset",
    "motor.winding", "motor.pole_pairs", "motor.torque_constant_q", "motor.phase_resistance",
    "motor.q_inductance", "motor.rotor_inertia", "motor.viscous_damping", "motor.reference_temperature",
    "drive.bus_voltage", "drive.current_limit", "drive.current_loop_rate", "gear.gear_ratio",
    "thermal.ambient_temperature",
)
SYMBOLS = {
    "motor.torque_constant_q": "K_t_q", "motor.phase_resistance": "R_phase", "motor.q_inductance": "L_q",
    "motor.rotor_inertia": "J", "motor.viscous_damping": "b", "drive.bus_voltage": "V_bus",
    "gear.gear_ratio": "N", "motor.pole_pairs": "p",
}
#: log times above this (2001-09-09) are taken as wall-clock epoch times, below as simulation time
EPOCH_THRESHOLD_NS = 1_000_000_000 * 1_000_000_000


def register(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "record-info",
        help="summarise an MCAP recording (topics, rates, parameters, issues)",
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("file", metavar="FILE", help="MCAP file (.mcap) written by actuator_node or any ROS 2 recorder")
    parser.add_argument("--json", action="store_true", help="print the full summary as JSON")
    parser.add_argument("--foxglove-layout", metavar="OUT", type=Path,
                        help="also write a Foxglove layout (JSON) for the joints and topics of this recording")
    parser.set_defaults(func=run)
    return parser


def _time(t_ns: int | None) -> str:
    if t_ns is None:
        return "-"
    if t_ns >= EPOCH_THRESHOLD_NS:
        stamp = datetime.datetime.fromtimestamp(t_ns * 1e-9, tz=datetime.timezone.utc)
        return f"{t_ns * 1e-9:.6f} s ({stamp.isoformat(timespec='milliseconds')})"
    return f"{t_ns * 1e-9:.6f} s (simulation time)"


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} B"


def _value(key: str, value: Any) -> str:
    from .params import SPECS

    spec = SPECS.get(key)
    unit = f" {spec.unit}" if spec is not None and spec.unit else ""
    if isinstance(value, float):
        return f"{value:.6g}{unit}"
    if value == "" or value is None:
        return "(not set)"
    return f"{value}{unit}"


def recorded_joints(summary: dict[str, Any]) -> list[str]:
    """The joints whose parameters a recording holds: the ``joints`` parameter of a robot recording (each with
    ``joint.<name>.*``), else the single joint's name (``node.joint_name`` or the ``joint_name`` metadata);
    [] when the recording does not say."""
    params = summary.get("parameters") or {}
    joints = params.get("joints")
    if isinstance(joints, list) and len(joints) > 1:
        return [str(j) for j in joints]
    if isinstance(joints, list) and len(joints) == 1:
        return [str(joints[0])]
    name = params.get("node.joint_name") or summary.get("metadata", {}).get("joint_name")
    return [str(name)] if name else []


def report(summary: dict[str, Any], out: TextIO) -> None:
    """The human-readable report of :func:`recording.summarize`'s dict."""
    w = out.write
    state = "finalized" if summary["finalized"] else "NOT FINALIZED"
    w(f"File:       {summary['path']}  ({_size(summary['file_size'])}, {state})\n")
    w(f"Writer:     {summary['library'] or '-'}  (profile {summary['profile'] or '-'})\n")
    w(f"Start:      {_time(summary['start_ns'])}\n")
    w(f"Duration:   {summary['duration_s']:.6f} s\n")
    topics = summary["topics"]
    w(f"Messages:   {summary['message_count']} on {len(topics)} topic(s)\n\n")
    if topics:
        tw = max(5, *(len(t) for t in topics))
        yw = max(4, *(len(v["type"]) for v in topics.values()))
        w(f"  {'topic':<{tw}}  {'type':<{yw}}  {'count':>9}  {'rate [Hz]':>10}\n")
        for topic, info in topics.items():
            rate = f"{info['rate_hz']:.3f}" if info["rate_hz"] else "-"
            w(f"  {topic:<{tw}}  {info['type']:<{yw}}  {info['count']:>9}  {rate:>10}\n")
        w("\n")
    params = summary["parameters"]
    joints = recorded_joints(summary)
    if params is None:
        w("Parameters: none recorded\n")
    elif len(joints) > 1:
        w(f"Parameters: {len(params)} recorded for {len(joints)} joints ({', '.join(joints)}); key values of "
          f"each joint below (all with --json: joint.<name>.<parameter>)\n")
        rows = [(k, [params.get(f"joint.{j}.{k}") for j in joints]) for k in KEY_PARAMETERS]
        rows = [(k, vals) for k, vals in rows if any(v is not None for v in vals)]
        kw = max([len("parameter")] + [len(k) for k, _ in rows])
        cells = [[_value(k, v) if v is not None else "-" for v in vals] for k, vals in rows]
        cw = [max([len(j)] + [len(c[n]) for c in cells]) for n, j in enumerate(joints)]
        w((f"  {'parameter':<{kw}}  " + "  ".join(f"{j:<{cw[n]}}" for n, j in enumerate(joints))).rstrip() + "\n")
        for (key, _), row in zip(rows, cells):
            line = f"  {key:<{kw}}  " + "  ".join(f"{c:<{cw[n]}}" for n, c in enumerate(row))
            w(f"{line}  {SYMBOLS.get(key, '')}".rstrip() + "\n")
    else:
        whose = f"joint {joints[0]!r}" if joints else "the recorded actuator"
        w(f"Parameters: {len(params)} recorded, of {whose} (key values below; all with --json)\n")
        keys = [k for k in KEY_PARAMETERS if k in params]
        kw = max(len(k) for k in keys) if keys else 0
        for key in keys:
            symbol = SYMBOLS.get(key, "")
            w(f"  {key:<{kw}}  {_value(key, params[key]):<22} {symbol}\n".rstrip() + "\n")
    # a robot's joint_name metadata is the first joint's: the per-joint table above says whose is whose
    hidden = {"recorder", "joint_name"} if len(joints) > 1 else {"recorder"}
    meta = {k: v for k, v in summary["metadata"].items() if k not in hidden and v != ""}
    if meta:
        w("Metadata:\n")
        for key, value in meta.items():
            w(f"  {key}: {value}\n")
    issues = summary["issues"]
    w("Issues:     none\n" if not issues else f"Issues:     {len(issues)}\n")
    for issue in issues:
        w(f"  ! {issue}\n")


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    from .recording import RecordingError, summarize

    out = out or sys.stdout
    try:
        summary = summarize(args.file)
    except RecordingError as exc:
        print(f"bldc-actuator record-info: {exc}", file=sys.stderr)
        return 2
    if args.json:
        json.dump(summary, out, indent=2)
        out.write("\n")
    else:
        report(summary, out)
    if getattr(args, "foxglove_layout", None):
        from .recording.foxglove import write_layout

        found = write_layout(args.file, args.foxglove_layout)
        names = ", ".join(j.name or j.prefix for j in found.joints) or "none"
        # on stderr with --json, so that stdout stays one JSON document
        print(f"wrote Foxglove layout {args.foxglove_layout} (joints: {names}; import it in Foxglove with "
              f"Layouts > Import)", file=sys.stderr if args.json else out)
        for note in found.notes:
            print(f"  ! layout: {note}", file=sys.stderr if args.json else out)
    return 0
