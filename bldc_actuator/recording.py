"""MCAP recordings of the actuator: ROS 2 profile, CDR messages, parameters inside the file.

A recording alone is enough to re-simulate a run: the model parameters travel in a metadata record, and
every message is a ROS 2 CDR message under the schema, channel and QoS conventions of rosbag2's own MCAP
plugin (rosbag2_storage_mcap), which ``ros2 bag info/play`` (Jazzy and later) and Foxglove read. Verified
here: ``mcap_ros2`` and ``rosbags`` decode the files (``ros2 bag`` itself is not installable from PyPI).

Writing
-------
``McapRecorder(path, *, parameters=None, metadata=None, chunk_size=256 * 1024, compression="zstd",
flush_interval=1.0)``
    Opens ``path`` (truncating it) and starts an MCAP file with ``profile="ros2"``,
    ``library="bldc_actuator <version>"``. ``parameters``: an :class:`~bldc_actuator.params.ActuatorParams`
    or the flat dotted dict of :func:`bldc_actuator.params.to_flat` (non-model keys such as ``node.*`` or
    ``preset`` may ride along; ``None`` values are left out: a params file cannot say "not set");
    ``metadata``: extra ``str -> str`` pairs for the metadata record.
    ``compression`` (``"zstd"``, ``"lz4"`` or ``"none"``) and ``flush_interval`` (wall seconds, ``None``
    = off) are keyword extensions of the team API; the defaults suit the node.
``add_topic(topic, msg_type, qos=None) -> channel id``
    ``msg_type``: ``"sensor_msgs/msg/JointState"`` (``"sensor_msgs/JointState"`` and the message class
    are accepted too). Registers the schema once per type (encoding ``ros2msg``: the ``.msg`` text and
    every dependency after a line of 80 ``=`` and ``MSG: pkg/Type``, exactly as rosbag2's
    ``message_definition_cache`` builds it) and one channel per topic (``message_encoding="cdr"``,
    metadata ``offered_qos_profiles`` in rosbag2's YAML layout (metadata version 9: enum names as strings)
    and ``topic_type_hash``, the ``RIHS01_...`` hash from ``share/<pkg>/msg/<Type>.json``, empty when not
    found). ``qos``: an ``rclpy.qos.QoSProfile`` (``publisher.qos_profile``), a list of them, or ``None``
    for KEEP_LAST 10 / RELIABLE / VOLATILE. Idempotent for the same topic and type; another type on a
    known topic is an error. Pass fully resolved names (``publisher.topic_name``).
``write(topic, msg, t_ns)``
    ``rclpy.serialization.serialize_message(msg)``; ``log_time = publish_time = t_ns`` (integer
    nanoseconds of SIMULATION time, >= 0); ``sequence`` counts 1, 2, 3 ... per channel, so a gap means a
    lost message. An unknown topic is added on the fly with the message's type and the default QoS.
``write_serialized(topic, data, t_ns)``
    The same for CDR bytes you already have (the topic must have been added).
``set_parameters(parameters)``
    Replaces the recorded parameters; the LAST value is in the final record. Each change is also written
    at once as an ``"update"`` record (with the simulation time of the last message written), so a
    crashed run keeps its parameter history.
``close()``
    Writes the final metadata record ``"bldc_actuator"`` = ``{"parameters_yaml": <YAML text in the node's
    params-file layout (params.dump_yaml)>, **metadata, "record": "final", "finalized_by": ...,
    "messages_written": ..., "last_time_ns": ..., "recorder": ...}``, then the MCAP summary and footer,
    fsyncs and closes the file. Idempotent; safe from ``finally``, ``atexit`` and signal handlers; raises
    at most once (a second call after a failed close returns quietly).
``with McapRecorder(...) as rec:``
    Closes on exceptions too (the file is finalized and readable; a close error then is reported as a
    warning and never masks the original exception).
``messages_written`` (int), ``bytes_written`` (int: bytes in the file plus an estimate of the open chunk),
``closed`` (bool), ``path``.

No ``rosbag2`` metadata record is written (rosbag2 then reads topics, counts and times from the MCAP
Statistics record, which this writer always emits); run data lives under our own record name.

Crash safety
------------
Messages are grouped in chunks. The file is written WITHOUT user-space buffering: when a chunk is
complete it is in the operating system's hands, so a crash of the process (exception, ``os._exit``,
SIGKILL) loses at most the chunk being filled; :func:`read_recording` and ``bldc-actuator record-info``
recover everything before it from an unfinalized file by streaming it record by record. A chunk closes
when it exceeds ``chunk_size`` bytes (uncompressed) or, with messages pending, ``flush_interval`` wall
seconds after its first message. At the node's default rates (joint_states, ~/phase_currents, ~/q_axis_state
(15 labelled values), ~/winding_temperature and ~/housing_temperature at 1 kHz, /diagnostics at 10 Hz:
5010 messages and 0.73 MB of uncompressed message records per simulated second, measured by
``benchmarks/bench_mcap.py``; the file grows by about 0.16 MB/s with zstd), a 256 KiB chunk holds about
360 ms of simulated data (about 340 ms with ``node.publish_clock``): a crash loses at most that, and at
most ``flush_interval`` (1 s) of wall time in slow runs. Power loss is another matter: only ``close()``
fsyncs.

Finalizing on Ctrl-C / SIGTERM: the recorder registers ``close`` with :mod:`atexit` (which covers an
uncaught KeyboardInterrupt or SystemExit); :func:`install_signal_finalizer` adds SIGINT/SIGTERM handlers
that close the file and then behave as before (KeyboardInterrupt for SIGINT, SystemExit(143) for a default
SIGTERM, or the previous Python handler). rclpy's own C-level handlers stay in the chain (they are
re-installed on top), so a spinning executor still wakes up. A signal that arrives in the middle of a
``write`` in the main thread is deferred to the end of that write, so the file is never cut mid-record.
Typical node use::

    rec = McapRecorder(path, parameters=params.to_flat(), metadata={"node": name})
    uninstall = install_signal_finalizer(rec)       # after rclpy.init() is fine
    for pub in publishers: rec.add_topic(pub.topic_name, pub.msg_type, pub.qos_profile)
    try:
        rclpy.spin(node)                             # callbacks call rec.write(pub.topic_name, msg, t_ns)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rec.close(); uninstall(); node.destroy_node(); rclpy.try_shutdown()

Reading
-------
``read_recording(path, *, topics=None, decoder="auto") -> Recording``
    Decodes every message (or those of ``topics``). ``decoder="auto"`` uses rclpy
    (``deserialize_message`` with the installed message class) and falls back, per type, to the pure
    Python ``mcap_ros2`` decoder when rclpy or the message package is not importable; ``"rclpy"`` and
    ``"mcap_ros2"`` force one. Field types differ between the two: rclpy gives ``array.array`` /
    ``numpy`` arrays and ``bytes`` for ``byte`` fields (``DiagnosticStatus.level == b'\\x01'``);
    mcap_ros2 gives lists and ``int`` (``level == 1``). Use :func:`as_level` for diagnostics levels.
    Other readers: ``rosbags`` (>= 0.11: ``rosbag2.Reader``/``AnyReader`` open the single file) decodes
    all the node's outputs, but not messages with an EMPTY float64/int64 sequence (Fast-CDR aligns them;
    e.g. rcl_interfaces/ParameterEvent, JointState without velocities) and not unfinalized files.
    Every file is read as a stream, record by record (the MCAP stream-reader approach, with a struct-based
    parser about 10x faster than ``mcap.stream_reader`` on long runs), so an unfinalized file is read up
    to its last complete chunk (an issue says so) and a corrupt chunk is skipped (an issue says so).
    Decoding dominates the time: rclpy about 60 us per message here, mcap_ros2 about 20 us; the scan
    alone (``summarize``) about 1.5 us. Pass ``topics=[...]`` to decode only what you need.
``Recording``: ``topics`` {topic: [(t_ns, msg), ...]} sorted by time; ``types`` {topic: type};
    ``parameters`` (flat dotted dict parsed back from the YAML, model values normalised like
    ``to_flat``; ``None`` when absent); ``parameters_yaml``; ``metadata`` (the last ``bldc_actuator``
    record without the YAML); ``metadata_records`` [(name, dict)] (all, file order); ``finalized``;
    ``issues`` [str]; ``decoders`` {topic: "rclpy" | "mcap_ros2" | "raw"}; ``params()`` ->
    ActuatorParams; ``start_ns``, ``end_ns``, ``duration_s``.
``parameters_from_recording(path) -> ActuatorParams``
    The model parameters of a recording (last ``bldc_actuator`` record with ``parameters_yaml``): the
    same object that :func:`bldc_actuator.params.load_yaml` of the extracted text gives.
``summarize(path) -> dict``
    Without decoding messages: ``path``, ``file_size``, ``finalized``, ``profile``, ``library``,
    ``topics`` {topic: {type, count, first_ns, last_ns, rate_hz, message_encoding, schema_encoding,
    type_hash, sequence_gaps}}, ``message_count``, ``start_ns``, ``end_ns``, ``duration_s``,
    ``parameters_present``, ``parameters``, ``metadata``, ``issues``. JSON-serialisable.
``RecordingError``: the file is missing, not MCAP, or has no parameters where they are required.
"""

