"""ROS 2 MCAP recordings -> raw :class:`~..signals.Signals`: this project's own recordings by their topics,
foreign ones through a :class:`~.mapping.Mapping` (``topic.field[index]``). Fields are read straight from the
CDR bytes with the file's own message schemas."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from ..signals import COMMAND_CHANNELS, DataIssue, Signals
from .mapping import LoadError, Mapping

#: default mapping for this project's own recordings (topics of ``actuator_node``; ``~`` = node namespace)
OWN_TOPICS = {
    "current": ("q_axis_state", "i_q"),
    "current_d": ("q_axis_state", "i_d"),
    "current_command": ("q_axis_state", "i_q_ref"),
    "voltage_q": ("q_axis_state", "v_q"),
    "voltage_d": ("q_axis_state", "v_d"),
    "bus_voltage": ("q_axis_state", "bus_voltage"),
    "velocity": ("q_axis_state", "omega"),
    "position": ("joint_states", "position[0]"),        # output side -> x gear ratio
    "winding_temperature": ("winding_temperature", "temperature"),
    "housing_temperature": ("housing_temperature", "temperature"),
    "torque_command": ("torque_command", "data"),
    "load_torque": ("load_torque", "data"),
}
#: channels that hold their last value between messages (commands, set-points); others are interpolated
HOLD_CHANNELS = set(COMMAND_CHANNELS) | {"load_torque"}

# ------------------------------------------------------------------------ CDR field extraction by schema
# A ROS 2 message in an MCAP file is CDR bytes; the channel's schema (encoding ros2msg) is the .msg text
# with its dependencies. From it we compute the byte offset of every numeric field of one message; when
# all messages of a topic have the same length and the same offsets (the usual case: fixed-size arrays,
# same joint names / labels), each requested field is read for all messages at once with numpy.

_PRIM = {"bool": "u1", "byte": "u1", "char": "u1", "int8": "i1", "uint8": "u1", "int16": "<i2", "uint16": "<u2",
         "int32": "<i4", "uint32": "<u4", "int64": "<i8", "uint64": "<u8", "float32": "<f4", "float64": "<f8"}


class _Unsupported(Exception):
    pass


def _norm_type(name: str, pkg: str) -> str:
    name = name.replace("/msg/", "/")
    if "/" in name:
        return name
    if name == "Header":
        return "std_msgs/Header"
    return f"{pkg}/{name}"


def parse_ros2msg(root: str, text: str) -> dict[str, list[tuple[str, str, str, int]]]:
    """``{type: [(base type, field name, array kind '' | 'seq' | 'fixed', fixed length), ...]}`` from a
    ros2msg schema (``root`` is the schema name, ``pkg/msg/Type``)."""
    sections = re.split(r"^=+\s*$", text, flags=re.M)
    types: dict[str, list] = {}
    for k, sec in enumerate(sections):
        lines = sec.strip("\n").splitlines()
        if k == 0:
            tname = root.replace("/msg/", "/")
        else:
            first = next((ln for ln in lines if ln.strip()), "")
            if not first.startswith("MSG:"):
                continue
            tname = first.split(":", 1)[1].strip().replace("/msg/", "/")
            lines = lines[lines.index(first) + 1:]
        pkg = tname.split("/")[0]
        fields = []
        for ln in lines:
            ln = ln.split("#", 1)[0].strip()
            tok = ln.split()
            if len(tok) < 2 or "=" in tok[1] or re.match(r"^\S+\s+\w+\s*=", ln):
                continue                                    # blank, or a constant NAME=value
            ftype, fname = ln.split()[:2]
            kind, n = "", 0
            m = re.match(r"^(.*?)\[(<=)?(\d*)\]$", ftype)
            if m:
                ftype = m.group(1)
                if m.group(3) and not m.group(2):
                    kind, n = "fixed", int(m.group(3))
                else:
                    kind = "seq"
            ftype = re.sub(r"<=\d+$", "", ftype)           # bounded string
            if ftype not in _PRIM and ftype not in ("string", "wstring"):
                ftype = _norm_type(ftype, pkg)
            fields.append((ftype, fname, kind, n))
        types[tname] = fields
    return types


def _walk(buf: bytes, types: dict, tname: str) -> tuple[dict[str, tuple[int, str]], dict[str, str]]:
    """Offsets ``path -> (byte offset, dtype)`` of every numeric leaf of one message, and its strings."""
    if len(buf) < 4 or buf[1] != 1:
        raise _Unsupported("not little-endian plain CDR")
    nums: dict[str, tuple[int, str]] = {}
    strs: dict[str, str] = {}
    pos = 4

    def align(n: int) -> None:
        nonlocal pos
        pos += (-(pos - 4)) % n

    def u32() -> int:
        nonlocal pos
        align(4)
        v = int.from_bytes(buf[pos:pos + 4], "little")
        pos += 4
        return v

    def one(ftype: str, path: str) -> None:
        nonlocal pos
        if ftype in _PRIM:
            size = int(_PRIM[ftype][-1])
            align(size)
            if pos + size > len(buf):
                raise _Unsupported("message shorter than its schema")
            nums[path] = (pos, _PRIM[ftype])
            pos += size
        elif ftype == "string":
            n = u32()
            strs[path] = buf[pos:pos + max(0, n - 1)].decode("utf-8", "replace")
            pos += n
        elif ftype == "wstring":
            raise _Unsupported("wstring")
        else:
            sub = types.get(ftype)
            if sub is None:
                raise _Unsupported(f"type {ftype} not in the schema")
            for st, sn, sk, sl in sub:
                field(st, sn, sk, sl, f"{path}.{sn}" if path else sn)

    def field(ftype: str, name: str, kind: str, n: int, path: str) -> None:
        if kind == "":
            one(ftype, path)
            return
        count = n if kind == "fixed" else u32()
        if count > len(buf):
            raise _Unsupported("implausible sequence length")
        for i in range(count):
            one(ftype, f"{path}[{i}]")

    for ft, fn, fk, fl in types[tname]:
        field(ft, fn, fk, fl, fn)
    return nums, strs


def _resolve_path(fld: str, nums: dict, strs: dict) -> str | None:
    """A mapping field (``i_q`` label, ``position[joint]`` name, ``data[3]``, ``temperature``) -> leaf path."""
    if fld in nums:
        return fld
    labels = strs.get("layout.dim[0].label", "")
    if labels and "," in labels:
        names = [x.strip() for x in labels.split(",")]
        if fld in names and f"data[{names.index(fld)}]" in nums:
            return f"data[{names.index(fld)}]"
    m = re.match(r"^(.*)\[([^\]]+)\]$", fld)
    if m and not m.group(2).isdigit():
        base, key = m.group(1), m.group(2)
        for path, val in strs.items():
            mm = re.match(r"^name\[(\d+)\]$", path)
            if mm and val == key and f"{base}[{mm.group(1)}]" in nums:
                return f"{base}[{mm.group(1)}]"
    return None


def _extract_topic(raws: list[tuple[int, bytes]], root: str, schema_text: str, fields: list[str],
                   topic: str) -> tuple[np.ndarray, dict[str, np.ndarray], str]:
    """(times [ns], field -> values, how). Vectorised when every message has the same layout."""
    types = parse_ros2msg(root, schema_text)
    tname = root.replace("/msg/", "/")
    if tname not in types:
        raise _Unsupported(f"schema of {topic} does not define {root}")
    t_log = np.fromiter((t for t, _ in raws), dtype=np.int64, count=len(raws))
    first_nums, first_strs = _walk(raws[0][1], types, tname)
    paths = {}
    for f in fields + ["header.stamp.sec", "header.stamp.nanosec"]:
        pth = _resolve_path(f, first_nums, first_strs)
        if pth is None and f in fields:
            avail = sorted(set(first_nums) | {x.strip() for x in first_strs.get("layout.dim[0].label", "").split(",")
                                              if x.strip()})
            raise LoadError(f"topic {topic} has no numeric field {f!r} (fields: {', '.join(avail[:40])})")
        if pth is not None:
            paths[f] = pth
    lengths = {len(d) for _, d in raws}
    same = len(lengths) == 1
    if same:
        for k in (len(raws) // 2, len(raws) - 1):
            nums_k, strs_k = _walk(raws[k][1], types, tname)
            if any(nums_k.get(p) != first_nums[p] for p in paths.values()) or \
                    strs_k.get("layout.dim[0].label") != first_strs.get("layout.dim[0].label") or \
                    any(strs_k.get(k2) != v for k2, v in first_strs.items() if k2.startswith("name[")):
                same = False
                break
    out: dict[str, np.ndarray] = {}
    if same:
        L = lengths.pop()
        block = np.frombuffer(b"".join(d for _, d in raws), dtype=np.uint8).reshape(len(raws), L)
        for f, pth in paths.items():
            off, dt = first_nums[pth]
            size = np.dtype(dt).itemsize
            out[f] = np.ascontiguousarray(block[:, off:off + size]).view(dt).ravel().astype(float)
        how = "cdr-vectorised"
    else:
        cols = {f: np.full(len(raws), np.nan) for f in paths}
        for i, (_, d) in enumerate(raws):
            nums_i, strs_i = _walk(d, types, tname)
            for f in paths:
                pth = _resolve_path(f, nums_i, strs_i)
                if pth is not None:
                    off, dt = nums_i[pth]
                    cols[f][i] = float(np.frombuffer(d, dtype=dt, count=1, offset=off)[0])
        out = cols
        how = "cdr-per-message"
    t = t_log
    if "header.stamp.sec" in out and "header.stamp.nanosec" in out:
        st = out.pop("header.stamp.sec").astype(np.int64) * 1_000_000_000 + out.pop("header.stamp.nanosec").astype(np.int64)
        if np.any(st > 0):                 # publishers that never stamp leave all zeros
            t = st
            how += ", time=header.stamp"
    else:
        out.pop("header.stamp.sec", None)
        out.pop("header.stamp.nanosec", None)
    return t, {f: out[f] for f in fields}, how


def _decode_topic_generic(raws, schema, channel, fields: list[str], topic: str):
    """Slow, general fallback: decode each message (mcap_ros2) and pick the fields."""
    from mcap_ros2.decoder import DecoderFactory

    fn = DecoderFactory().decoder_for(channel.message_encoding, schema)
    if fn is None:
        raise LoadError(f"cannot decode topic {topic} ({channel.message_encoding}, {schema.name})")
    t = np.empty(len(raws), dtype=np.int64)
    cols = {f: np.full(len(raws), np.nan) for f in fields}
    for i, (tl, data) in enumerate(raws):
        msg = fn(data)
        flat: dict[str, float] = {}
        _flatten(msg, "", flat)
        st = _stamp_ns(msg)
        t[i] = st if st is not None else tl
        for f in fields:
            if f in flat:
                cols[f][i] = flat[f]
            elif i == 0:
                raise LoadError(f"topic {topic} has no numeric field {f!r} (fields: {', '.join(sorted(flat)[:40])})")
    return t, cols, "mcap_ros2-decoded"


def _flatten(obj: Any, prefix: str, out: dict[str, float]) -> None:
    """Numeric leaves of a decoded message as ``prefix.field[index]`` -> float."""
    if isinstance(obj, bool):
        out[prefix] = float(obj)
        return
    if isinstance(obj, (int, float)):
        out[prefix] = float(obj)
        return
    if isinstance(obj, (str, bytes)):
        return
    if isinstance(obj, (list, tuple, np.ndarray, memoryview)) or hasattr(obj, "tolist") and not hasattr(obj, "__slots__"):
        seq = list(obj)
        for i, v in enumerate(seq):
            _flatten(v, f"{prefix}[{i}]", out)
        return
    fields = None
    if hasattr(obj, "get_fields_and_field_types"):
        fields = list(obj.get_fields_and_field_types())
    elif hasattr(obj, "__slots__"):
        fields = [s for s in obj.__slots__ if not s.startswith("_")]
    elif hasattr(obj, "__dict__"):
        fields = [k for k in vars(obj) if not k.startswith("_")]
    if not fields:
        return
    for name in fields:
        try:
            v = getattr(obj, name)
        except AttributeError:
            continue
        _flatten(v, f"{prefix}.{name}" if prefix else name, out)
    # labelled Float64MultiArray (this node): data elements also by label
    if "layout" in fields and "data" in fields:
        try:
            dims = obj.layout.dim
            labels = dims[0].label.split(",") if dims else []
            data = list(obj.data)
            if len(labels) == len(data) and len(labels) > 1:
                for lab, v in zip(labels, data):
                    out[f"{prefix}.{lab.strip()}" if prefix else lab.strip()] = float(v)
        except Exception:  # noqa: BLE001 - an unusual layout is simply not labelled
            pass
    # JointState-like: arrays indexed by joint name too
    if "name" in fields:
        try:
            names = list(obj.name)
            for arr in ("position", "velocity", "effort"):
                vals = list(getattr(obj, arr, []) or [])
                for n, v in zip(names, vals):
                    out[f"{prefix}.{arr}[{n}]" if prefix else f"{arr}[{n}]"] = float(v)
        except Exception:  # noqa: BLE001
            pass




def _stamp_ns(msg: Any) -> int | None:
    h = getattr(msg, "header", None)
    st = getattr(h, "stamp", None) if h is not None else None
    if st is None:
        return None
    t = int(getattr(st, "sec", 0)) * 1_000_000_000 + int(getattr(st, "nanosec", 0))
    return t if t > 0 else None


def _mcap_raw(path: Path, topics: set[str] | None):
    """(channels {id: Channel}, schemas {id: Schema}, messages {channel id: [(log_time, bytes)]},
    metadata [(name, dict)], notes). Uses the public raw reader of :mod:`bldc_actuator.recording`
    (``read_raw``: fast, and it recovers unfinalized files); falls back to the mcap library."""
    notes: list[str] = []
    try:
        from ...recording import read_raw

        raw = read_raw(path, topics=topics)
        notes += [f"recording: {i}" for i in raw.issues]
        return raw.channels, raw.schemas, raw.messages, list(raw.metadata), notes
    except ImportError:
        pass
    except Exception as exc:  # noqa: BLE001 - RecordingError and friends
        raise LoadError(f"{path}: {exc}") from None
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None:
                raise LoadError(f"{path}: MCAP file has no summary (recording not finished?)")
            msgs: dict[int, list] = {}
            for _, ch, m in reader.iter_messages(topics=list(topics) if topics is not None else None):
                msgs.setdefault(ch.id, []).append((m.log_time, m.data))
            meta = [(r.name, dict(r.metadata)) for r in reader.iter_metadata()]
    except OSError as exc:
        raise LoadError(f"{path}: cannot read: {exc.strerror}") from None
    except LoadError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise LoadError(f"{path}: not a readable MCAP file ({type(exc).__name__}: {exc})") from None
    return summary.channels, summary.schemas, msgs, meta, notes


def mcap_topics(path: Path) -> dict[str, str]:
    """topic -> type, from the summary (fast) or a message-free scan (unfinalized files)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except OSError as exc:
        raise LoadError(f"{path}: cannot read: {exc.strerror}") from None
    except Exception:  # noqa: BLE001
        summary = None
    if summary is not None:
        return {ch.topic: (summary.schemas[ch.schema_id].name if ch.schema_id in summary.schemas else "")
                for ch in summary.channels.values()}
    channels, schemas, _, _, _ = _mcap_raw(path, set())
    return {ch.topic: (schemas[ch.schema_id].name if ch.schema_id in schemas else "") for ch in channels.values()}


