"""MCAP recordings: values survive a round trip through three independent readers, parameters come back
equal, exceptions / crashes / signals still leave readable files, record-info reports them.

In-process (no ROS graph): messages are constructed directly. Values are compared, never bytes (rclpy
leaves CDR padding bytes uninitialised). Reader compatibility found here (mcap 1.6, mcap-ros2-support 0.6,
rosbags 0.11):

* our ``read_recording`` (rclpy and mcap_ros2 decoders), ``mcap_ros2`` (make_reader + DecoderFactory) and
  ``rosbags`` (``rosbag2.Reader`` and ``highlevel.AnyReader`` open a single ``.mcap`` file directly, no
  metadata.yaml directory needed) decode all five types, DiagnosticStatus ``byte level`` included: rclpy
  gives ``b'\\x02'``, mcap_ros2 and rosbags give ``2``. (mcap_ros2 can DECODE ``byte``; its encoder cannot
  take rclpy's ``bytes`` values, which is why the recorder serialises with rclpy.)
* rclpy's Fast-CDR aligns EMPTY sequences of 8-byte elements (JointState with empty velocity/effort,
  empty Float64MultiArray, rcl_interfaces/ParameterEvent): rclpy and mcap_ros2 decode those, rosbags 0.11
  raises "CDR message size mismatch". The node's outputs always fill their arrays; /parameter_events
  cannot be decoded by rosbags.
* an unfinalized file (crash): only ``read_recording``/``record-info`` recover it; rosbags refuses it
  ("File end magic is invalid") and mcap_ros2's reader fails on the cut record.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import scaled

from bldc_actuator import params as P
from bldc_actuator.recording import (
    DEFAULT_CHUNK_SIZE, METADATA_NAME, PARAMETERS_KEY, McapRecorder, RecorderClosedError, RecordingError,
    as_level, message_definition, parameters_from_recording, qos_yaml, read_raw, read_recording, summarize,
    type_hash,
)

REPO = Path(__file__).resolve().parents[1]
SEC = 1_000_000_000


@pytest.fixture
def msgs():
    """The message modules (skips without rclpy)."""
    pytest.importorskip("rclpy", reason="rclpy not importable (pip install .[wheels] or source ROS)")
    from types import SimpleNamespace

    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from sensor_msgs.msg import JointState, Temperature
    from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension

    return SimpleNamespace(JointState=JointState, Temperature=Temperature, Float64=Float64,
                           Float64MultiArray=Float64MultiArray, MultiArrayDimension=MultiArrayDimension,
                           DiagnosticArray=DiagnosticArray, DiagnosticStatus=DiagnosticStatus, KeyValue=KeyValue)


def _stamp(msg, t_ns):
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, SEC)
    return msg


# ------------------------------------------------------------------------------------ reference data

N = 40  # messages per 1 kHz topic
T0 = 3 * SEC + 250  # simulation time of the first message (not a round number on purpose)


def expected():
    """Plain-Python expected values per topic: [(t_ns, dict)]."""
    js, arr, temp, f64, diag = [], [], [], [], []
    for i in range(N):
        t = T0 + i * 1_000_000
        js.append((t, {"stamp": divmod(t, SEC), "frame_id": "j1", "name": ["j1"], "position": [0.5 + 0.01 * i],
                       "velocity": [-1.25 * i], "effort": [1e-3 * i * i]}))
        arr.append((t, {"label": "i_phase_a,i_phase_b,i_phase_c", "data": [i + 0.1, -0.5 * i, math.pi * i]}))
        f64.append((t, {"data": 2.0 ** -i if i % 2 else -1e300 * (i + 1) / N}))
    for i in range(0, N, 10):
        t = T0 + i * 1_000_000
        temp.append((t, {"stamp": divmod(t, SEC), "temperature": 25.0 + 0.125 * i, "variance": 0.0}))
        diag.append((t, {"stamp": divmod(t, SEC), "level": i // 10 % 4, "name": f"/a: actuator {i}",
                         "message": "ünïcode OK" if i else "", "hardware_id": "j1",
                         "values": [(f"k{k} [A]", f"{k * 0.5:.3f}") for k in range(i // 10 + 1)]}))
    return {"/joint_states": js, "/actuator_node/phase_currents": arr, "/actuator_node/winding_temperature": temp,
            "/actuator_node/current_command": f64, "/diagnostics": diag}


TYPES = {"/joint_states": "sensor_msgs/msg/JointState",
         "/actuator_node/phase_currents": "std_msgs/msg/Float64MultiArray",
         "/actuator_node/winding_temperature": "sensor_msgs/msg/Temperature",
         "/actuator_node/current_command": "std_msgs/msg/Float64",
         "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}


def build(m, topic, v):
    if topic == "/joint_states":
        msg = _stamp(m.JointState(name=v["name"], position=v["position"], velocity=v["velocity"],
                                  effort=v["effort"]), 0)
        msg.header.stamp.sec, msg.header.stamp.nanosec = v["stamp"]
        msg.header.frame_id = v["frame_id"]
    elif topic.endswith("phase_currents"):
        msg = m.Float64MultiArray(data=v["data"])
        msg.layout.dim = [m.MultiArrayDimension(label=v["label"], size=3, stride=3)]
    elif topic.endswith("temperature"):
        msg = m.Temperature(temperature=v["temperature"], variance=v["variance"])
        msg.header.stamp.sec, msg.header.stamp.nanosec = v["stamp"]
    elif topic.endswith("current_command"):
        msg = m.Float64(data=v["data"])
    else:
        msg = m.DiagnosticArray(status=[m.DiagnosticStatus(
            level=bytes([v["level"]]), name=v["name"], message=v["message"], hardware_id=v["hardware_id"],
            values=[m.KeyValue(key=k, value=x) for k, x in v["values"]])])
        msg.header.stamp.sec, msg.header.stamp.nanosec = v["stamp"]
    return msg


def values_of(topic, msg):
    """Decoded message (rclpy, mcap_ros2 or rosbags object) -> the plain dict of :func:`expected`."""
    if topic == "/joint_states":
        h = msg.header
        return {"stamp": (h.stamp.sec, h.stamp.nanosec), "frame_id": h.frame_id, "name": list(msg.name),
                "position": [float(x) for x in msg.position], "velocity": [float(x) for x in msg.velocity],
                "effort": [float(x) for x in msg.effort]}
    if topic.endswith("phase_currents"):
        return {"label": msg.layout.dim[0].label, "data": [float(x) for x in msg.data]}
    if topic.endswith("temperature"):
        return {"stamp": (msg.header.stamp.sec, msg.header.stamp.nanosec), "temperature": msg.temperature,
                "variance": msg.variance}
    if topic.endswith("current_command"):
        return {"data": msg.data}
    (s,) = msg.status
    return {"stamp": (msg.header.stamp.sec, msg.header.stamp.nanosec), "level": as_level(s.level),
            "name": s.name, "message": s.message, "hardware_id": s.hardware_id,
            "values": [(kv.key, kv.value) for kv in s.values]}


def write_reference(m, path, **kwargs):
    """Write the reference messages interleaved in time order, as the node would."""
    exp = expected()
    events = sorted((t, k, topic, v) for k, (topic, items) in enumerate(exp.items()) for t, v in items)
    rec = McapRecorder(path, **kwargs)
    for topic, type_str in TYPES.items():
        rec.add_topic(topic, type_str)
    for t, _, topic, v in events:
        rec.write(topic, build(m, topic, v), t)
    return rec, exp


def custom_params() -> P.ActuatorParams:
    return P.ActuatorParams().replace(**{
        "motor.winding": "delta", "motor.pole_pairs": 14, "motor.phase_resistance": 0.0871,
        "motor.q_inductance": 3.3e-5, "motor.torque_constant_q": 0.1234, "drive.bus_voltage": 48.0,
        "effects.cogging_order": 42, "effects.cogging_cos": (0.01, 0.002), "effects.cogging_sin": (0.0, -0.003),
        "gear.gear_ratio": 9.0, "load.gravity_torque": -1.5})


def assert_reference(decoded: dict[str, list], exp: dict[str, list], reader: str) -> None:
    assert set(decoded) == set(exp), reader
    for topic, items in exp.items():
        got = decoded[topic]
        assert [t for t, _ in got] == [t for t, _ in items], f"{reader}: log times of {topic}"
        for (t, want), (_, msg) in zip(items, got):
            assert values_of(topic, msg) == want, f"{reader}: {topic} at t={t}"


# ------------------------------------------------------------------------------------------ round trip

@pytest.fixture
def reference_file(msgs, tmp_path):
    path = tmp_path / "ref.mcap"
    rec, exp = write_reference(msgs, path, parameters=custom_params(), metadata={"node": "/actuator_node"})
    rec.close()
    return path, exp


@pytest.mark.parametrize("decoder", ["rclpy", "mcap_ros2", "auto"])
def test_read_recording_gives_back_every_value(reference_file, decoder):
    path, exp = reference_file
    rec = read_recording(path, decoder=decoder)
    assert rec.finalized and rec.issues == []
    assert rec.types == TYPES
    assert set(rec.decoders.values()) == {"mcap_ros2" if decoder == "mcap_ros2" else "rclpy"}
    assert_reference(rec.topics, exp, f"read_recording({decoder})")
    assert rec.start_ns == T0 and rec.end_ns == T0 + (N - 1) * 1_000_000
    assert rec.metadata["node"] == "/actuator_node" and rec.metadata["finalized_by"] == "close()"


def test_read_raw_gives_the_cdr_of_every_message(reference_file):
    """The public undecoded reader (what the diagnosis reads through): per topic, the log times and CDR bytes
    that deserialise to every reference value (byte equality is not expected: Fast-CDR leaves its alignment
    padding uninitialised); a topic filter keeps only those messages; ``keep_messages=False`` still counts
    every message and reads the parameters record."""
    from rclpy.serialization import deserialize_message

    from bldc_actuator.recording import message_class

    path, exp = reference_file
    raw = read_raw(path)
    assert raw.finalized and raw.issues == [] and raw.profile == "ros2"
    by_topic = {raw.channels[cid].topic: got for cid, got in raw.messages.items()}
    assert set(by_topic) == set(exp)
    for topic, items in exp.items():
        assert [t for t, _ in by_topic[topic]] == [t for t, _ in items]
        cls = message_class(TYPES[topic])
        assert [values_of(topic, deserialize_message(d, cls)) for _, d in by_topic[topic]] == [v for _, v in items]
    only = read_raw(path, topics=["/diagnostics"])
    assert [only.channels[c].topic for c in only.messages] == ["/diagnostics"]
    counted = read_raw(path, keep_messages=False)
    assert counted.messages == {}
    assert {counted.channels[c].topic: st[0] for c, st in counted.stats.items()} == {t: len(v) for t, v in exp.items()}
    assert any(name == METADATA_NAME and PARAMETERS_KEY in d for name, d in counted.metadata)


def test_byte_field_types_per_decoder(reference_file):
    path, _ = reference_file
    by_rclpy = read_recording(path, topics=["/diagnostics"], decoder="rclpy")["/diagnostics"]
    by_mcap = read_recording(path, topics=["/diagnostics"], decoder="mcap_ros2")["/diagnostics"]
    assert by_rclpy[1][1].status[0].level == b"\x01"
    assert by_mcap[1][1].status[0].level == 1
    assert list(read_recording(path, topics=["/diagnostics"]).topics) == ["/diagnostics"]


def test_mcap_ros2_reader_decodes_the_file(reference_file):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    path, exp = reference_file
    decoded: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, msg in reader.iter_decoded_messages():
            decoded.setdefault(channel.topic, []).append((message.log_time, msg))
            assert message.publish_time == message.log_time
    assert_reference(decoded, exp, "mcap_ros2")


def test_rosbags_reads_the_single_mcap_file(reference_file):
    rosbags = pytest.importorskip("rosbags")
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Reader

    if ".mcap" not in getattr(Reader, "STORAGE_PLUGINS", {}):  # single-file reading: rosbags 0.11 has it
        pytest.skip(f"rosbags {getattr(rosbags, '__version__', '?')} opens only rosbag2 directories "
                    "(metadata.yaml + files); pin rosbags>=0.11 to read a single .mcap")
    path, exp = reference_file
    with Reader(path) as reader:  # a single .mcap file, no rosbag2 directory / metadata.yaml
        assert reader.message_count == sum(len(v) for v in exp.values())
        assert {c.topic: c.msgtype for c in reader.connections} == TYPES
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        assert qos["/joint_states"][0].depth == 10
        assert qos["/joint_states"][0].reliability.name == "RELIABLE"
        assert qos["/joint_states"][0].durability.name == "VOLATILE"
    decoded: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for conn, t, raw in reader.messages():
            decoded.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
    assert_reference(decoded, exp, f"rosbags {getattr(rosbags, '__version__', '')}")


def test_file_follows_rosbag2_mcap_conventions(reference_file):
    from mcap.reader import make_reader

    path, _ = reference_file
    with open(path, "rb") as f:
        reader = make_reader(f)
        header, summary = reader.get_header(), reader.get_summary()
        metadata = list(reader.iter_metadata())
    assert header.profile == "ros2" and header.library.startswith("bldc_actuator ")
    assert summary.statistics.message_count == sum(len(v) for v in expected().values())
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(schemas) == set(TYPES.values())  # one schema per type, named pkg/msg/Type
    assert {s.encoding for s in schemas.values()} == {"ros2msg"}
    text = schemas["diagnostic_msgs/msg/DiagnosticArray"].data.decode()
    bar = "\n" + "=" * 80 + "\n"
    # rosbag2's order: root, then dependencies depth first in sorted order, each once
    parts = text.split(bar)
    assert [p.split("\n", 1)[0] for p in parts[1:]] == [
        "MSG: diagnostic_msgs/DiagnosticStatus", "MSG: diagnostic_msgs/KeyValue", "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time"]
    assert "byte level" in parts[1] and "uint32 nanosec" in parts[4]
    assert text == message_definition("diagnostic_msgs/DiagnosticArray")
    import yaml

    for channel in summary.channels.values():
        assert channel.message_encoding == "cdr"
        (profile,) = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert profile["history"] == "keep_last" and profile["reliability"] == "reliable"
        assert profile["deadline"] == {"sec": 9223372036, "nsec": 854775807}
        hash_ = channel.metadata["topic_type_hash"]
        assert hash_.startswith("RIHS01_") and len(hash_) == 7 + 64
        assert hash_ == type_hash(schemas_by_id(summary)[channel.schema_id])
    names = [m.name for m in metadata]
    assert "rosbag2" not in names and names[-1] == METADATA_NAME


def schemas_by_id(summary):
    return {i: s.name for i, s in summary.schemas.items()}


def test_qos_yaml_from_an_rclpy_profile(msgs):
    from rclpy.duration import Duration
    from rclpy.qos import QoSProfile, qos_profile_sensor_data

    text = qos_yaml(QoSProfile(depth=3, deadline=Duration(seconds=1, nanoseconds=5)))
    assert text.splitlines()[:5] == ["- history: keep_last", "  depth: 3", "  reliability: reliable",
                                     "  durability: volatile", "  deadline:"]
    assert "    sec: 1\n    nsec: 5\n  lifespan:" in text and not text.endswith("\n")
    assert "reliability: best_effort" in qos_yaml(qos_profile_sensor_data)


# ------------------------------------------------------------------------------------------ parameters

def test_parameters_round_trip_to_equal_actuator_params(reference_file, tmp_path):
    path, _ = reference_file
    p = custom_params()
    assert parameters_from_recording(path) == p
    rec = read_recording(path)
    assert rec.params() == p
    assert rec.parameters == P.to_flat(p)
    extracted = tmp_path / "extracted.yaml"
    extracted.write_text(rec.parameters_yaml)
    assert P.load_yaml(extracted) == p  # "a recording alone is enough to re-simulate it"


def test_node_style_flat_dict_with_node_keys_and_last_value_wins(msgs, tmp_path):
    path = tmp_path / "node.mcap"
    p1 = custom_params()
    flat = {k: (list(v) if isinstance(v, tuple) else v) for k, v in P.to_flat(p1).items()}
    flat.update({"node.publish_rate": 1000.0, "node.joint_name": "j1", "node.lock_step": False, "preset": "ak80_9"})
    with McapRecorder(path, parameters=flat) as rec:
        rec.write("/c", msgs.Float64(data=1.0), 0)
        p2 = p1.replace(**{"drive.bus_voltage": 36.0})
        rec.set_parameters(dict(flat, **{"drive.bus_voltage": 36.0}))
        rec.write("/c", msgs.Float64(data=2.0), 1000)
        rec.set_parameters(dict(flat, **{"drive.bus_voltage": 36.0}))  # unchanged: no new record
    assert parameters_from_recording(path) == p2
    r = read_recording(path)
    assert r.parameters["node.publish_rate"] == 1000.0 and r.parameters["preset"] == "ak80_9"
    assert r.parameters["drive.bus_voltage"] == 36.0
    kinds = [d["record"] for name, d in r.metadata_records if name == METADATA_NAME]
    assert kinds == ["initial", "update", "final"]
    extracted = tmp_path / "x.yaml"
    extracted.write_text(r.parameters_yaml)
    assert P.load_yaml(extracted) == p2  # node.* and preset are non-model sections load_yaml accepts


def test_bad_parameters_and_metadata_are_refused_before_the_file_exists(tmp_path):
    path = tmp_path / "bad.mcap"
    with pytest.raises(P.ParameterError, match="drive.bus_voltage"):
        McapRecorder(path, parameters={"drive.bus_voltage": -5.0})
    with pytest.raises(P.ParameterError, match="motor.not_a_field"):
        McapRecorder(path, parameters={"motor.not_a_field": 1.0})
    with pytest.raises(ValueError, match="reserved"):
        McapRecorder(path, metadata={PARAMETERS_KEY: "x"})
    with pytest.raises(TypeError, match="str"):
        McapRecorder(path, metadata={"n": 3})
    assert not path.exists()


def test_recording_without_parameters_is_reported(msgs, tmp_path):
    path = tmp_path / "nop.mcap"
    with McapRecorder(path) as rec:
        rec.write("/c", msgs.Float64(data=1.0), 5)
    with pytest.raises(RecordingError, match="parameters_yaml"):
        parameters_from_recording(path)
    s = summarize(path)
    assert not s["parameters_present"] and any("parameters" in i for i in s["issues"])


# ------------------------------------------------------------------------------------ API behaviour

def test_recorder_api_contract(msgs, tmp_path):
    path = tmp_path / "api.mcap"
    rec = McapRecorder(path)
    cid = rec.add_topic("/js", "sensor_msgs/JointState")
    assert rec.add_topic("/js", msgs.JointState) == cid  # idempotent, class or name
    with pytest.raises(ValueError, match="already recorded as sensor_msgs/msg/JointState"):
        rec.add_topic("/js", "std_msgs/msg/Float64")
    with pytest.raises(TypeError, match="records sensor_msgs/msg/JointState"):
        rec.write("/js", msgs.Float64(data=1.0), 0)
    with pytest.raises(ValueError, match="t_ns"):
        rec.write("/js", msgs.JointState(), -1)
    with pytest.raises(ValueError, match="t_ns"):
        rec.write("/js", msgs.JointState(), 1.5)
    with pytest.raises(KeyError, match="add_topic"):
        rec.write_serialized("/unknown", b"\x00\x01\x00\x00", 0)
    from rclpy.serialization import serialize_message

    rec.write("/js", msgs.JointState(position=[1.0]), 10)
    rec.write_serialized("/js", serialize_message(msgs.JointState(position=[2.0])), 20)
    rec.write("/auto", msgs.Float64(data=3.0), 30)  # unknown topic: added with the message's type
    assert rec.messages_written == 3 and rec.bytes_written > 3 * 31
    rec.close()
    rec.close()  # idempotent
    with pytest.raises(RecorderClosedError):
        rec.write("/js", msgs.JointState(), 40)
    r = read_recording(path)
    assert [m.position[0] for _, m in r["/js"]] == [1.0, 2.0] and r["/auto"][0][1].data == 3.0
    assert r.types["/auto"] == "std_msgs/msg/Float64"


def test_exception_inside_with_leaves_a_finalized_file(msgs, tmp_path):
    from mcap.reader import make_reader

    path = tmp_path / "exc.mcap"
    with pytest.raises(ZeroDivisionError):
        with McapRecorder(path, parameters=custom_params()) as rec:
            for i in range(100):
                rec.write("/js", msgs.JointState(position=[float(i)]), i * 1000)
            1 / 0
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.message_count == 100
    r = read_recording(path)
    assert r.finalized and r.issues == [] and r.metadata["finalized_by"] == "exception ZeroDivisionError"
    assert [m.position[0] for _, m in r["/js"]] == [float(i) for i in range(100)]
    assert r.params() == custom_params()


# ------------------------------------------------------------------------------------------ crashes

CRASH_CHILD = textwrap.dedent("""
    import os, sys
    from sensor_msgs.msg import JointState
    from bldc_actuator.params import ActuatorParams
    from bldc_actuator.recording import McapRecorder
    rec = McapRecorder(sys.argv[1], parameters=ActuatorParams().replace(**{"drive.bus_voltage": 30.0}))
    n = int(sys.argv[2])
    for i in range(n):
        m = JointState(name=["j"], position=[float(i)], velocity=[0.5], effort=[0.0])
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(i * 1000000, 1000000000)
        rec.write("/joint_states", m, i * 1000000)
    sys.stdout.write(f"{rec.messages_written} {rec.bytes_written}\\n"); sys.stdout.flush()
    os._exit(0)  # crash: no close(), no atexit, no finally