from __future__ import annotations

import atexit
import importlib
import importlib.util
import json
import math
import os
import re
import signal
import struct
import sys
import threading
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from . import __version__
from .params import flatten_tree

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
METADATA_NAME = "bldc_actuator"
PARAMETERS_KEY = "parameters_yaml"
LIBRARY = f"bldc_actuator {__version__}"
DEFAULT_CHUNK_SIZE = 256 * 1024
DEFAULT_FLUSH_INTERVAL = 1.0
MCAP_MAGIC = b"\x89MCAP0\r\n"
#: keys of the metadata record written by the recorder itself (user metadata may not use them)
RESERVED_METADATA_KEYS = frozenset({PARAMETERS_KEY, "record", "finalized_by", "messages_written",
                                    "last_time_ns", "recorder", "parameters_error"})

#: rmw's "infinite" duration as rosbag2 writes it (RMW_DURATION_INFINITE)
_INFINITE = (9223372036, 854775807)
_MCAP_MESSAGE_OVERHEAD = 1 + 8 + 2 + 4 + 8 + 8 + 16  # record header + fields + message index entry


class RecordingError(Exception):
    """A recording cannot be read: missing file, not MCAP, or required content absent."""


class RecorderClosedError(RuntimeError):
    """write()/add_topic() after close()."""


class RecordingWriteError(OSError):
    """Writing to the file failed (disk full, I/O error, file system gone). The recording has stopped: the
    file was cut back to its last complete chunk (readable, unfinalized) and further writes raise
    :class:`RecorderClosedError`. ``errno``/``strerror`` are those of the failed write."""


# ============================================================================ message types and schemas

_TYPE_RE = re.compile(r"^([a-zA-Z][a-zA-Z0-9_]*)/(?:(msg|srv)/)?([a-zA-Z][a-zA-Z0-9_]*)$")
# the two regular expressions and the primitive list of rosbag2_storage_mcap/message_definition_cache.cpp
_FIELD_TYPE_RE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVES = frozenset({"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
                         "int32", "uint32", "int64", "uint64", "string"})
_DELIMITER = "=" * 80 + "\n"

_class_types: dict[type, str] = {}
_definition_cache: dict[str, str | None] = {}
_share_cache: dict[str, list[Path]] = {}


def type_name(msg_type: Any) -> str:
    """``"pkg/msg/Type"`` for ``"pkg/msg/Type"``, ``"pkg/Type"``, a message class or a message instance."""
    if isinstance(msg_type, str):
        m = _TYPE_RE.match(msg_type.strip())
        if not m:
            raise ValueError(f"message type {msg_type!r}: expected 'pkg/msg/Type' (e.g. sensor_msgs/msg/JointState)")
        return f"{m.group(1)}/{m.group(2) or 'msg'}/{m.group(3)}"
    cls = msg_type if isinstance(msg_type, type) else type(msg_type)
    cached = _class_types.get(cls)
    if cached is None:
        module = getattr(cls, "__module__", "") or ""
        parts = module.split(".")
        if len(parts) < 2 or parts[1] not in ("msg", "srv", "action") or not hasattr(cls, "get_fields_and_field_types"):
            raise TypeError(f"{cls!r} is not a ROS 2 message class (expected e.g. sensor_msgs.msg.JointState)")
        cached = _class_types[cls] = f"{parts[0]}/{parts[1]}/{cls.__name__}"
    return cached


def _share_dirs(package: str) -> list[Path]:
    """Candidate ``share/<package>`` directories: AMENT_PREFIX_PATH, the prefix the package's Python module
    is installed under (pip venv, colcon install, /opt/ros), then sys.prefix."""
    if package in _share_cache:
        return _share_cache[package]
    candidates: list[Path] = []
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        candidates.append(Path(prefix) / "share" / package)
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        spec = None
    locations = list(spec.submodule_search_locations or []) if spec is not None else []
    for loc in locations:
        for parent in list(Path(loc).resolve().parents)[:6]:
            candidates.append(parent / "share" / package)
    for prefix in (sys.prefix, sys.base_prefix):
        candidates.append(Path(prefix) / "share" / package)
    seen, out = set(), []
    for c in candidates:
        if c not in seen and c.is_dir():
            seen.add(c)
            out.append(c)
    _share_cache[package] = out
    return out


def interface_file(msg_type: str, extension: str) -> Path | None:
    """The installed ``share/<pkg>/msg/<Type><extension>`` file of a type (``.msg``, ``.json``), or None."""
    m = _TYPE_RE.match(msg_type)
    if not m:
        return None
    package, namespace, name = m.group(1), m.group(2) or "msg", m.group(3)
    for share in _share_dirs(package):
        path = share / namespace / f"{name}{extension}"
        if path.is_file():
            return path
    return None


def _msg_dependencies(text: str, package: str) -> list[str]:
    deps = set()
    for m in _FIELD_TYPE_RE.finditer(text):
        t = m.group(1)
        if t in _PRIMITIVES:
            continue
        deps.add(t if "/" in t else f"{package}/{t}")
    return sorted(deps)  # std::set<std::string> order