def _find_topic(ref: str, topics: list[str]) -> tuple[str, str]:
    """Split ``topic.field`` against the known topics (longest match; a unique suffix is enough)."""
    best = None
    for t in topics:
        if ref.startswith(t + ".") and (best is None or len(t) > len(best)):
            best = t
    if best is not None:
        return best, ref[len(best) + 1:]
    # suffix match: "q_axis_state.i_q" -> "/ns/bldc_actuator/q_axis_state"
    cands = []
    parts = ref.split(".")
    for t in topics:
        for k in range(1, len(parts)):
            head = ".".join(parts[:k])
            if head and (t == head or t.endswith("/" + head.lstrip("/"))):
                cands.append((t, ref[len(head) + 1:]))
    uniq = {c[0] for c in cands}
    if len(uniq) == 1:
        return cands[0]
    if len(uniq) > 1:
        raise LoadError(f"mapping source {ref!r} matches several topics: {', '.join(sorted(uniq))}")
    raise LoadError(f"mapping source {ref!r}: no such topic (topics: {', '.join(sorted(topics))})")


def _resample(t_src: np.ndarray, v_src: np.ndarray, t_dst: np.ndarray, hold: bool, fill_before=np.nan) -> np.ndarray:
    """Put one topic's samples on the common time axis: exact matches copied; otherwise zero-order hold
    (``hold``) or linear interpolation, never across a gap of more than 5 median periods (NaN there)."""
    ok = np.isfinite(v_src)
    t_src, v_src = t_src[ok], v_src[ok]
    out = np.full(len(t_dst), np.nan)
    if len(t_src) == 0:
        return out
    order = np.argsort(t_src, kind="stable")
    t_src, v_src = t_src[order], v_src[order]
    if hold:
        idx = np.searchsorted(t_src, t_dst, side="right") - 1
        good = idx >= 0
        out[good] = v_src[idx[good]]
        out[~good] = fill_before
        return out
    if len(t_src) == 1:
        out[t_dst == t_src[0]] = v_src[0]
        return out
    out = np.interp(t_dst, t_src, v_src, left=np.nan, right=np.nan)
    dt = np.diff(t_src)
    med = np.median(dt[dt > 0]) if np.any(dt > 0) else 0.0
    j = np.clip(np.searchsorted(t_src, t_dst, side="right"), 1, len(t_src) - 1)
    span = t_src[j] - t_src[j - 1]
    exact = np.isin(t_dst, t_src)
    out[(span > 5 * med) & ~exact] = np.nan
    return out



