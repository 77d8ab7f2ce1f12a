"""MCAP write throughput: bldc_actuator.recording.McapRecorder vs raw mcap.Writer + serialize_message.

Prints messages/s and MB/s (file bytes) for
  1. a 1-joint sensor_msgs/JointState stream,
  2. the node's full default topic set per 1 ms period: joint_states (JointState), ~/phase_currents
     (Float64MultiArray, 3 values), ~/q_axis_state (Float64MultiArray, 15 labelled values),
     ~/winding_temperature and ~/housing_temperature (Temperature), plus /diagnostics (DiagnosticArray,
     ~20 key values) every 100 periods (10 Hz),
each with zstd (the recorder's default) and without compression, and the crash-loss figure: how many
milliseconds of simulated data one chunk holds at the node's default rates.

No assertions: figures only. Usage: .venv/bin/python benchmarks/bench_mcap.py [--periods N] [--repeat R]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from mcap.writer import CompressionType, Writer  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from sensor_msgs.msg import JointState, Temperature  # noqa: E402
from std_msgs.msg import Float64MultiArray, MultiArrayDimension  # noqa: E402

from bldc_actuator.recording import (  # noqa: E402
    DEFAULT_CHUNK_SIZE, McapRecorder, message_definition, qos_yaml, type_hash, type_name,
)

Q_AXIS_FIELDS = ("i_q", "i_d", "i_q_ref", "v_q", "v_d", "v_limit_q", "bus_voltage", "v_magnitude_q", "omega",
                 "torque_em", "current_limit_effective", "joule_power", "resistance_phase", "voltage_saturated",
                 "tripped")
PHASE_FIELDS = ("i_phase_a", "i_phase_b", "i_phase_c")
MB = 1e6


def labelled(labels):
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=",".join(labels), size=len(labels), stride=len(labels))]
    return msg


def stamp(msg, t_ns):
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)


def joint_stream(n):
    """[(topic, msg, t_ns)] for n 1-joint JointState messages at 1 kHz."""
    out = []
    for i in range(n):
        t = i * 1_000_000
        m = JointState(name=["joint"], position=[0.001 * i], velocity=[1.0 + 1e-6 * i], effort=[0.25])
        m.header.frame_id = "joint"
        stamp(m, t)
        out.append(("/joint_states", m, t))
    return out


def node_stream(periods):
    """[(topic, msg, t_ns)] of the node's default outputs over ``periods`` 1 ms periods."""
    out = []
    for i in range(periods):
        t = i * 1_000_000
        j = JointState(name=["joint"], position=[0.001 * i], velocity=[1.0], effort=[0.25])
        j.header.frame_id = "joint"
        stamp(j, t)
        ph = labelled(PHASE_FIELDS)
        ph.data = [1.0 + i, -0.5, -0.5 - i]
        q = labelled(Q_AXIS_FIELDS)
        q.data = [0.1 * k + 1e-3 * i for k in range(len(Q_AXIS_FIELDS))]
        tw = Temperature(temperature=25.0 + 1e-4 * i, variance=0.0)
        tw.header.frame_id = "joint"
        stamp(tw, t)
        th = Temperature(temperature=25.0 + 1e-5 * i, variance=0.0)
        th.header.frame_id = "joint"
        stamp(th, t)
        out += [("/joint_states", j, t), ("/actuator_node/phase_currents", ph, t),
                ("/actuator_node/q_axis_state", q, t), ("/actuator_node/winding_temperature", tw, t),
                ("/actuator_node/housing_temperature", th, t)]
        if i % 100 == 0:
            d = DiagnosticArray(status=[DiagnosticStatus(
                level=b"\x00", name="/actuator_node: actuator", message="OK", hardware_id="joint",
                values=[KeyValue(key=f"value_{k} [unit]", value=f"{k * 1.2345:.4f}") for k in range(20)])])
            stamp(d, t)
            out.append(("/diagnostics", d, t))
    return out