def message_definition(msg_type: Any) -> str | None:
    """Full ``ros2msg`` schema text as rosbag2 writes it, or None when a ``.msg`` file is missing.

    The root ``.msg`` text, then for each dependency (depth first, each once, in sorted order) a newline,
    80 ``=``, ``MSG: <name as written in the field>`` and its text.
    """
    root = type_name(msg_type)
    if root in _definition_cache:
        return _definition_cache[root]
    seen: set[str] = set()

    def load(name: str) -> str:
        path = interface_file(name, ".msg")
        if path is None:
            raise FileNotFoundError(name)
        return path.read_text(encoding="utf-8")

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise RecursionError(f"message definition of {root} nests too deep")
        text = load(name)
        result = text
        for dep in _msg_dependencies(text, _TYPE_RE.match(name).group(1)):
            if dep not in seen:
                seen.add(dep)
                result += "\n" + _DELIMITER + f"MSG: {dep}\n" + append(dep, depth - 1)
        return result

    try:
        text = append(root, 50)
    except (FileNotFoundError, OSError, RecursionError, AttributeError):
        text = None
    _definition_cache[root] = text
    return text


def type_hash(msg_type: Any) -> str:
    """``RIHS01_<sha256>`` of the type from its installed ``.json`` type description, or ``""``."""
    name = type_name(msg_type)
    path = interface_file(name, ".json")
    if path is None:
        return ""
    try:
        for entry in json.loads(path.read_text(encoding="utf-8")).get("type_hashes", []):
            if entry.get("type_name") == name:
                return str(entry.get("hash_string", ""))
    except (OSError, ValueError, AttributeError):
        pass
    return ""


def message_class(msg_type: Any):
    """The rclpy message class of a type (imports ``<pkg>.msg``); raises ImportError/AttributeError."""
    if isinstance(msg_type, type):
        return msg_type
    pkg, namespace, name = type_name(msg_type).split("/")
    module = importlib.import_module(f"{pkg}.{namespace}")
    return getattr(module, name)


# =================================================================================================== QoS

_HISTORY = {0: "system_default", 1: "keep_last", 2: "keep_all"}
_RELIABILITY = {0: "system_default", 1: "reliable", 2: "best_effort", 4: "best_available"}
_DURABILITY = {0: "system_default", 1: "transient_local", 2: "volatile", 4: "best_available"}
_LIVELINESS = {0: "system_default", 1: "automatic", 3: "manual_by_topic", 5: "best_available"}
DEFAULT_QOS = {"history": 1, "depth": 10, "reliability": 1, "durability": 2, "deadline": 0, "lifespan": 0,
               "liveliness": 0, "liveliness_lease_duration": 0, "avoid_ros_namespace_conventions": False}


def _duration_pair(value: Any) -> tuple[int, int]:
    ns = getattr(value, "nanoseconds", value)
    ns = int(ns or 0)
    if ns <= 0 or ns >= _INFINITE[0] * 1_000_000_000 + _INFINITE[1]:
        return _INFINITE  # rmw default/unspecified (0) is "no limit": what a live recording reports
    return divmod(ns, 1_000_000_000)


def qos_yaml(qos: Any = None) -> str:
    """``offered_qos_profiles`` text as rosbag2 writes it (yaml-cpp dump, metadata version 9).

    ``qos``: an ``rclpy.qos.QoSProfile`` (or anything with its attributes), a dict with its keys, a list of
    those, a ready YAML string (used verbatim), or None (KEEP_LAST 10, RELIABLE, VOLATILE).
    """
    if isinstance(qos, str):
        return qos
    profiles = qos if isinstance(qos, (list, tuple)) else [qos]
    items = []
    for p in profiles:
        if p is None:
            p = DEFAULT_QOS
        get = (lambda k, _p=p: _p[k]) if isinstance(p, Mapping) else (lambda k, _p=p: getattr(_p, k))
        history = int(get("history"))
        lines = [
            f"- history: {_HISTORY.get(history, 'unknown')}",
            f"  depth: {int(get('depth'))}",
            f"  reliability: {_RELIABILITY.get(int(get('reliability')), 'unknown')}",
            f"  durability: {_DURABILITY.get(int(get('durability')), 'unknown')}",
        ]
        for key in ("deadline", "lifespan"):
            sec, nsec = _duration_pair(get(key))
            lines += [f"  {key}:", f"    sec: {sec}", f"    nsec: {nsec}"]
        lines.append(f"  liveliness: {_LIVELINESS.get(int(get('liveliness')), 'unknown')}")
        sec, nsec = _duration_pair(get("liveliness_lease_duration"))
        lines += ["  liveliness_lease_duration:", f"    sec: {sec}", f"    nsec: {nsec}"]
        avoid = "true" if get("avoid_ros_namespace_conventions") else "false"
        lines.append(f"  avoid_ros_namespace_conventions: {avoid}")
        items.append("\n".join(lines))
    return "\n".join(items)


# ============================================================================================ parameters

def _plain(value: Any) -> Any:
    """YAML-safe Python value (numpy scalars, tuples ...)."""
    if isinstance(value, (bool, str)) or value is None:
        return value
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if hasattr(value, "item") and callable(value.item):  # numpy scalar
        value = value.item()
    if isinstance(value, (int, float)):
        return value
    return str(value)


def _nest(flat: Mapping[str, Any]) -> dict[str, Any]:
    tree: dict[str, Any] = {}
    for key, value in flat.items():
        node = tree
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ValueError(f"parameter {key!r} conflicts with a parameter named {part!r}")
        node[parts[-1]] = value
    return tree


def render_parameters(parameters: Any) -> tuple[str, dict[str, Any]]:
    """``(yaml_text, flat_dict)`` for an ActuatorParams or a flat (or nested) parameter dict.

    Model keys (``params.SPECS``) are validated and written by :func:`params.dump_yaml` (every model
    parameter, defaults filled in); other keys (``node.*``, ``preset``, ...) are appended under the same
    ``ros__parameters`` mapping. Raises ParameterError naming a bad or unknown model field.
    """
    from . import params as P

    if isinstance(parameters, P.ActuatorParams):
        return P.dump_yaml(parameters, header=f"parameters recorded by {LIBRARY}"), P.to_flat(parameters)
    if not isinstance(parameters, Mapping):
        raise TypeError(f"parameters: expected ActuatorParams or a dict, got {type(parameters).__name__}")
    flat = flatten_tree(parameters)
    model = {k: v for k, v in flat.items() if k in P.SPECS}
    # None (a ROS parameter that is not set) has no params-file form: such keys are left out
    extra = {k: _plain(v) for k, v in flat.items() if k not in P.SPECS and v is not None}
    for key in extra:
        if key.split(".")[0] in P.SECTIONS:
            raise P.ParameterError(key, "unknown model parameter")
    params = P.from_flat(model)
    text = P.dump_yaml(params, header=f"parameters recorded by {LIBRARY}") if model else \
        f"{P.YAML_NODE_KEY}:\n  ros__parameters:\n"
    if extra:
        import yaml

        dumped = yaml.safe_dump(_nest(extra), default_flow_style=False, sort_keys=False, allow_unicode=True)
        text += "".join(f"    {line}\n" for line in dumped.splitlines())
    out = P.to_flat(params) if model else {}
    out.update(extra)
    return text, out


def parameters_from_yaml(text: str) -> dict[str, Any]:
    """Flat dotted dict from parameter YAML text (node layout or plain mapping); model values normalised
    like ``params.to_flat`` when they form valid parameters."""
    import yaml

    from . import params as P

    tree = yaml.safe_load(text) or {}
    if not isinstance(tree, Mapping):
        raise ValueError("parameters YAML is not a mapping")
    if len(tree) == 1:
        (only,) = tree.values()
        if isinstance(only, Mapping) and "ros__parameters" in only:
            tree = only["ros__parameters"] or {}
    flat = flatten_tree(tree)
    model = {k: v for k, v in flat.items() if k in P.SPECS}
    if model:
        flat.update(P.to_flat(P.from_flat(model)))
    return flat