def _own_recording(topics: dict[str, str]) -> bool:
    return any(t.endswith("/q_axis_state") for t in topics) and any(t.endswith("joint_states") for t in topics)


def _recorded_parameters(metadata: list[tuple[str, dict]]) -> dict | None:
    """Flat parameters from the last ``bldc_actuator`` metadata record with ``parameters_yaml``."""
    text = None
    for name, rec in metadata:
        if name == "bldc_actuator" and "parameters_yaml" in rec:
            text = rec["parameters_yaml"]
    if text is None:
        return None
    try:
        from ...recording import parameters_from_yaml

        return parameters_from_yaml(text)
    except Exception:  # noqa: BLE001 - unreadable parameters: loaded without them (noted by the caller)
        return None


def declared_pairs(metadata: list[tuple[str, dict]], joint: str | None) -> dict[str, str]:
    """The declarations (:mod:`bldc_actuator.voltage_timing`, :mod:`bldc_actuator.drive_tuning`) of the last
    ``bldc_actuator`` metadata record, a joint's own keys (``<key>.<joint>``) over the record's."""
    from ... import drive_tuning
    from ... import voltage_timing as vt

    keys = (vt.CONVENTION_KEY, vt.OFFSET_KEY, *drive_tuning.KEYS)
    rec = None
    for name, r in metadata:
        if name == "bldc_actuator" and isinstance(r, dict) and any(k in r for k in keys):
            rec = r
    if rec is None:
        return {}
    decl = {k: rec[k] for k in keys if k in rec}
    if joint is not None:
        decl.update({k: rec[f"{k}.{joint}"] for k in keys if f"{k}.{joint}" in rec})
    return decl