def bench_recorder(stream, path, compression):
    t0 = time.perf_counter()
    with McapRecorder(path, compression=compression) as rec:
        for topic, msg, t in stream:
            rec.write(topic, msg, t)
    return time.perf_counter() - t0


def bench_raw(stream, path, compression):
    kind = {"zstd": CompressionType.ZSTD, "none": CompressionType.NONE}[compression]
    t0 = time.perf_counter()
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=DEFAULT_CHUNK_SIZE, compression=kind)
        writer.start(profile="ros2", library="bench")
        schemas, channels, seq = {}, {}, {}
        try:
            for topic, msg, t in stream:
                cid = channels.get(topic)
                if cid is None:
                    name = type_name(msg)
                    if name not in schemas:
                        schemas[name] = writer.register_schema(name, "ros2msg", message_definition(name).encode())
                    cid = channels[topic] = writer.register_channel(
                        topic, "cdr", schemas[name],
                        {"offered_qos_profiles": qos_yaml(None), "topic_type_hash": type_hash(name)})
                    seq[cid] = 0
                seq[cid] += 1
                writer.add_message(cid, log_time=t, data=serialize_message(msg), publish_time=t, sequence=seq[cid])
        finally:
            writer.finish()
    return time.perf_counter() - t0


def serialize_only(stream):
    t0 = time.perf_counter()
    for _, msg, _ in stream:
        serialize_message(msg)
    return time.perf_counter() - t0


def report(label, stream, tmp, repeat):
    n = len(stream)
    print(f"\n{label}: {n} messages")
    print(f"  {'writer':<34} {'msg/s':>10} {'MB/s':>8} {'file MB':>8}")
    t = min(serialize_only(stream) for _ in range(repeat))
    print(f"  {'serialize_message only':<34} {n / t:>10.0f} {'':>8} {'':>8}")
    for compression in ("zstd", "none"):
        for name, fn in (("McapRecorder", bench_recorder), ("raw mcap.Writer + serialize", bench_raw)):
            path = tmp / f"{name.split()[0]}_{compression}.mcap"
            t = min(fn(stream, path, compression) for _ in range(repeat))
            size = path.stat().st_size
            print(f"  {f'{name} ({compression})':<34} {n / t:>10.0f} {size / MB / t:>8.2f} {size / MB:>8.2f}")


def chunk_figure(stream, sim_seconds):
    """Bytes per simulated second inside chunks (uncompressed, what chunk_size counts) and in the file."""
    records = sum(len(serialize_message(m)) + 31 for _, m, _ in stream)
    per_s = records / sim_seconds
    print(f"\nnode default topic set: {len(stream) / sim_seconds:.0f} messages per simulated second, "
          f"{per_s / MB:.3f} MB/s of message records (uncompressed chunk content)")
    print(f"  chunk_size {DEFAULT_CHUNK_SIZE // 1024} KiB holds {DEFAULT_CHUNK_SIZE / per_s * 1e3:.0f} ms "
          f"of simulated data: the most a crash can lose (or flush_interval = 1 s of wall time, if shorter)")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--periods", type=int, default=10_000,
                        help="1 ms periods of the node topic set (default 10000)")
    parser.add_argument("--joint", type=int, default=50_000, help="JointState messages (default 50000)")
    parser.add_argument("--repeat", type=int, default=3, help="best of R runs (default 3)")
    args = parser.parse_args(argv)
    print(f"python {sys.version.split()[0]}, chunk_size {DEFAULT_CHUNK_SIZE} B, best of {args.repeat}")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        report("1-joint JointState", joint_stream(args.joint), tmp, args.repeat)
        stream = node_stream(args.periods)
        report(f"node default topic set ({args.periods} periods of 1 ms)", stream, tmp, args.repeat)
        chunk_figure(stream, args.periods * 1e-3)
    return 0


if __name__ == "__main__":
    sys.exit(main())