def _model_params(text: str):
    from . import params as P

    flat = parameters_from_yaml(text)
    model = {k: v for k, v in flat.items() if k in P.SPECS}
    if not model:
        raise RecordingError("the recorded parameters contain no model parameter")
    return P.from_flat(model)


# ============================================================================================== writing

class _DirectFile:
    """Unbuffered write-only file for mcap.Writer: every write goes straight to the OS (a crash of the
    process loses nothing that the writer already handed over). Not an io.RawIOBase on purpose: the
    writer would wrap that in a BufferedWriter."""

    def __init__(self, path: Path):
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0), 0o644)
        self.pos = 0

    def write(self, data) -> int:
        view = memoryview(data)
        total = len(view)
        while view:
            n = os.write(self._fd, view)
            view = view[n:]
        self.pos += total
        return total

    def tell(self) -> int:
        return self.pos

    def flush(self) -> None:
        pass

    def fsync(self) -> None:
        os.fsync(self._fd)

    def truncate(self, size: int) -> None:
        """Cut the file back to ``size`` bytes (drop a partly written chunk after a failed write)."""
        os.ftruncate(self._fd, size)
        os.lseek(self._fd, size, os.SEEK_SET)
        self.pos = size

    def close(self) -> None:
        if self._fd >= 0:
            fd, self._fd = self._fd, -1
            os.close(fd)


@dataclass
class _Channel:
    id: int
    topic: str
    type: str
    msg_class: Any = None
    sequence: int = 0


_serialize_message: Callable[[Any], bytes] | None = None


def _serializer() -> Callable[[Any], bytes]:
    global _serialize_message
    if _serialize_message is None:
        from rclpy.serialization import serialize_message

        _serialize_message = serialize_message
    return _serialize_message


def _check_time(t_ns: Any) -> int:
    t = int(t_ns)
    if t != t_ns or not 0 <= t < 2**64:
        raise ValueError(f"t_ns: expected integer nanoseconds of simulation time in [0, 2**64), got {t_ns!r}")
    return t