""")


def test_killed_recorder_loses_at_most_the_last_chunk(msgs, tmp_path):
    pytest.importorskip("rclpy")
    path = tmp_path / "crash.mcap"
    n = 12000
    out = subprocess.run([sys.executable, "-c", CRASH_CHILD, str(path), str(n)], capture_output=True, text=True,
                         timeout=scaled(120), cwd=REPO)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout.split()[0]) == n
    r = read_recording(path)
    assert not r.finalized and "NOT finalized" in r.issues[0]
    got = r["/joint_states"]
    k = len(got)
    # the recovered messages are exactly the first k, with their values
    assert [m.position[0] for _, m in got] == [float(i) for i in range(k)]
    assert [t for t, _ in got] == [i * 1_000_000 for i in range(k)]
    # at most one chunk lost: the records of the missing messages fit in one chunk
    from rclpy.serialization import serialize_message

    record = len(serialize_message(msgs.JointState(name=["j"], position=[1.0], velocity=[0.5], effort=[0.0]))) + 31
    assert 0 < k < n
    assert (n - k) * record <= DEFAULT_CHUNK_SIZE + record
    # the parameters written at the start survive the crash
    assert r.params().drive.bus_voltage == 30.0 and parameters_from_recording(path).drive.bus_voltage == 30.0
    s = summarize(path)
    assert not s["finalized"] and s["topics"]["/joint_states"]["count"] == k


def test_flush_interval_puts_a_slow_stream_on_disk(msgs, tmp_path):
    import time

    path = tmp_path / "slow.mcap"
    rec = McapRecorder(path, flush_interval=0.05)
    rec.write("/t", msgs.Temperature(temperature=30.0), 0)
    time.sleep(0.08)
    rec.write("/t", msgs.Temperature(temperature=31.0), SEC)  # closes the chunk: older than 50 ms
    r = read_recording(path)  # while the recorder is still open, as after a crash
    assert not r.finalized and [m.temperature for _, m in r["/t"]] == [30.0, 31.0]
    rec.close()
    assert read_recording(path).finalized


SIGNAL_CHILD = textwrap.dedent("""
    import os, signal, sys, time
    from sensor_msgs.msg import JointState
    from bldc_actuator.recording import McapRecorder, install_signal_finalizer
    if sys.argv[2] == "default":
        # Python leaves SIGINT ignored when it starts with it ignored (a background job of a non-interactive
        # shell, nohup): the test must not depend on how pytest was launched
        signal.signal(signal.SIGINT, signal.default_int_handler)
    else:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    rec = McapRecorder(sys.argv[1], parameters={"drive.bus_voltage": 12.0})
    install_signal_finalizer(rec)
    i = 0
    while True:  # no try/finally: only the signal finalizer can close the file
        rec.write("/joint_states", JointState(position=[float(i)]), i * 1000)
        i += 1
        if i == 200:
            print("ready", flush=True)
