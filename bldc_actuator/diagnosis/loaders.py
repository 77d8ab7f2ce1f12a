"""Read recordings into raw :class:`~.signals.Signals` (canonical names, SI, motor side).

* :func:`load` dispatches by suffix: ``.csv``/``.tsv``/``.txt`` -> :func:`load_csv`, ``.mcap`` ->
  :func:`load_mcap`. A CSV inside one of the known real datasets (``../shared/data``) without canonical
  columns and without a mapping is handed to :mod:`.realdata`, which knows its semantics.
* :class:`Mapping` renames and scales: ``--map current=iq_measured --map velocity=speed*9
  --map torque=-adc_torque`` or a YAML file. Expressions: ``[k*][-]SOURCE[*k|/k|+k|-k]...`` applied left
  to right, i.e. ``value = scale * raw + offset``. SOURCE is a CSV column name (quote it, ``"a-b"``, when
  it contains operators), ``#3`` (the 4th column of a header-less CSV) or, for MCAP,
  ``topic.field[index]`` (``/joint_states.velocity[0]``, ``/motor/iq.data``, a labelled
  Float64MultiArray element ``/x/q_axis_state.i_q``, a JointState entry by joint name
  ``/joint_states.velocity[wrist]``). A topic may be given by its unique suffix (``q_axis_state.i_q``).

Loaders only translate; they never mask or drop samples (except rows with nothing parseable, which
are reported). Problems are found and reported by :func:`.cleaning.clean`.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .signals import CANONICAL, COMMAND_CHANNELS, DataIssue, Signals

#: mapping targets: the canonical channels plus the time axis
TARGETS = ("time",) + tuple(CANONICAL)


class LoadError(ValueError):
    """A recording cannot be read; the message names the file, and the line or field where it applies."""


# ============================================================================================ Mapping

_NUM = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_TRAIL = re.compile(r"\s*([*/+\-])\s*(" + _NUM + r")\s*$")
_LEAD_MUL = re.compile(r"^\s*(" + _NUM + r")\s*\*\s*")


def parse_expression(expr: str) -> tuple[str, float, float]:
    """``"-adc*2+0.5"`` -> (source ``adc``, scale -2, offset 0.5). Raises ValueError with the reason."""
    text = expr.strip()
    if not text:
        raise ValueError("empty expression")
    scale, offset = 1.0, 0.0
    m = _LEAD_MUL.match(text)
    if m:
        scale = float(m.group(1))
        text = text[m.end():]
    if text.startswith("-") and len(text) > 1 and not text[1].isdigit():
        scale = -scale
        text = text[1:].lstrip()
    ops: list[tuple[str, float]] = []
    if text.startswith('"') or text.startswith("'"):
        q = text[0]
        end = text.find(q, 1)
        if end < 0:
            raise ValueError(f"unterminated quote in {expr!r}")
        source, rest = text[1:end], text[end + 1:]
        while rest.strip():
            m = re.match(r"\s*([*/+\-])\s*(" + _NUM + r")", rest)
            if not m:
                raise ValueError(f"cannot read {rest.strip()!r} after the quoted name in {expr!r} "
                                 "(expected *k, /k, +k or -k)")
            ops.append((m.group(1), float(m.group(2))))
            rest = rest[m.end():]
    else:
        source = text
        while True:
            m = _TRAIL.search(source)
            if not m or m.start() == 0:
                break
            ops.insert(0, (m.group(1), float(m.group(2))))
            source = source[:m.start()]
        source = source.strip()
    if not source:
        raise ValueError(f"no source column in {expr!r}")
    for op, k in ops:
        if op == "*":
            scale, offset = scale * k, offset * k
        elif op == "/":
            if k == 0:
                raise ValueError(f"division by zero in {expr!r}")
            scale, offset = scale / k, offset / k
        elif op == "+":
            offset += k
        else:
            offset -= k
    return source, scale, offset


@dataclass
class Mapping:
    """canonical (or ``time``) -> source expression, with the parsed scale and offset per target."""

    columns: dict[str, str] = field(default_factory=dict)
    scale: dict[str, float] = field(default_factory=dict)
    offset: dict[str, float] = field(default_factory=dict)

    @classmethod
    def parse(cls, items: list[str] | tuple[str, ...]) -> "Mapping":
        """From ``["current=iq_measured", "velocity=speed*9", "torque=-adc_torque"]``."""
        m = cls()
        for item in items or ():
            if "=" not in item:
                raise ValueError(f"--map {item!r}: expected CANONICAL=EXPRESSION, e.g. velocity=speed*9")
            target, expr = item.split("=", 1)
            m.add(target.strip(), expr)
        return m

    @classmethod
    def from_yaml(cls, path: str | Path) -> "Mapping":
        """YAML ``{canonical: expression}`` or ``{columns: {...}, scale: {...}, offset: {...}}``."""
        import yaml

        path = Path(path)
        try:
            tree = yaml.safe_load(path.read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise ValueError(f"{path}: cannot read mapping file: {exc}") from None
        if not isinstance(tree, dict):
            raise ValueError(f"{path}: expected a mapping of canonical name -> expression")
        m = cls()
        if "columns" in tree and isinstance(tree["columns"], dict):
            for target, expr in tree["columns"].items():
                m.add(str(target), str(expr))
            for key in ("scale", "offset"):
                for target, value in (tree.get(key) or {}).items():
                    if target not in m.columns:
                        raise ValueError(f"{path}: {key}.{target} given without columns.{target}")
                    try:
                        v = float(value)
                    except (TypeError, ValueError):
                        raise ValueError(f"{path}: {key}.{target}: expected a number, got {value!r}") from None
                    if key == "scale":
                        m.scale[target] *= v
                        m.offset[target] *= v
                    else:
                        m.offset[target] += v
        else:
            for target, expr in tree.items():
                m.add(str(target), str(expr))
        return m

    def add(self, target: str, expr: str) -> None:
        if target not in TARGETS:
            raise ValueError(f"--map {target}=...: {target!r} is not a canonical name "
                             f"(known: {', '.join(TARGETS)})")
        try:
            source, scale, offset = parse_expression(expr)
        except ValueError as exc:
            raise ValueError(f"--map {target}={expr}: {exc}") from None
        self.columns[target] = source
        self.scale[target] = scale
        self.offset[target] = offset

    def apply(self, target: str, values: np.ndarray) -> np.ndarray:
        return values * self.scale.get(target, 1.0) + self.offset.get(target, 0.0)

    def describe(self) -> dict[str, str]:
        """target -> human-readable expression actually applied."""
        out = {}
        for t, src in self.columns.items():
            s, o = self.scale.get(t, 1.0), self.offset.get(t, 0.0)
            text = src if s == 1.0 else f"{s:g}*{src}"
            if o:
                text += f"{o:+g}"
            out[t] = text
        return out


# ============================================================================================ dispatch

def load(path: str | Path, *, mapping: Mapping | None = None, params=None, joint: str | None = None) -> Signals:
    """Read a recording (dispatch by suffix). The result is RAW: run :func:`.cleaning.clean` next.
    ``joint``: which joint of a multi-joint recording of ``actuator_node`` (MCAP)."""
    path = Path(path)
    if not path.exists():
        raise LoadError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        return load_mcap(path, mapping=mapping, params=params, joint=joint)
    if joint is not None:
        raise LoadError(f"{path}: --joint applies to multi-joint MCAP recordings of actuator_node")
    if suffix in (".csv", ".tsv", ".txt"):
        if mapping is None:
            from . import realdata

            adapter = realdata.adapter_for(path)
            if adapter is not None and not _has_canonical_header(path):
                return adapter(path)
        return load_csv(path, mapping=mapping, params=params)
    raise LoadError(f"{path}: unknown recording type {suffix!r} (expected .csv, .tsv, .txt or .mcap)")


def _has_canonical_header(path: Path) -> bool:
    try:
        with open(path, newline="", encoding="utf-8-sig", errors="replace") as f:
            for line in f:
                if line.strip() and not line.lstrip().startswith("#"):
                    names = {c.strip() for c in re.split(r"[,;\t]", line)}
                    return "time" in names and bool(names & set(CANONICAL))
    except OSError:
        return False
    return False


# ================================================================================================ CSV

def _delimiter(line: str) -> str:
    counts = {d: line.count(d) for d in (",", ";", "\t")}
    best = max(counts, key=counts.get)
    return best if counts[best] else ","


def _is_number(token: str) -> bool:
    try:
        float(token)
        return True
    except ValueError:
        return False


def _to_float_column(tokens: list[str], lines: list[int], path: Path, name: str) -> np.ndarray:
    try:
        return np.asarray(tokens, dtype=float)
    except ValueError:
        pass
    out = np.empty(len(tokens))
    for k, tok in enumerate(tokens):
        t = tok.strip()
        if t == "":
            out[k] = np.nan
            continue
        try:
            out[k] = float(t)
        except ValueError:
            raise LoadError(f"{path}: line {lines[k]}, column {name!r}: cannot read {tok!r} as a number") from None
    return out


def load_csv(path: str | Path, mapping: Mapping | None = None, params=None, *,
             aux: dict[str, str] | None = None, only_mapped: bool = False) -> Signals:
    """CSV with a header row. Default columns: ``time`` plus any canonical names (SI units, see
    :data:`~.signals.CANONICAL`); ``mapping`` renames/scales other columns (``#k`` for header-less files).
    Empty cells are NaN; a row with fewer fields than the header gets NaN for the missing ones (reported);
    a non-numeric cell in a used column is an error naming the line and column.
    ``aux`` (name -> expression, same syntax as a mapping) reads extra non-canonical columns into
    ``meta["aux"]``; a missing aux column is skipped (listed in ``meta["aux_missing"]``).
    ``only_mapped``: use the mapping alone (do not also pick up columns that happen to carry canonical
    names; the real-data adapters use this)."""
    path = Path(path)
    mapping = mapping or Mapping()
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            raw_lines = f.read().splitlines()
    except OSError as exc:
        raise LoadError(f"{path}: cannot read: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise LoadError(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None
    numbered = [(i + 1, ln) for i, ln in enumerate(raw_lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not numbered:
        raise LoadError(f"{path}: no data (empty or only comments)")
    delim = _delimiter(numbered[0][1])
    head_line, head = numbered[0]
    header = [h.strip() for h in next(csv.reader([head], delimiter=delim))]
    uses_index = any(src.startswith("#") for src in mapping.columns.values())
    headerless = all(_is_number(h) for h in header if h)
    if headerless and not uses_index:
        raise LoadError(
            f"{path}: line {head_line} looks like data, not a header: a CSV needs a header row naming the "
            f"columns (time, {', '.join(CANONICAL)}); for a header-less file name the columns by index, "
            f"e.g. --map time=#0 --map torque=#1")
    data_rows = numbered if headerless else numbered[1:]
    if not data_rows:
        raise LoadError(f"{path}: header only, no data rows")
    width = len(header)

    # resolve targets -> column index
    lower = {h.lower(): k for k, h in enumerate(header)}
    exact = {h: k for k, h in enumerate(header)}
    targets: dict[str, int] = {}
    for target in TARGETS:
        if target in mapping.columns:
            src = mapping.columns[target]
            if src.startswith("#") and src[1:].isdigit():
                targets[target] = int(src[1:])
                continue
            k = exact.get(src, lower.get(src.lower()))
            if k is None:
                raise LoadError(f"{path}: mapping {target}={src}: no column {src!r} "
                                f"(columns: {', '.join(header)})")
            targets[target] = k
        elif not headerless and not only_mapped:
            k = exact.get(target)
            if k is not None:
                targets[target] = k
    aux_cols: dict[str, tuple[int, float, float]] = {}
    aux_missing: list[str] = []
    for aname, expr in (aux or {}).items():
        src, sc, off = parse_expression(expr)
        if src.startswith("#") and src[1:].isdigit():
            aux_cols[aname] = (int(src[1:]), sc, off)
            continue
        k = exact.get(src, lower.get(src.lower()))
        if k is None:
            aux_missing.append(aname)
        else:
            aux_cols[aname] = (k, sc, off)
    if "time" not in targets:
        raise LoadError(f"{path}: no 'time' column (columns: {', '.join(header)}); name it 'time' [s] or map "
                        f"one, e.g. --map time=timestamp (scale it: --map time=t_ms*0.001)")
    if len(targets) == 1:
        raise LoadError(f"{path}: no canonical channel found (columns: {', '.join(header)}; canonical: "
                        f"{', '.join(CANONICAL)}); map some with --map NAME=COLUMN")

    need = max(targets.values()) + 1
    cols: dict[str, list[str]] = {t: [] for t in targets}
    acols: dict[str, list[str]] = {a: [] for a in aux_cols}
    lines: list[int] = []
    short: list[int] = []
    long_rows = 0
    reader = csv.reader([ln for _, ln in data_rows], delimiter=delim)
    for (lineno, _), row in zip(data_rows, reader):
        n = len(row)
        if n < need:
            short.append(lineno)
        if n > max(width, need):
            long_rows += 1
        for t, k in targets.items():
            cols[t].append(row[k] if k < n else "")
        for a, (k, _, _) in aux_cols.items():
            acols[a].append(row[k] if k < n else "")
        lines.append(lineno)
    values = {}
    for t, k in targets.items():
        name = mapping.columns.get(t, header[k] if k < width else f"#{k}")
        values[t] = mapping.apply(t, _to_float_column(cols[t], lines, path, name)) if t in mapping.columns \
            else _to_float_column(cols[t], lines, path, name)
    aux_values = {}
    for a, (k, sc, off) in aux_cols.items():
        aux_values[a] = _to_float_column(acols[a], lines, path, header[k] if k < width else f"#{k}") * sc + off
    t_all = values.pop("time")
    issues: list[DataIssue] = []
    notes: list[str] = []
    if short:
        issues.append(DataIssue(
            "nan", "time", len(short), None,
            f"{len(short)} row(s) have fewer fields than the {need} needed; the missing fields read as NaN "
            f"(first at line {short[0]}{', last line of the file' if short[-1] == data_rows[-1][0] else ''})",
            "missing fields set to NaN"))
    if long_rows:
        notes.append(f"{long_rows} row(s) have more fields than the header ({width}); extra fields ignored")
    used = {header[k] if k < width else f"#{k}" for k in targets.values()}
    unused = [h for h in header if h not in used] if not headerless else []
    semantics = {t: f"column {mapping.describe().get(t, header[k] if k < width else f'#{k}')}"
                 for t, k in targets.items()}
    meta = {"format": "csv", "mapping": mapping.describe(), "semantics": semantics, "notes": notes,
            "unused_columns": unused, "gear_ratio": float(params.gear.gear_ratio) if params is not None else None,
            "params_from_recording": None, "first_data_line": data_rows[0][0],
            "line_numbers": np.asarray(lines, dtype=np.int64), "aux": aux_values, "aux_missing": aux_missing,
            "header": header}
    return Signals(t_all, values, str(path), issues, [], meta)


# =============================================================================================== MCAP

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
    metadata [(name, dict)], notes). Uses the fast record scanner of :mod:`bldc_actuator.recording`
    (it also recovers unfinalized files); falls back to the mcap library."""
    notes: list[str] = []
    try:
        from .. import recording as R

        scan = R._scan(path, keep_messages=True, topics=topics)  # noqa: SLF001 - see docs/realdata.md
        notes += [f"recording: {i}" for i in scan.issues]
        return scan.channels, scan.schemas, scan.messages, list(scan.metadata), notes
    except (ImportError, AttributeError, TypeError):
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


def _mcap_topics(path: Path) -> dict[str, str]:
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
        from ..recording import parameters_from_yaml

        return parameters_from_yaml(text)
    except Exception:  # noqa: BLE001 - unreadable parameters: loaded without them (noted by the caller)
        return None


def _params_from_flat(flat: dict | None):
    if not flat:
        return None
    from ..params import SPECS, from_flat

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
    topic_types = _mcap_topics(path)
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
    meta = {"format": "mcap", "own_recording": own, "joint": joint if joints else None,
            "mapping": mapping.describe(), "semantics": semantics,
            "notes": notes, "gear_ratio": gear, "params_from_recording": params_rec,
            "recorded_parameters": rec_params, "time_base": plan[base_target][0], "t0_ns": t0,
            "topics": topic_types, "extraction": how}
    return Signals(time_axis, chans, str(path), issues, [], meta)