class McapRecorder:
    """Writes a ROS 2 MCAP recording; see the module docstring for the API and guarantees."""

    def __init__(self, path, *, parameters: Any = None, metadata: Mapping[str, str] | None = None,
                 chunk_size: int = DEFAULT_CHUNK_SIZE, compression: str = "zstd",
                 flush_interval: float | None = DEFAULT_FLUSH_INTERVAL):
        from mcap.writer import CompressionType, Writer

        if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1024:
            raise ValueError(f"chunk_size: expected an integer >= 1024 [bytes], got {chunk_size!r}")
        kinds = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE,
                 "": CompressionType.NONE}
        if compression not in kinds:
            raise ValueError(f"compression: expected one of zstd, lz4, none, got {compression!r}")
        if flush_interval is not None and not (flush_interval > 0 and math.isfinite(flush_interval)):
            raise ValueError(f"flush_interval: expected a positive number of seconds or None, "
                             f"got {flush_interval!r}")
        user_meta: dict[str, str] = {}
        for key, value in (metadata or {}).items():
            if not isinstance(key, str) or not isinstance(value, str):
                raise TypeError(f"metadata: keys and values must be str, got {key!r}: {value!r}")
            if key in RESERVED_METADATA_KEYS:
                raise ValueError(f"metadata: key {key!r} is reserved "
                                 f"(reserved: {', '.join(sorted(RESERVED_METADATA_KEYS))})")
            user_meta[key] = value
        # render before opening the file: bad parameters must not leave an empty file behind
        rendered = render_parameters(parameters) if parameters is not None else None

        self.path = Path(path)
        self._lock = threading.Lock()
        self._busy: set[int] = set()        # threads inside a critical section (see install_signal_finalizer)
        self._deferred_signal: tuple[int, Any] | None = None
        self._signal_finalizer: _SignalFinalizer | None = None
        self._closed = False
        self._finalized_by = "close()"
        self._metadata = user_meta
        self._parameters_yaml: str | None = None
        self._parameters_flat: dict[str, Any] | None = None
        self._channels: dict[str, _Channel] = {}
        self._schemas: dict[str, int] = {}
        self._last_t_ns: int | None = None
        self._pending = 0                   # messages in the open chunk
        self._pending_bytes = 0
        self._chunk_opened = 0.0
        self._flush_interval = flush_interval
        self.messages_written = 0
        self.write_error: OSError | None = None   #: the OS error that stopped the recording, if any

        self._sink = _DirectFile(self.path)
        try:
            self._writer = Writer(self._sink, chunk_size=chunk_size, compression=kinds[compression])
            self._writer.start(profile=PROFILE, library=LIBRARY)
            # Writer.flush() closes the open chunk (mcap >= 1.2); older versions only have the private one
            self._flush_chunk = getattr(self._writer, "flush", None) or getattr(self._writer, "_Writer__finalize_chunk")
            if rendered is not None:
                self._parameters_yaml, self._parameters_flat = rendered
                self._write_metadata("initial")
        except BaseException:
            self._sink.close()
            raise
        atexit.register(self._atexit_close)

    # -- properties -------------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def bytes_written(self) -> int:
        return self._sink.pos + self._pending_bytes

    @property
    def topics(self) -> dict[str, str]:
        return {t: c.type for t, c in self._channels.items()}

    # -- topics -----------------------------------------------------------------------------------
    def add_topic(self, topic: str, msg_type: Any, qos: Any = None) -> int:
        if not isinstance(topic, str) or not topic:
            raise ValueError(f"topic: expected a non-empty topic name, got {topic!r}")
        name = type_name(msg_type)
        cls = msg_type if isinstance(msg_type, type) else None
        channel = self._channels.get(topic)
        if channel is not None:
            if channel.type != name:
                raise ValueError(f"topic {topic!r} is already recorded as {channel.type}, not {name}")
            if cls is not None and channel.msg_class is None:
                channel.msg_class = cls
            return channel.id
        qos_text = qos_yaml(qos)
        ident = threading.get_ident()
        self._busy.add(ident)
        try:
            with self._lock:
                self._check_open()
                channel = self._channels.get(topic)
                if channel is not None:  # added by another thread meanwhile
                    if channel.type != name:
                        raise ValueError(f"topic {topic!r} is already recorded as {channel.type}, not {name}")
                    return channel.id
                schema_id = self._schemas.get(name)
                if schema_id is None:
                    text = message_definition(name)
                    if text is None:
                        warnings.warn(f"no .msg definition found for {name} (searched share/{name.split('/')[0]}"
                                      f" in AMENT_PREFIX_PATH, beside the Python package and in {sys.prefix}); "
                                      "schema left empty as rosbag2 does: only readers that know the type can "
                                      "decode this topic", RuntimeWarning, stacklevel=2)
                        schema_id = self._writer.register_schema(name=name, encoding="", data=b"")
                    else:
                        schema_id = self._writer.register_schema(name=name, encoding=SCHEMA_ENCODING,
                                                                 data=text.encode("utf-8"))
                    self._schemas[name] = schema_id
                channel_id = self._writer.register_channel(
                    topic=topic, message_encoding=MESSAGE_ENCODING, schema_id=schema_id,
                    metadata={"offered_qos_profiles": qos_text, "topic_type_hash": type_hash(name)})
                self._channels[topic] = _Channel(channel_id, topic, name, cls)
        finally:
            self._busy.discard(ident)
        self._fire_deferred_signal()
        return channel_id

    # -- messages ---------------------------------------------------------------------------------
    def write(self, topic: str, msg: Any, t_ns: int) -> None:
        channel = self._channels.get(topic)
        cls = type(msg)
        if channel is None:
            self.add_topic(topic, cls)
            channel = self._channels[topic]
        if channel.msg_class is not cls:
            if channel.msg_class is None and type_name(cls) == channel.type:
                channel.msg_class = cls
            else:
                raise TypeError(f"topic {topic!r} records {channel.type}, got a {cls.__module__}.{cls.__name__}")
        self._add(channel, _serializer()(msg), t_ns)

    def write_serialized(self, topic: str, data: bytes, t_ns: int) -> None:
        channel = self._channels.get(topic)
        if channel is None:
            raise KeyError(f"topic {topic!r} is not recorded yet: call add_topic(topic, msg_type) first")
        self._add(channel, bytes(data), t_ns)

    def _add(self, channel: _Channel, data: bytes, t_ns: int) -> None:
        t = int(t_ns)
        if t != t_ns or t < 0 or t >= 18446744073709551616:
            _check_time(t_ns)  # raises with the message
        ident = threading.get_ident()
        self._busy.add(ident)
        try:
            with self._lock:
                if self._closed:
                    raise RecorderClosedError(f"recording {self.path} is closed ({self._finalized_by}); "
                                              f"message on {channel.topic} not written")
                pos = self._sink.pos
                channel.sequence += 1
                try:
                    self._writer.add_message(channel.id, log_time=t, data=data, publish_time=t,
                                             sequence=channel.sequence)
                except OSError as exc:
                    self._fail(exc, pos)
                self.messages_written += 1
                if self._last_t_ns is None or t > self._last_t_ns:
                    self._last_t_ns = t
                if self._sink.pos != pos:   # the chunk (with this message) went to the file
                    self._pending = self._pending_bytes = 0
                else:
                    self._pending += 1
                    self._pending_bytes += len(data) + _MCAP_MESSAGE_OVERHEAD
                    if self._flush_interval is not None:
                        now = time.monotonic()
                        if self._pending == 1:
                            self._chunk_opened = now
                        elif now - self._chunk_opened >= self._flush_interval:
                            self._guarded(self._flush_chunk)
                            self._pending = self._pending_bytes = 0
        finally:
            self._busy.discard(ident)
        if self._deferred_signal is not None:
            self._fire_deferred_signal()

    def flush(self) -> None:
        """Close the open chunk now (it goes to the file; compression works per chunk)."""
        ident = threading.get_ident()
        self._busy.add(ident)
        try:
            with self._lock:
                self._check_open()
                if self._pending:
                    self._guarded(self._flush_chunk)
                    self._pending = self._pending_bytes = 0
        finally:
            self._busy.discard(ident)
        self._fire_deferred_signal()

    # -- parameters and metadata ------------------------------------------------------------------
    def set_parameters(self, parameters: Any) -> None:
        text, flat = render_parameters(parameters)
        ident = threading.get_ident()
        self._busy.add(ident)
        try:
            with self._lock:
                self._check_open()
                if text != self._parameters_yaml:
                    first = self._parameters_yaml is None
                    self._parameters_yaml, self._parameters_flat = text, flat
                    self._guarded(self._write_metadata, "initial" if first and not self.messages_written else "update")
        finally:
            self._busy.discard(ident)
        self._fire_deferred_signal()

    @property
    def parameters(self) -> dict[str, Any] | None:
        return None if self._parameters_flat is None else dict(self._parameters_flat)

    def _write_metadata(self, kind: str) -> None:
        data: dict[str, str] = {}
        if self._parameters_yaml is not None:
            data[PARAMETERS_KEY] = self._parameters_yaml
        data.update(self._metadata)
        data["record"] = kind
        data["recorder"] = LIBRARY
        data["messages_written"] = str(self.messages_written)
        data["last_time_ns"] = "" if self._last_t_ns is None else str(self._last_t_ns)
        if kind == "final":
            data["finalized_by"] = self._finalized_by
        self._writer.add_metadata(METADATA_NAME, data)

    # -- write errors -----------------------------------------------------------------------------
    def _guarded(self, fn, *args):
        """Run a writer call that may write to the file; on an OS error stop recording (see :meth:`_fail`)."""
        pos = self._sink.pos
        try:
            return fn(*args)
        except OSError as exc:
            self._fail(exc, pos)

    def _fail(self, exc: OSError, good_pos: int) -> None:
        """A write failed: cut the file back to ``good_pos`` (the end of the last complete chunk and its
        indexes, so readers see a clean unfinalized recording), close it and raise
        :class:`RecordingWriteError`. Called with the lock held."""
        self._closed = True
        self._finalized_by = f"write error: {exc.strerror or exc}"
        self.write_error = exc
        try:
            self._sink.truncate(good_pos)
        except OSError:
            pass   # the partly written chunk stays; readers stop at the last complete one anyway
        finally:
            self._sink.close()
            atexit.unregister(self._atexit_close)
        raise RecordingWriteError(exc.errno, f"{exc.strerror or exc}; recording stopped, file kept up to its last "
                                  f"complete chunk ({good_pos} bytes)", str(self.path)) from exc

    # -- closing ----------------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise RecorderClosedError(f"recording {self.path} is closed ({self._finalized_by})")

    def close(self) -> None:
        self._close("close()")

    def _close(self, reason: str) -> None:
        if self._closed:
            return
        ident = threading.get_ident()
        self._busy.add(ident)
        try:
            with self._lock:
                if self._closed:
                    return
                self._finalized_by = reason
                error: BaseException | None = None
                good = self._sink.pos   # the end of the last chunk the writer handed over
                try:
                    try:
                        self._write_metadata("final")
                    except BaseException as exc:  # still try to write the summary
                        error = exc
                    try:
                        self._writer.finish()
                        self._sink.fsync()
                    except OSError as exc:   # disk full while finalizing: keep what was complete
                        self._fail(exc, good)
                    self._closed = True
                    self._pending = self._pending_bytes = 0
                finally:
                    self._closed = True
                    self._sink.close()
                    atexit.unregister(self._atexit_close)
                if error is not None:
                    raise error
        finally:
            self._busy.discard(ident)
            self._fire_deferred_signal()

    def _atexit_close(self) -> None:
        try:
            self._close("atexit")
        except Exception as exc:  # noqa: BLE001 - nothing can handle it at exit
            print(f"bldc_actuator.recording: could not finalize {self.path}: {exc}", file=sys.stderr)

    def _fire_deferred_signal(self) -> None:
        deferred = self._deferred_signal
        if deferred is None or threading.get_ident() in self._busy or self._signal_finalizer is None:
            return
        self._deferred_signal = None
        self._signal_finalizer.finish(*deferred)

    def __enter__(self) -> "McapRecorder":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.close()
            return False
        try:
            self._close(f"exception {exc_type.__name__}")
        except Exception as close_exc:  # noqa: BLE001 - never mask the original exception
            warnings.warn(f"could not finalize {self.path} after {exc_type.__name__}: {close_exc}",
                          RuntimeWarning, stacklevel=2)
        return False

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return (f"McapRecorder({str(self.path)!r}, {state}, {len(self._channels)} topics, "
                f"{self.messages_written} messages)")