def declared_voltage_timing(metadata: list[tuple[str, dict]], joint: str | None, path: Path):
    """The voltage timing the last ``bldc_actuator`` metadata record declares (:func:`declared_pairs`), or None; a
    malformed one, or a malformed drive tuning beside it, is a :class:`LoadError`."""
    from ... import drive_tuning
    from ... import voltage_timing as vt

    decl = declared_pairs(metadata, joint)
    where = "MCAP metadata record bldc_actuator" + (f", joint {joint}" if joint else "")
    try:
        drive_tuning.from_metadata(decl, where)
        return vt.from_metadata(decl, where) if vt.CONVENTION_KEY in decl else None
    except ValueError as exc:
        raise LoadError(f"{path}: {exc}") from None


def _params_from_flat(flat: dict | None):
    if not flat:
        return None
    from ...params import SPECS, from_flat

    try:
        return from_flat({k: (tuple(v) if isinstance(v, list) else v) for k, v in flat.items() if k in SPECS})
    except Exception:  # noqa: BLE001 - a recording with odd parameters still loads; note it
        return None



def _joint_parameters(flat: dict | None, joint: str) -> dict | None:
    """One joint's model parameters from the flat parameters of a multi-joint recording."""
    if not flat:
        return None
    prefix = f"joint.{joint}."
    mine = {k[len(prefix):]: v for k, v in flat.items() if k.startswith(prefix)}
    return mine or None


