"""The type system of a recording: ROS 2 message type names, their ``ros2msg`` definitions and RIHS01 type
hashes exactly as rosbag2's MCAP plugin writes them, the rclpy message classes, and QoS profiles in rosbag2's
``offered_qos_profiles`` YAML. Pure Python: no rclpy needed except for :func:`message_class`."""

from __future__ import annotations

import importlib
import importlib.util
import json
import os
import re
import sys
from pathlib import Path
from typing import Any, Mapping

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
#: rmw's "infinite" duration as rosbag2 writes it (RMW_DURATION_INFINITE)
_INFINITE = (9223372036, 854775807)
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