class _SignalFinalizer:
    def __init__(self, recorder: McapRecorder, signals: Iterable[int]):
        self.recorder = recorder
        self.previous: dict[int, Any] = {}
        for signum in signals:
            prev = signal.getsignal(signum)
            if prev == signal.SIG_IGN:
                continue  # an ignored signal stays ignored
            self.previous[signum] = prev
        for signum in self.previous:
            signal.signal(signum, self.handle)

    def handle(self, signum, frame) -> None:
        rec = self.recorder
        if threading.get_ident() in rec._busy:
            rec._deferred_signal = (signum, frame)  # finished at the end of the interrupted write
            return
        self.finish(signum, frame)

    def finish(self, signum, frame) -> None:
        try:
            self.recorder._close(f"signal {signal.Signals(signum).name}")
        except Exception as exc:  # noqa: BLE001 - the signal's own effect must still happen
            print(f"bldc_actuator.recording: could not finalize {self.recorder.path}: {exc}", file=sys.stderr)
        prev = self.previous.get(signum)
        if callable(prev):
            prev(signum, frame)
        elif signum == signal.SIGINT:
            raise KeyboardInterrupt
        else:
            raise SystemExit(128 + signum)

    def uninstall(self) -> None:
        for signum, prev in self.previous.items():
            if signal.getsignal(signum) == self.handle:
                signal.signal(signum, prev if prev is not None else signal.SIG_DFL)
        if self.recorder._signal_finalizer is self:
            self.recorder._signal_finalizer = None


def install_signal_finalizer(recorder: McapRecorder,
                             signals: Iterable[int] = (signal.SIGINT, signal.SIGTERM)) -> Callable[[], None]:
    """Finalize ``recorder`` on SIGINT/SIGTERM, then act as before (see the module docstring).

    Must be called from the main thread. If rclpy's signal handlers are installed they are re-installed
    on top, so rclpy still wakes its executors and then chains to ours. Returns ``uninstall()``.
    """
    if threading.current_thread() is not threading.main_thread():
        raise RuntimeError("install_signal_finalizer must be called from the main thread (Python runs signal "
                           "handlers there); the recorder's atexit finalizer is active anyway")
    rclpy_options = None
    rclpy_signals = sys.modules.get("rclpy.signals")
    if rclpy_signals is None and "rclpy" in sys.modules:
        try:
            import rclpy.signals as rclpy_signals  # noqa: PLW0621
        except Exception:  # noqa: BLE001
            rclpy_signals = None
    if rclpy_signals is not None:
        try:
            options = rclpy_signals.get_current_signal_handlers_options()
            if options != rclpy_signals.SignalHandlerOptions.NO:
                rclpy_options = options
                rclpy_signals.uninstall_signal_handlers()
        except Exception:  # noqa: BLE001 - older rclpy: leave its handlers alone
            rclpy_options = None
    finalizer = _SignalFinalizer(recorder, signals)
    if rclpy_options is not None:
        rclpy_signals.install_signal_handlers(rclpy_options)
    recorder._signal_finalizer = finalizer

    def uninstall() -> None:
        if rclpy_options is not None:
            rclpy_signals.uninstall_signal_handlers()
        finalizer.uninstall()
        if rclpy_options is not None:
            rclpy_signals.install_signal_handlers(rclpy_options)

    return uninstall


# ============================================================================================== reading

_REC_HEADER = struct.Struct("<BQ")
_MSG_FIELDS = struct.Struct("<HIQQ")        # channel id, sequence, log time, publish time
_CHUNK_FIELDS = struct.Struct("<QQQII")     # start, end, uncompressed size, crc, compression length
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
_OP_STATISTICS, _OP_METADATA = 0x0B, 0x0C


@dataclass
class _Scan:
    path: Path
    file_size: int
    finalized: bool = False
    profile: str = ""
    library: str = ""
    schemas: dict = field(default_factory=dict)
    channels: dict = field(default_factory=dict)
    messages: dict = field(default_factory=dict)        # channel id -> [(log_time, data)]
    stats: dict = field(default_factory=dict)           # channel id -> [count, first, last, gaps, backwards, last_seq]
    metadata: list = field(default_factory=list)        # [(name, dict)]
    statistics: Any = None
    issues: list = field(default_factory=list)
    complete_bytes: int = 0


def _open_checked(path) -> tuple[Path, Any, int]:
    p = Path(path)
    if not p.exists():
        raise RecordingError(f"{p}: no such file")
    if p.is_dir():
        mcaps = sorted(p.glob("*.mcap"))
        hint = f" (it holds {', '.join(m.name for m in mcaps[:3])})" if mcaps else ""
        raise RecordingError(f"{p}: is a directory, expected an .mcap file{hint}")
    try:
        f = open(p, "rb")
    except OSError as exc:
        raise RecordingError(f"{p}: cannot open: {exc.strerror}") from None
    size = os.fstat(f.fileno()).st_size
    head = f.read(len(MCAP_MAGIC))
    if head != MCAP_MAGIC:
        f.close()
        what = "empty file" if size == 0 else f"starts with {head[:8]!r}"
        raise RecordingError(f"{p}: not an MCAP file ({what}; MCAP files start with {MCAP_MAGIC!r})")
    return p, f, size


def _record(cls, body: bytes):
    from mcap.data_stream import ReadDataStream
    import io

    return cls.read(ReadDataStream(io.BytesIO(body)))


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    raise ValueError(f"unsupported chunk compression {compression!r}")