def load_mcap(path: str | Path, mapping: Mapping | None = None, params=None, joint: str | None = None) -> Signals:
    """A ROS 2 MCAP recording.

    This project's own recordings (``joint_states`` + ``~/q_axis_state`` present) load without a mapping:
    q-axis state gives current, current_d, current_command (``i_q_ref``, the reference after the drive's
    limits), voltage_q/d, bus_voltage and velocity (motor side); ``joint_states`` position is OUTPUT side
    and is multiplied by the gear ratio of the parameters stored in the recording (``--params`` when the
    file has none); temperatures; ``~/torque_command`` and ``~/load_torque`` (held between messages; 0
    before the first one, as in the node). A ``mapping`` adds to / overrides this default. Foreign
    recordings need a mapping (``topic.field[index]`` per canonical channel). A recording of several joints
    (``actuator_node -p joints:=[...]``) loads one joint: ``joint`` (its ``~/<joint>/...`` topics, its entry of
    ``joint_states`` and its own parameters); without ``joint`` it is an error naming the joints.

    Fields are read straight from the CDR bytes using the file's own message schemas (vectorised when a
    topic's messages share one layout, the usual case; about 1 s for 60 s of the node at 1 kHz). Message
    time is ``header.stamp`` when a topic's messages carry one (not all zero), else the MCAP log time.
    The common time axis is the topic that supplies ``current`` (else velocity, torque, position, or the
    largest); other topics are copied where their times coincide, else interpolated (measurements) or
    held (commands), and NaN across their own gaps.
    """
    path = Path(path)
    if not path.exists():
        raise LoadError(f"{path}: no such file")
    mapping = mapping or Mapping()
    topic_types = mcap_topics(path)
    topic_names = list(topic_types)
    own = _own_recording(topic_types)

    plan: dict[str, tuple[str, str, float, float]] = {}
    notes: list[str] = []
    q_topics = [t for t in topic_names if t.endswith("/q_axis_state")]
    joints = sorted(t.rsplit("/", 2)[-2] for t in q_topics) if own and len(q_topics) > 1 else []
    if joints and joint is None:
        raise LoadError(f"{path}: a recording of several joints ({', '.join(joints)}): choose one with --joint NAME")
    if joints and joint not in joints:
        raise LoadError(f"{path}: no joint {joint!r} in this recording (joints: {', '.join(joints)})")
    if own:
        for target, (suffix, fld) in OWN_TOPICS.items():
            if joints and suffix != "joint_states":
                suffix = f"{joint}/{suffix}"
            elif joints:
                fld = fld.replace("[0]", f"[{joint}]")
            hits = [t for t in topic_names if t == suffix or t.endswith("/" + suffix)]
            if len(hits) == 1:
                plan[target] = (hits[0], fld, 1.0, 0.0)
    for target, src in mapping.columns.items():
        if target == "time":
            raise LoadError(f"{path}: the time of an MCAP recording comes from its messages, not --map time=")
        try:
            topic, fld = _find_topic(src, topic_names)
        except LoadError as exc:
            raise LoadError(f"{path}: {exc}") from None
        plan[target] = (topic, fld, mapping.scale.get(target, 1.0), mapping.offset.get(target, 0.0))
    if not plan:
        raise LoadError(f"{path}: not a bldc_actuator recording (no joint_states + q_axis_state) and no mapping "
                        f"given; map channels, e.g. --map current=/motor/iq.data "
                        f"(topics: {', '.join(f'{t} [{ty}]' for t, ty in sorted(topic_types.items()))})")
    channels_by_id, schemas, messages, metadata, scan_notes = _mcap_raw(path, {p[0] for p in plan.values()})
    notes += scan_notes
    by_topic = {ch.topic: ch for ch in channels_by_id.values()}
    rec_params = _recorded_parameters(metadata) if own else None
    if own and joints:
        rec_params = _joint_parameters(rec_params, joint)
        notes.append(f"joint {joint} of a recording of {len(joints)} joints ({', '.join(joints)})")
    params_rec = _params_from_flat(rec_params)
    if own and rec_params is None:
        notes.append("no parameters stored in the recording")

    gear = None
    if params_rec is not None:
        gear = float(params_rec.gear.gear_ratio)
    elif params is not None:
        gear = float(params.gear.gear_ratio)
        if own:
            notes.append(f"gear ratio {gear:g} taken from --params")
    load_side = params_rec is not None and getattr(params_rec.gear, "encoder_side", "motor") == "load"
    if own and load_side and "position" in plan and "position" not in mapping.columns \
            and "load_position" not in mapping.columns:
        # gear.encoder_side: load -> the node's joint_states position is the LOAD's angle behind the transmission
        # (output side); the rotor's angle is not recorded (its speed is: q_axis_state omega)
        plan["load_position"] = plan.pop("position")
        notes.append("joint_states position is the load's angle (gear.encoder_side: load): read as load_position "
                     "(output side); the rotor's angle is not in the recording")
    if own and "position" in plan and "position" not in mapping.columns:
        if gear is None:
            plan.pop("position")
            notes.append("joint_states position is output side and no gear ratio is known: position omitted")
        else:
            t_, f_, s_, o_ = plan["position"]
            plan["position"] = (t_, f_, s_ * gear, o_ * gear)

    # extract: one pass per topic for all of its fields
    fields_by_topic: dict[str, list[str]] = {}
    for target, (topic, fld, _, _) in plan.items():
        fields_by_topic.setdefault(topic, [])
        if fld not in fields_by_topic[topic]:
            fields_by_topic[topic].append(fld)
    extracted: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
    how: dict[str, str] = {}
    missing: list[str] = []
    for topic, flds in fields_by_topic.items():
        ch = by_topic.get(topic)
        raws = messages.get(ch.id, []) if ch is not None else []
        if not raws:
            continue
        raws = sorted(raws, key=lambda m: m[0])
        schema = schemas.get(ch.schema_id)
        if schema is None:
            raise LoadError(f"{path}: topic {topic} has no schema: cannot read its fields")
        try:
            if schema.encoding != "ros2msg":
                raise _Unsupported(schema.encoding)
            t_ns, vals, h = _extract_topic(raws, schema.name, schema.data.decode("utf-8", "replace"), flds, topic)
        except _Unsupported:
            t_ns, vals, h = _decode_topic_generic(raws, schema, ch, flds, topic)
        except LoadError as exc:
            raise LoadError(f"{path}: {exc}") from None
        extracted[topic] = (t_ns, vals)
        how[topic] = h
    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for target, (topic, fld, s_, o_) in plan.items():
        if topic not in extracted:
            if target in mapping.columns:
                missing.append(target)
            continue
        t_ns, vals = extracted[topic]
        series[target] = (t_ns, vals[fld] * s_ + o_)
    if not series:
        raise LoadError(f"{path}: none of the mapped topics has messages ({', '.join(sorted(plan))})")
    base_target = next((t for t in ("current", "velocity", "torque", "position") if t in series), None)
    if base_target is None:
        base_target = max(series, key=lambda k: len(series[k][0]))
    base_ns = series[base_target][0]
    t_base, first = np.unique(base_ns, return_index=True)
    t0 = int(t_base[0])
    time_axis = (t_base - t0) * 1e-9
    chans: dict[str, np.ndarray] = {}
    for target, (t_ns, vals) in series.items():
        if plan[target][0] == plan[base_target][0]:
            chans[target] = vals[first]
            continue
        fill = 0.0 if (own and target in HOLD_CHANNELS and target not in mapping.columns) else np.nan
        chans[target] = _resample((t_ns - t0) * 1e-9, vals, time_axis, target in HOLD_CHANNELS, fill)
    if own and "load_torque" not in chans and any(t.endswith("/load_torque") for t in topic_names):
        chans["load_torque"] = np.zeros(len(time_axis))
        notes.append("no ~/load_torque message: extra load 0 all along (params.load.* still apply)")
    issues = [DataIssue("missing_channel", t, 0, None, f"{t}: mapped topic {plan[t][0]} has no messages", "none")
              for t in missing]
    dup = len(base_ns) - len(t_base)
    if dup:
        issues.append(DataIssue("duplicate_time", "time", dup, None,
                                f"{dup} messages of {plan[base_target][0]} repeat an earlier timestamp",
                                "dropped later duplicate"))
    semantics = {t: f"{plan[t][0]}.{plan[t][1]}" + (f" x {plan[t][2]:g}" if plan[t][2] != 1 else "")
                 + (f" {plan[t][3]:+g}" if plan[t][3] else "") for t in chans if t in plan}
    if own:
        semantics["current_command"] = "q_axis_state.i_q_ref: current reference after the drive's limits"
        semantics["load_torque"] = "~/load_torque: external load in ADDITION to params.load.* (as set_load_torque)"
        if "position" in semantics:
            semantics["position"] = (f"joint_states.position[{joint if joints else 0}] (output side) x gear "
                                     f"ratio {gear:g}")
    meta_start, meta_aid = None, None
    for name, rec in metadata:              # the recording's own start time and actuator id, when it says
        if isinstance(rec, dict) and rec.get("start_time"):
            meta_start = (str(rec["start_time"]), f"recording metadata ({name}.start_time)")
        if isinstance(rec, dict) and rec.get("actuator_id"):
            meta_aid = str(rec["actuator_id"])
    timing = declared_voltage_timing(metadata, joint if joints else None, path)
    if timing is not None:
        notes.append(f"the recording declares its voltage timing: {timing.convention}"
                     + (f" (acts {1e6 * timing.acts_after_sample_s:+.3g} µs after its sample)"
                        if timing.acts_after_sample_s is not None else ""))
    meta = {"format": "mcap", "own_recording": own, "joint": joint if joints else None, "voltage_timing": timing,
            "declared": declared_pairs(metadata, joint if joints else None),
            "mapping": mapping.describe(), "semantics": semantics,
            "notes": notes, "gear_ratio": gear, "params_from_recording": params_rec,
            "recorded_parameters": rec_params, "time_base": plan[base_target][0], "t0_ns": t0,
            "topics": topic_types, "extraction": how}
    if meta_start:
        meta["start_time"], meta["start_time_source"] = meta_start
    if meta_aid:
        meta["actuator_id"] = meta_aid
    return Signals(time_axis, chans, str(path), issues, [], meta)