""")


@pytest.mark.parametrize("signum, returncode", [(signal.SIGTERM, 128 + signal.SIGTERM),
                                                (signal.SIGINT, -signal.SIGINT)])
def test_signal_finalizer_closes_the_file(msgs, tmp_path, signum, returncode):
    path = tmp_path / "sig.mcap"
    proc = subprocess.Popen([sys.executable, "-c", SIGNAL_CHILD, str(path), "default"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=REPO)
    try:
        assert proc.stdout.readline().strip() == "ready"
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=scaled(60))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    # SIGTERM: SystemExit(143); SIGINT: an uncaught KeyboardInterrupt (Python re-raises SIGINT at exit)
    assert proc.returncode in (returncode, 1), err
    r = read_recording(path)
    assert r.finalized and r.issues == []
    assert r.metadata["finalized_by"] == f"signal {signal.Signals(signum).name}"
    n = len(r["/joint_states"])
    assert n >= 200 and [m.position[0] for _, m in r["/joint_states"]] == [float(i) for i in range(n)]
    assert r.params().drive.bus_voltage == 12.0


def test_an_ignored_sigint_stays_ignored(msgs, tmp_path):
    """A process started with SIGINT ignored (nohup, a background job) keeps recording through a SIGINT; the
    finalizer still closes the file on SIGTERM."""
    path = tmp_path / "ign.mcap"
    proc = subprocess.Popen([sys.executable, "-c", SIGNAL_CHILD, str(path), "ignored"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=REPO)
    try:
        assert proc.stdout.readline().strip() == "ready"
        proc.send_signal(signal.SIGINT)
        with pytest.raises(subprocess.TimeoutExpired):
            proc.wait(timeout=1.0)          # still running: the ignored SIGINT did nothing
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=scaled(60))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 128 + signal.SIGTERM, err
    r = read_recording(path)
    assert r.finalized and r.metadata["finalized_by"] == "signal SIGTERM"


# ------------------------------------------------------------------------------------------ record-info

def _record_info(argv, capsys):
    from bldc_actuator.cli import main

    code = main(["record-info", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_record_info_on_a_finalized_file(reference_file, capsys):
    path, exp = reference_file
    code, out, err = _record_info([str(path)], capsys)
    assert code == 0 and err == ""
    assert "finalized" in out and "NOT FINALIZED" not in out and "Issues:     none" in out
    line = next(l for l in out.splitlines() if l.strip().startswith("/joint_states"))
    assert "sensor_msgs/msg/JointState" in line and f" {N} " in line and "1000.000" in line
    assert "motor.torque_constant_q      0.1234 N*m/A" in out and "K_t_q" in out
    assert "motor.winding" in out and "delta" in out and "drive.bus_voltage" in out and "48 V" in out
    assert "3.000000 s (simulation time)" in out
    code, out, _ = _record_info([str(path), "--json"], capsys)
    s = json.loads(out)
    assert code == 0 and s["finalized"] and s["message_count"] == sum(len(v) for v in exp.values())
    assert s["topics"]["/joint_states"]["rate_hz"] == pytest.approx(1000.0)
    assert s["parameters"]["motor.q_inductance"] == 3.3e-5


def test_record_info_on_a_truncated_file(reference_file, tmp_path, capsys, msgs):
    # a longer file with small chunks so that a cut keeps some complete chunks
    path = tmp_path / "long.mcap"
    with McapRecorder(path, parameters=custom_params(), chunk_size=4096) as rec:
        for i in range(3000):
            rec.write("/joint_states", msgs.JointState(position=[float(i)]), i * 1_000_000)
    cut = tmp_path / "cut.mcap"
    data = path.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    code, out, err = _record_info([str(cut)], capsys)
    assert code == 0, err
    assert "NOT FINALIZED" in out and "file is NOT finalized" in out
    count = int(next(l for l in out.splitlines() if l.strip().startswith("/joint_states")).split()[2])
    assert 1000 < count < 3000
    assert "0.1234 N*m/A" in out  # parameters from the record written at the start
    r = read_recording(cut)
    assert [m.position[0] for _, m in r["/joint_states"]] == [float(i) for i in range(count)]


def test_record_info_refuses_missing_and_non_mcap_files(tmp_path, capsys):
    code, out, err = _record_info([str(tmp_path / "nope.mcap")], capsys)
    assert code == 2 and "no such file" in err and out == ""
    text = tmp_path / "notes.mcap"
    text.write_text("hello")
    code, _, err = _record_info([str(text)], capsys)
    assert code == 2 and "not an MCAP file" in err
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    code, _, err = _record_info([str(empty)], capsys)
    assert code == 2 and "empty file" in err
    code, _, err = _record_info([str(tmp_path)], capsys)
    assert code == 2 and "directory" in err


def test_a_corrupt_chunk_is_skipped_and_reported(msgs, tmp_path):
    path = tmp_path / "corrupt.mcap"
    with McapRecorder(path, chunk_size=4096, compression="none") as rec:
        for i in range(2000):
            rec.write("/joint_states", msgs.JointState(position=[float(i)]), i * 1_000_000)
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    middle = chunks[len(chunks) // 2]
    data = bytearray(path.read_bytes())
    at = middle.chunk_start_offset + middle.chunk_length // 2
    data[at:at + 64] = bytes(64)  # zero a stretch inside one chunk's content: its CRC no longer matches
    path.write_bytes(bytes(data))
    r = read_recording(path)
    got = [m.position[0] for _, m in r["/joint_states"]]
    assert 1000 < len(got) < 2000 and got == sorted(got) and got[0] == 0.0 and got[-1] == 1999.0
    assert any("corrupt chunk skipped" in i for i in r.issues)
    assert any("summary says 2000 messages" in i for i in r.issues)


def test_empty_float64_sequences_decode_in_both_decoders(msgs, tmp_path):
    """Fast-CDR (rclpy) aligns even EMPTY sequences of 8-byte elements; rclpy and mcap_ros2 agree on that
    layout (rosbags 0.11 does not: it reports "CDR message size mismatch" for these messages)."""
    from rcl_interfaces.msg import Parameter, ParameterEvent, ParameterValue

    path = tmp_path / "empty.mcap"
    with McapRecorder(path) as rec:
        rec.write("/js", msgs.JointState(name=["a"], position=[1.5]), 1)  # velocity, effort empty
        rec.write("/arr", msgs.Float64MultiArray(), 2)
        rec.write("/parameter_events", ParameterEvent(node="/n", changed_parameters=[
            Parameter(name="drive.bus_voltage", value=ParameterValue(type=3, double_value=48.0))]), 3)
    for decoder in ("rclpy", "mcap_ros2"):
        r = read_recording(path, decoder=decoder)
        assert r.issues == [f"the '{METADATA_NAME}' metadata record has no {PARAMETERS_KEY}: parameters missing"]
        (_, js), = r["/js"]
        assert list(js.position) == [1.5] and list(js.velocity) == [] and list(js.effort) == []
        assert list(r["/arr"][0][1].data) == []
        (_, ev), = r["/parameter_events"]
        assert ev.changed_parameters[0].name == "drive.bus_voltage"
        assert ev.changed_parameters[0].value.double_value == 48.0