class _Scanner:
    """Walks an MCAP file record by record with struct (much faster than mcap's record objects for the
    millions of small messages of a long run); stops cleanly at the cut of an unfinalized file."""

    def __init__(self, scan: _Scan, keep_messages: bool, topics: Iterable[str] | None):
        self.scan = scan
        self.keep = keep_messages
        self.wanted = set(topics) if topics is not None else None
        self.keep_channel: dict[int, bool] = {}
        self.bad_chunks = 0

    def _channel(self, body: bytes) -> None:
        from mcap.records import Channel

        ch = _record(Channel, body)
        self.scan.channels.setdefault(ch.id, ch)
        self.keep_channel[ch.id] = self.keep and (self.wanted is None or ch.topic in self.wanted)

    def _messages(self, buf, start: int, end: int) -> None:
        """Parse the records in ``buf[start:end]`` (a chunk's content, or one top-level record)."""
        stats, messages, keep_channel = self.scan.stats, self.scan.messages, self.keep_channel
        unpack_header, unpack_msg = _REC_HEADER.unpack_from, _MSG_FIELDS.unpack_from
        off = start
        while off + 9 <= end:
            opcode, length = unpack_header(buf, off)
            body = off + 9
            off = body + length
            if off > end:
                raise ValueError("record runs past the end of its chunk")
            if opcode == _OP_MESSAGE:
                cid, seq, log_time, _ = unpack_msg(buf, body)
                st = stats.get(cid)
                if st is None:
                    st = stats[cid] = [0, log_time, log_time, 0, 0, None]
                st[0] += 1
                if log_time < st[2]:
                    st[4] += 1
                    st[1] = min(st[1], log_time)
                else:
                    st[2] = log_time
                if seq and st[5] is not None and seq != st[5] + 1:
                    st[3] += 1
                st[5] = seq
                if keep_channel.get(cid, self.keep and self.wanted is None):
                    messages.setdefault(cid, []).append((log_time, bytes(buf[body + 22:off])))
            elif opcode == _OP_CHANNEL:
                self._channel(bytes(buf[body:off]))
            elif opcode == _OP_SCHEMA:
                from mcap.records import Schema

                schema = _record(Schema, bytes(buf[body:off]))
                self.scan.schemas.setdefault(schema.id, schema)

    def _chunk(self, body: bytes) -> None:
        import zlib

        start, end, size, crc, clen = _CHUNK_FIELDS.unpack_from(body, 0)
        at = _CHUNK_FIELDS.size + clen
        compression = body[_CHUNK_FIELDS.size:at].decode()
        (dlen,) = struct.unpack_from("<Q", body, at)
        data = body[at + 8:at + 8 + dlen]
        try:
            content = _decompress(compression, data, size)
            if crc and zlib.crc32(content) != crc:
                raise ValueError(f"CRC mismatch (expected {crc:#010x})")
            self._messages(memoryview(content), 0, len(content))
        except Exception as exc:  # noqa: BLE001 - skip a corrupt chunk, keep the rest
            self.bad_chunks += 1
            if self.bad_chunks == 1:
                self.scan.issues.append(f"corrupt chunk skipped ({type(exc).__name__}: {exc})")

    def run(self, f, size: int) -> None:
        from mcap.records import Header, Metadata, Statistics

        scan = self.scan
        pos = len(MCAP_MAGIC)
        f.seek(pos)
        while True:
            head = f.read(9)
            if len(head) < 9:
                break
            opcode, length = _REC_HEADER.unpack(head)
            if pos + 9 + length > size:
                break  # the cut of an unfinalized file: a record that was never completed
            body = f.read(length)
            pos += 9 + length
            if opcode == _OP_CHUNK:
                self._chunk(body)
            elif opcode in (_OP_MESSAGE, _OP_CHANNEL, _OP_SCHEMA):  # unchunked files
                self._messages(memoryview(head + body), 0, 9 + length)
            elif opcode == _OP_METADATA:
                record = _record(Metadata, body)
                scan.metadata.append((record.name, dict(record.metadata)))
            elif opcode == _OP_HEADER:
                record = _record(Header, body)
                scan.profile, scan.library = record.profile, record.library
            elif opcode == _OP_STATISTICS:
                scan.statistics = _record(Statistics, body)
            elif opcode == _OP_FOOTER:
                scan.finalized = f.read(len(MCAP_MAGIC)) == MCAP_MAGIC
                if not scan.finalized:
                    scan.issues.append("footer found but the closing MCAP magic is missing or damaged")
                break
        scan.complete_bytes = pos
        if self.bad_chunks > 1:
            scan.issues.append(f"{self.bad_chunks} corrupt chunks skipped in total")


def _scan(path, *, keep_messages: bool, topics: Iterable[str] | None = None) -> _Scan:
    p, f, size = _open_checked(path)
    scan = _Scan(p, size)
    try:
        _Scanner(scan, keep_messages, topics).run(f, size)
    except Exception as exc:  # noqa: BLE001 - damage beyond a clean cut: keep what was read
        scan.issues.append(f"reading stopped at a damaged record ({type(exc).__name__}: {exc})")
    finally:
        f.close()
    if not scan.finalized:
        lost = size - scan.complete_bytes
        scan.issues.insert(0, f"file is NOT finalized (no summary/footer: the writer did not close it, e.g. a "
                              f"crash or kill); recovered {sum(s[0] for s in scan.stats.values())} messages from "
                              f"the complete chunks, {lost} trailing bytes (an unfinished record) are unreadable")
    elif scan.statistics is not None:
        for cid, count in scan.statistics.channel_message_counts.items():
            got = scan.stats.get(cid, [0])[0]
            if got != count:
                topic = scan.channels[cid].topic if cid in scan.channels else f"channel {cid}"
                scan.issues.append(f"{topic}: summary says {count} messages, {got} read")
    if scan.profile and scan.profile != PROFILE:
        scan.issues.append(f"MCAP profile is {scan.profile!r}, not {PROFILE!r}")
    return scan


def _recorded_parameters(scan: _Scan) -> tuple[str | None, dict[str, str]]:
    """(parameters YAML of the last bldc_actuator record that has one, the last record's other keys)."""
    records = [data for name, data in scan.metadata if name == METADATA_NAME]
    text = next((d[PARAMETERS_KEY] for d in reversed(records) if PARAMETERS_KEY in d), None)
    meta = {k: v for k, v in records[-1].items() if k != PARAMETERS_KEY} if records else {}
    return text, meta


def _parameter_issues(scan: _Scan, text: str | None) -> tuple[dict | None, list[str]]:
    issues = []
    if not any(name == METADATA_NAME for name, _ in scan.metadata):
        issues.append(f"no '{METADATA_NAME}' metadata record: the parameters of this run are not in the file")
        return None, issues
    if text is None:
        issues.append(f"the '{METADATA_NAME}' metadata record has no {PARAMETERS_KEY}: parameters missing")
        return None, issues
    try:
        flat = parameters_from_yaml(text)
    except Exception as exc:  # noqa: BLE001 - report, do not fail
        issues.append(f"recorded parameters do not load: {exc}")
        try:
            import yaml

            tree = yaml.safe_load(text)
            return (flatten_tree(tree) if isinstance(tree, Mapping) else None), issues
        except Exception:  # noqa: BLE001
            return None, issues
    if not any(name == METADATA_NAME and d.get("record") == "final" for name, d in scan.metadata):
        if scan.finalized:
            issues.append("no final parameter record (the file was finalized by another writer)")
        else:
            issues.append("parameters come from the last record written before the cut (initial/update): "
                          "changes after it are not known")
    return flat, issues


@dataclass
class Recording:
    """A decoded recording (see the module docstring)."""

    path: Path
    topics: dict[str, list[tuple[int, Any]]]
    types: dict[str, str]
    parameters: dict[str, Any] | None
    parameters_yaml: str | None
    metadata: dict[str, str]
    metadata_records: list[tuple[str, dict[str, str]]]
    finalized: bool
    issues: list[str]
    decoders: dict[str, str]
    profile: str = ""
    library: str = ""

    def __getitem__(self, topic: str) -> list[tuple[int, Any]]:
        try:
            return self.topics[topic]
        except KeyError:
            raise KeyError(f"no topic {topic!r} in {self.path} (topics: {', '.join(sorted(self.topics))})") from None

    def params(self):
        """The recorded model parameters as ActuatorParams (RecordingError when absent)."""
        if self.parameters_yaml is None:
            raise RecordingError(f"{self.path}: no parameters recorded")
        return _model_params(self.parameters_yaml)

    @property
    def start_ns(self) -> int | None:
        firsts = [m[0][0] for m in self.topics.values() if m]
        return min(firsts) if firsts else None

    @property
    def end_ns(self) -> int | None:
        lasts = [m[-1][0] for m in self.topics.values() if m]
        return max(lasts) if lasts else None

    @property
    def duration_s(self) -> float:
        return 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) * 1e-9


def _rclpy_decoder(type_str: str):
    from rclpy.serialization import deserialize_message

    cls = message_class(type_str)
    return lambda data, _cls=cls: deserialize_message(data, _cls)


def _mcap_ros2_decoder(schema, channel):
    from mcap_ros2.decoder import DecoderFactory

    fn = DecoderFactory().decoder_for(channel.message_encoding, schema)
    if fn is None:
        raise LookupError(f"mcap_ros2 cannot decode encoding {channel.message_encoding!r} / schema "
                          f"{getattr(schema, 'encoding', None)!r}")
    return fn


def read_recording(path, *, topics: Iterable[str] | None = None, decoder: str = "auto") -> Recording:
    """Decode a recording (see the module docstring). Raises RecordingError for a missing/non-MCAP file."""
    if decoder not in ("auto", "rclpy", "mcap_ros2"):
        raise ValueError(f"decoder: expected auto, rclpy or mcap_ros2, got {decoder!r}")
    scan = _scan(path, keep_messages=True, topics=topics)
    text, meta = _recorded_parameters(scan)
    flat, param_issues = _parameter_issues(scan, text)
    issues = scan.issues + param_issues
    out_topics: dict[str, list[tuple[int, Any]]] = {}
    types: dict[str, str] = {}
    decoders: dict[str, str] = {}
    wanted = set(topics) if topics is not None else None
    for cid, channel in scan.channels.items():
        if wanted is not None and channel.topic not in wanted:
            continue
        schema = scan.schemas.get(channel.schema_id)
        type_str = schema.name if schema is not None else ""
        types[channel.topic] = type_str
        raw = scan.messages.get(cid, [])
        fn, kind, why = None, "raw", []
        if channel.message_encoding != MESSAGE_ENCODING:
            why.append(f"message encoding {channel.message_encoding!r}")
        else:
            if decoder in ("auto", "rclpy") and type_str:
                try:
                    fn, kind = _rclpy_decoder(type_str), "rclpy"
                except Exception as exc:  # noqa: BLE001 - rclpy or the message package missing
                    why.append(f"rclpy: {type(exc).__name__}: {exc}")
            if fn is None and decoder in ("auto", "mcap_ros2") and schema is not None and schema.encoding:
                try:
                    fn, kind = _mcap_ros2_decoder(schema, channel), "mcap_ros2"
                except Exception as exc:  # noqa: BLE001
                    why.append(f"mcap_ros2: {type(exc).__name__}: {exc}")
        decoders[channel.topic] = kind
        if fn is None:
            if raw:
                issues.append(f"{channel.topic} ({type_str or 'no schema'}): {len(raw)} messages kept as raw CDR "
                              f"bytes, no decoder ({'; '.join(why) or 'no schema'})")
            out_topics[channel.topic] = sorted(raw, key=lambda m: m[0])
            continue
        decoded, failed, first_error = [], 0, None
        for t, data in raw:
            try:
                decoded.append((t, fn(data)))
            except Exception as exc:  # noqa: BLE001 - count and report, keep the rest
                failed += 1
                first_error = first_error or f"{type(exc).__name__}: {exc}"
        if failed:
            issues.append(f"{channel.topic}: {failed} of {len(raw)} messages failed to decode ({first_error})")
        decoded.sort(key=lambda m: m[0])
        out_topics[channel.topic] = decoded
    return Recording(path=scan.path, topics=out_topics, types=types, parameters=flat, parameters_yaml=text,
                     metadata=meta, metadata_records=scan.metadata, finalized=scan.finalized, issues=issues,
                     decoders=decoders, profile=scan.profile, library=scan.library)


def _metadata_only(path) -> _Scan:
    """Metadata records: through the summary's metadata index for a finalized file, else a full scan."""
    p, f, size = _open_checked(path)
    try:
        if size >= 2 * len(MCAP_MAGIC) + 9:
            f.seek(size - len(MCAP_MAGIC))
            if f.read(len(MCAP_MAGIC)) == MCAP_MAGIC:
                from mcap.reader import make_reader

                f.seek(0)
                try:
                    scan = _Scan(p, size, finalized=True)
                    scan.metadata = [(m.name, dict(m.metadata)) for m in make_reader(f).iter_metadata()]
                    return scan
                except Exception:  # noqa: BLE001 - fall back to the full scan
                    pass
    finally:
        f.close()
    return _scan(path, keep_messages=False, topics=())


def parameters_from_recording(path):
    """ActuatorParams recorded in ``path`` (RecordingError when the file has none)."""
    scan = _metadata_only(path)
    text, _ = _recorded_parameters(scan)
    if text is None:
        raise RecordingError(f"{scan.path}: no '{METADATA_NAME}' metadata record with {PARAMETERS_KEY} "
                             "(recorded by another tool, or cut before the recorder wrote it)")
    return _model_params(text)


def summarize(path) -> dict[str, Any]:
    """Topics, counts, rates, times, parameters and issues of a recording, without decoding messages."""
    scan = _scan(path, keep_messages=False)
    text, meta = _recorded_parameters(scan)
    flat, param_issues = _parameter_issues(scan, text)
    topics: dict[str, dict[str, Any]] = {}
    issues = list(scan.issues)
    for cid, channel in sorted(scan.channels.items(), key=lambda kv: kv[1].topic):
        schema = scan.schemas.get(channel.schema_id)
        count, first, last, gaps, backwards, _ = scan.stats.get(cid, [0, None, None, 0, 0, None])
        rate = (count - 1) / ((last - first) * 1e-9) if count > 1 and last > first else None
        topics[channel.topic] = {
            "type": schema.name if schema is not None else "",
            "count": count,
            "first_ns": first,
            "last_ns": last,
            "rate_hz": rate,
            "message_encoding": channel.message_encoding,
            "schema_encoding": schema.encoding if schema is not None else "",
            "type_hash": channel.metadata.get("topic_type_hash", ""),
            "sequence_gaps": gaps,
        }
        if schema is None or not schema.encoding:
            issues.append(f"{channel.topic}: no message definition (schema) in the file")
        if channel.message_encoding != MESSAGE_ENCODING:
            issues.append(f"{channel.topic}: message encoding {channel.message_encoding!r}, expected 'cdr'")
        if gaps:
            issues.append(f"{channel.topic}: {gaps} gap(s) in the message sequence numbers (messages lost)")
        if backwards:
            issues.append(f"{channel.topic}: log time goes backwards {backwards} time(s)")
    issues += param_issues
    starts = [t["first_ns"] for t in topics.values() if t["count"]]
    ends = [t["last_ns"] for t in topics.values() if t["count"]]
    start, end = (min(starts), max(ends)) if starts else (None, None)
    return {
        "path": str(scan.path),
        "file_size": scan.file_size,
        "finalized": scan.finalized,
        "profile": scan.profile,
        "library": scan.library,
        "topics": topics,
        "message_count": sum(t["count"] for t in topics.values()),
        "start_ns": start,
        "end_ns": end,
        "duration_s": (end - start) * 1e-9 if start is not None else 0.0,
        "parameters_present": text is not None,
        "parameters": {k: _plain(v) for k, v in flat.items()} if flat is not None else None,
        "metadata": meta,
        "issues": issues,
    }


def as_level(level: Any) -> int:
    """A DiagnosticStatus level as int, whichever decoder produced it (rclpy: ``b'\\x01'``; mcap_ros2: 1)."""
    if isinstance(level, (bytes, bytearray)):
        return level[0] if level else 0
    return int(level)


__all__ = [
    "McapRecorder", "Recording", "RecordingError", "RecorderClosedError", "RecordingWriteError", "install_signal_finalizer",
    "read_recording", "summarize", "parameters_from_recording", "message_definition", "type_hash",
    "type_name", "qos_yaml", "render_parameters", "parameters_from_yaml", "as_level",
    "DEFAULT_CHUNK_SIZE", "METADATA_NAME", "PARAMETERS_KEY",
]
