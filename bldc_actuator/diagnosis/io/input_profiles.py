"""Input profiles: how a log format's columns become canonical channels — as data, not code.

A profile is a YAML file (``config/input_profiles/<name>.yaml``, or any file given with ``--profile FILE``)
that declares, for one log format:

``signature``     how to recognise the format from the file itself, never from its folder:
                  ``header_has`` (column names that must all be in the header), ``header_regex`` (each
                  regex matches at least one column), ``header_lacks`` (names that must be absent),
                  ``headerless: true`` with ``columns`` (allowed field counts) and ``increasing`` (a column
                  index that must increase, e.g. a time column), ``ranges`` (column index -> [lo, hi] the
                  first lines' values lie in), ``first_line_regex``; for MCAP
                  ``topics_have``. ``priority`` breaks ties (higher first).
``layout``        ``skip_lines`` (lines before the header), ``units_row`` (a line of units after it)
``time``          ``column`` (an expression) | ``rate_hz`` (no time column: synthesised) | ``index: true``
                  (a table of operating points); ``zero_start`` (subtract the first value, kept as
                  ``meta["time_offset_s"]``), ``epoch`` (the column is Unix time: the recording's start)
``start_time``    ``{line: N}``: a date on line N of the file is the recording's start
``columns``       canonical channel -> expression (``--map`` syntax) or a list of alternatives, the first
                  whose column exists wins; an alternative may be ``{column: EXPR, side: output}``
``optional``      channels that may be absent (others missing -> an error naming the profile field)
``units``         channel -> unit of the column (``N*mm``, ``mA``, ``rpm``, ``erpm``, ``deg``, ``K`` ...);
                  checked against the file's units row when it has one
``side``          channel -> ``output`` when recorded after the gear (angles and speeds are multiplied by
                  the gear ratio, the canonical channels being motor side)
``gear_ratio``, ``pole_pairs``  the actuator's, when the profile knows them (else ``--params``)
``joints``        several actuators side by side: ``pattern`` (a regex with a group ``j`` over the header)
                  and ``columns`` / ``aux`` (templates with ``{j}``), ``name`` (the joint's name, default
                  ``{j}``); ``actuator_id`` template (``{stem}``,
                  ``{parent}``, ``{j}``)
``aux``           extra non-canonical columns kept in ``meta["aux"]``
``from_file_name`` channel -> regex with one group: a constant channel read from the file name
``companion``     a second file beside the first that supplies one channel (joined by time)
``format``        ``csv`` (default), ``mcap`` or ``json`` (a list of records, JSON Lines or an object of arrays,
                  :mod:`.jsonio`: its keys are the header a ``signature`` names, its columns what ``columns`` map)
``quirks``        generic operations (:mod:`.quirks`): sign alignment, masking, relabelled columns
``semantics``, ``notes``, ``description``, ``licence``, ``source``, ``hints``, ``clean_limits``,
``steady_state_points``  carried into ``Signals.meta`` for the report and for cleaning.
"""

from __future__ import annotations

import datetime as dt
import functools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..signals import DataIssue, Signals
from . import quirks as _quirks
from . import jsonio
from .csvio import load_csv
from .mapping import TARGETS, Expression, LoadError, Mapping, compile_expression

#: unit -> (scale, offset) to SI (value_SI = scale * value + offset); ``erpm`` needs the pole pairs
UNITS: dict[str, tuple[float, float]] = {
    "s": (1.0, 0.0), "ms": (1e-3, 0.0), "us": (1e-6, 0.0), "ns": (1e-9, 0.0),
    "rad": (1.0, 0.0), "deg": (math.pi / 180, 0.0), "rev": (2 * math.pi, 0.0),
    "rad/s": (1.0, 0.0), "rad.s": (1.0, 0.0), "deg/s": (math.pi / 180, 0.0), "rpm": (2 * math.pi / 60, 0.0),
    "rps": (2 * math.pi, 0.0),
    "a": (1.0, 0.0), "ma": (1e-3, 0.0), "v": (1.0, 0.0), "mv": (1e-3, 0.0),
    "n*m": (1.0, 0.0), "nm": (1.0, 0.0), "n.m": (1.0, 0.0), "n*mm": (1e-3, 0.0), "n.mm": (1e-3, 0.0),
    "nmm": (1e-3, 0.0), "mn*m": (1e-3, 0.0), "mnm": (1e-3, 0.0),
    "degc": (1.0, 0.0), "deg c": (1.0, 0.0), "c": (1.0, 0.0), "k": (1.0, -273.15),
}
#: the SI unit of each canonical quantity (what the channel holds after conversion)
_SI = {"s": "s", "rad": "rad", "rad/s": "rad/s", "A": "A", "V": "V", "N*m": "N*m", "degC": "degC"}
_SIDE_SCALED = {"position": "multiply", "velocity": "multiply"}
SIDES = ("motor", "output")


class ProfileError(ValueError):
    """A profile file is malformed; the message names the file and the field."""


@dataclass
class InputProfile:
    name: str
    path: str = ""
    description: str = ""
    format: str = "csv"
    signature: dict = field(default_factory=dict)
    priority: int = 0
    layout: dict = field(default_factory=dict)
    time: dict = field(default_factory=dict)
    start_time: dict = field(default_factory=dict)
    columns: dict = field(default_factory=dict)
    optional: list = field(default_factory=list)
    units: dict = field(default_factory=dict)
    side: dict = field(default_factory=dict)
    gear_ratio: float | None = None
    pole_pairs: int | None = None
    joints: dict = field(default_factory=dict)
    actuator_id: str | None = None
    aux: dict = field(default_factory=dict)
    from_file_name: dict = field(default_factory=dict)
    companion: dict = field(default_factory=dict)
    quirks: list = field(default_factory=list)
    semantics: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    licence: str = ""
    source: str = ""
    hints: dict = field(default_factory=dict)
    clean_limits: dict = field(default_factory=dict)
    steady_state_points: bool = False

    # ------------------------------------------------------------------------------ construction
    @classmethod
    def from_dict(cls, tree: dict, path: str = "") -> "InputProfile":
        where = path or "profile"
        if not isinstance(tree, dict):
            raise ProfileError(f"{where}: expected a mapping of profile fields")
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(tree) - known)
        if unknown:
            raise ProfileError(f"{where}: unknown field(s) {', '.join(unknown)} (known: {', '.join(sorted(known))})")
        if "name" not in tree:
            raise ProfileError(f"{where}: field 'name' is required")
        prof = cls(**{**tree, "path": path})
        prof.validate()
        return prof

    @classmethod
    def from_yaml(cls, path: str | Path) -> "InputProfile":
        import yaml

        path = Path(path)
        try:
            tree = yaml.safe_load(path.read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise ProfileError(f"{path}: cannot read profile: {exc}") from None
        return cls.from_dict(tree, str(path))

    def validate(self) -> None:
        where = self.path or self.name
        if self.format not in ("csv", "mcap", "json"):
            raise ProfileError(f"{where}: format: expected csv, mcap or json, got {self.format!r}")
        for ch in list(self.columns) + list(self.optional) + list(self.units) + list(self.side):
            if ch not in TARGETS:
                raise ProfileError(f"{where}: {ch!r} is not a canonical channel (known: {', '.join(TARGETS)})")
        for ch, s in self.side.items():
            if s not in SIDES:
                raise ProfileError(f"{where}: side.{ch}: expected one of {SIDES}, got {s!r}")
        for ch, u in self.units.items():
            if u.lower() not in UNITS and u.lower() != "erpm":
                raise ProfileError(f"{where}: units.{ch}: unknown unit {u!r} (known: {', '.join(sorted(UNITS))}, erpm)")
        if self.gear_ratio is not None and not (float(self.gear_ratio) > 0):
            raise ProfileError(f"{where}: gear_ratio: expected > 0, got {self.gear_ratio!r}")
        if self.joints and ("pattern" not in self.joints or "columns" not in self.joints):
            raise ProfileError(f"{where}: joints: needs 'pattern' (a regex with a group j) and 'columns'")
        for k, q in enumerate(self.quirks):
            if not isinstance(q, dict) or q.get("op") not in _quirks.OPERATIONS:
                raise ProfileError(f"{where}: quirks[{k}].op: expected one of {', '.join(_quirks.OPERATIONS)}")

    # ------------------------------------------------------------------------------ recognition
    def matches(self, head: "FileHead") -> bool:
        sig = self.signature
        if not sig:
            return False
        if self.format == "mcap":
            return head.topics is not None and all(any(t == x or t.endswith("/" + x.lstrip("/")) for t in head.topics)
                                                   for x in sig.get("topics_have", []))
        if head.topics is not None or (self.format == "json") != head.json:
            return False
        if sig.get("headerless"):
            if not head.headerless:
                return False
        elif head.headerless:
            return False
        names = head.header_at(int(self.layout.get("skip_lines", 0)))
        if names is None:
            return False
        if "columns" in sig and len(names) not in [int(c) for c in np.atleast_1d(sig["columns"])]:
            return False
        if not all(n in names for n in sig.get("header_has", [])):
            return False
        if any(n in names for n in sig.get("header_lacks", [])):
            return False
        for rx in sig.get("header_regex", []):
            if not any(re.search(rx, n) for n in names):
                return False
        if "first_line_regex" in sig and not re.search(sig["first_line_regex"], head.lines[0] if head.lines else ""):
            return False
        for k, (lo, hi) in (sig.get("ranges") or {}).items():
            col = head.numeric_column(int(k))
            if col is None or not np.all((col >= float(lo)) & (col <= float(hi))):
                return False
        if "increasing" in sig:
            col = head.numeric_column(int(sig["increasing"]))
            if col is None or len(col) < 3 or not np.all(np.diff(col) > 0):
                return False
        return True


# ------------------------------------------------------------------------------------------- registry

def profile_dir() -> Path:
    from ...params import config_dir

    return config_dir() / "input_profiles"


def available() -> list[InputProfile]:
    """Every shipped profile, highest priority first (each file parsed once per process while unchanged)."""
    d = profile_dir()
    files = sorted(d.glob("*.yaml")) if d.is_dir() else []
    profs = [_parsed(str(p), p.stat().st_mtime_ns) for p in files]
    return sorted(profs, key=lambda p: -int(p.priority))


@functools.lru_cache(maxsize=256)
def _parsed(path: str, mtime_ns: int) -> InputProfile:
    """A profile file parsed (memoised on path and modification time; profiles are read-only once parsed)."""
    return InputProfile.from_yaml(path)


def get(name_or_file: str | Path | InputProfile) -> InputProfile:
    """A shipped profile by name, or a profile YAML file."""
    if isinstance(name_or_file, InputProfile):
        return name_or_file
    p = Path(name_or_file)
    if p.suffix in (".yaml", ".yml") and p.exists():
        return InputProfile.from_yaml(p)
    profs = available()
    for prof in profs:
        if prof.name == str(name_or_file) or Path(prof.path).stem == str(name_or_file):
            return prof
    raise LoadError(f"--profile {name_or_file}: no such profile file or name (shipped: "
                    f"{', '.join(p.name for p in profs)})")


@dataclass
class FileHead:
    """The first lines of a CSV (or the topics of an MCAP) — what signatures look at."""

    lines: list[str]
    delimiter: str = ","
    topics: list[str] | None = None
    json: bool = False       #: a JSON log, its keys as the header (:func:`.jsonio.header`)

    @classmethod
    def read(cls, path: Path, n: int = 8) -> "FileHead":
        if path.suffix.lower() == ".mcap":
            from .mcapio import mcap_topics

            return cls([], topics=list(mcap_topics(path)))
        if path.suffix.lower() in jsonio.SUFFIXES:
            try:
                return cls(jsonio.header(path, n), ",", json=True)
            except LoadError:
                return cls([], ",", json=True)
        lines: list[str] = []
        try:
            with open(path, newline="", encoding="utf-8-sig", errors="replace") as f:
                for ln in f:
                    if ln.strip() and not ln.lstrip().startswith("#"):
                        lines.append(ln.rstrip("\r\n"))
                        if len(lines) >= n:
                            break
        except OSError:
            pass
        counts = {d: lines[0].count(d) for d in (",", ";", "\t")} if lines else {",": 0}
        delim = max(counts, key=counts.get) if max(counts.values()) else ","
        return cls(lines, delim)

    def fields(self, k: int) -> list[str] | None:
        return [c.strip() for c in self.lines[k].split(self.delimiter)] if k < len(self.lines) else None

    @property
    def headerless(self) -> bool:
        f = self.fields(0)
        return bool(f) and all(_is_number(x) for x in f if x)

    def header_at(self, skip: int) -> list[str] | None:
        return self.fields(0) if self.headerless else self.fields(skip)

    def numeric_column(self, k: int) -> np.ndarray | None:
        vals = []
        for i in range(len(self.lines)):
            f = self.fields(i)
            if f is None or len(f) <= k or not _is_number(f[k]):
                return None
            vals.append(float(f[k]))
        return np.array(vals)


def _is_number(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def detect(path: str | Path) -> InputProfile | None:
    """The shipped profile whose signature the file matches (highest priority first), else None."""
    head = FileHead.read(Path(path))
    for prof in available():
        if prof.matches(head):
            return prof
    return None


# ------------------------------------------------------------------------------------------- reading

def joints(path: str | Path, profile: InputProfile) -> list[str]:
    """Joint ids a multi-actuator file holds (``[]`` when the profile has no ``joints``)."""
    if not profile.joints:
        return []
    head = FileHead.read(Path(path))
    names = head.header_at(int(profile.layout.get("skip_lines", 0))) or []
    return [_joint_name(profile, j) for j in _joint_ids(names, profile)]


def _joint_ids(names: list[str], profile: InputProfile) -> list[str]:
    rx = re.compile(profile.joints["pattern"])
    found = {m.group("j") for n in names for m in [rx.search(n)] if m}
    return sorted(found, key=lambda j: (len(j), j))


def _joint_name(profile: InputProfile, j: str) -> str:
    return str(profile.joints.get("name", "{j}")).format(j=j)


def _alternatives(spec) -> list[tuple[str, str | None]]:
    """``"expr"`` | ``[alt, ...]`` | ``{column, side}`` -> [(expr, side or None)]."""
    items = spec if isinstance(spec, list) else [spec]
    out = []
    for it in items:
        if isinstance(it, dict):
            out.append((str(it["column"]), it.get("side")))
        else:
            out.append((str(it), None))
    return out


def _column_exists(expr: str, header: set[str], headerless: bool, width: int) -> bool:
    try:
        form = compile_expression(expr)
    except ValueError:
        return False
    if isinstance(form, Expression):
        return all(_column_exists(f'"{c}"' if not c.startswith("#") else c, header, headerless, width)
                   for c in form.columns)
    src = form[0]
    if src.startswith("#") and src[1:].lstrip("-").isdigit():
        k = int(src[1:])
        return -width <= k < width
    return (not headerless) and (src in header or src.lower() in {h.lower() for h in header})


def _unit_factor(unit: str, pole_pairs, where: str) -> tuple[float, float]:
    u = unit.lower()
    if u == "erpm":
        if not pole_pairs:
            raise LoadError(f"{where}: unit erpm needs the pole pairs: set the profile's pole_pairs or give --params")
        return 2 * math.pi / 60 / float(pole_pairs), 0.0
    return UNITS[u]


def read(path: str | Path, profile: InputProfile, params=None, joint: str | None = None,
         overrides: Mapping | None = None) -> Signals:
    """Read ``path`` as ``profile`` says; the result is raw (run :func:`.cleaning.clean` next). ``overrides``
    (``--map``): channels read from these expressions instead of the profile's (canonical units and side, as
    every ``--map``; ``{j}`` in a column name is the chosen joint's id), the profile's other channels kept."""
    overrides = overrides if overrides is not None and overrides.has_columns else None
    path = Path(path)
    where = f"{path}: profile {profile.name}"
    if path.suffix.lower() in jsonio.SUFFIXES:
        if profile.format != "json":
            raise LoadError(f"{where}: the profile reads {profile.format} files, this is a JSON log (give a profile "
                            f"with format: json)")
        with jsonio.as_csv(path) as (tmp, table):
            sig = _read_table(tmp, profile, params, joint, overrides, f"{path}: profile {profile.name}")
        jsonio.finish(sig, path, table)
        return sig
    if profile.format == "json":
        raise LoadError(f"{where}: the profile reads JSON logs ({', '.join(jsonio.SUFFIXES)}), not {path.suffix}")
    if profile.format == "mcap":
        from .mcapio import load_mcap

        m = Mapping()
        for ch, spec in profile.columns.items():
            m.add(ch, _alternatives(spec)[0][0])
        sig = load_mcap(path, m, params=params)
        return _finish(sig, path, profile, params, joint, where)
    return _read_table(path, profile, params, joint, overrides, where)


def _read_table(path: Path, profile: InputProfile, params, joint, overrides: Mapping | None, where: str) -> Signals:
    """A CSV (or a JSON log written as one) read as ``profile`` says."""
    head = FileHead.read(path)
    skip = int(profile.layout.get("skip_lines", 0))
    header_list = head.header_at(skip) or []
    header = set(header_list)
    headerless = head.headerless
    width = len(header_list)
    columns = dict(profile.columns)
    if profile.joints:
        ids = {_joint_name(profile, j): j for j in _joint_ids(header_list, profile)}
        if joint is None:
            if len(ids) != 1:
                raise LoadError(f"{where}: a file of several joints ({', '.join(ids)}): choose one with --joint NAME")
            joint = next(iter(ids))
        if joint not in ids:
            raise LoadError(f"{where}: no joint {joint!r} (joints: {', '.join(ids)})")
        jid = ids[joint]
        def fill(tpl):
            return [t.format(j=jid) if isinstance(t, str) else {**t, "column": t["column"].format(j=jid)}
                    for t in (tpl if isinstance(tpl, list) else [tpl])]

        columns.update({ch: fill(tpl) for ch, tpl in profile.joints["columns"].items()})
        aux_specs = {**profile.aux, **{k: fill(v) for k, v in (profile.joints.get("aux") or {}).items()}}
    elif joint is not None:
        raise LoadError(f"{where}: --joint {joint}: this format holds one actuator per file")
    else:
        aux_specs = dict(profile.aux)

    mapping, sides = Mapping(), {}
    for ch, spec in columns.items():
        if overrides is not None and (ch in overrides.columns or ch in overrides.combined):
            continue
        alts = _alternatives(spec)
        hit = next(((e, s) for e, s in alts if _column_exists(e, header, headerless, width)), None)
        if hit is None:
            if ch in profile.optional:
                continue
            raise LoadError(f"{where}: columns.{ch}: none of {', '.join(e for e, _ in alts)} is in the file "
                            f"(columns: {', '.join(header_list)})")
        expr, side = hit
        src = _normalise_negative_index(expr, width)
        mapping.add(ch, src)
        sides[ch] = side or profile.side.get(ch, "motor")
    aux = {}
    for name, spec in aux_specs.items():
        alts = _alternatives(spec)
        hit = next((e for e, _ in alts if _column_exists(e, header, headerless, width)), None)
        if hit is not None:
            aux[name] = _normalise_negative_index(hit, width)
    time_spec = profile.time or {}
    if overrides is not None:
        jid_ = jid if profile.joints else ""
        for ch, src in overrides.columns.items():
            src = src.replace("{j}", jid_)
            if not _column_exists(src, header, headerless, width) and not src.startswith("#"):
                raise LoadError(f"{where}: --map {ch}={src}: no such column (columns: {', '.join(header_list)})")
            mapping.columns[ch] = _normalise_negative_index(src, width)
            mapping.scale[ch] = overrides.scale.get(ch, 1.0)
            mapping.offset[ch] = overrides.offset.get(ch, 0.0)
            sides[ch] = "motor"
        for ch, e in overrides.combined.items():
            mapping.combined[ch] = Expression.parse(e.text.replace("{j}", jid_))
            sides[ch] = "motor"
        if "time" in overrides.columns:
            time_spec = {k: v for k, v in time_spec.items() if k != "column"}
    if "column" in time_spec and (overrides is None or "time" not in overrides.columns):
        alts = _alternatives(time_spec["column"])
        hit = next((e for e, _ in alts if _column_exists(e, header, headerless, width)), None)
        if hit is None:
            raise LoadError(f"{where}: time.column: none of {', '.join(e for e, _ in alts)} is in the file "
                            f"(columns: {', '.join(header_list)})")
        mapping.add("time", _normalise_negative_index(hit, width))
    rate = time_spec.get("rate_hz") or (1.0 if time_spec.get("index") else None)
    combined = dict(mapping.combined)
    if combined and not (set(mapping.columns) - {"time"}):      # load_csv wants one single-column channel
        ch0, e0 = next(iter(combined.items()))
        mapping.columns[ch0] = e0.columns[0]
    sig = load_csv(path, mapping, params, aux={**aux, **mapping.combined_sources()}, only_mapped=True,
                   skip_lines=skip, units_row=bool(profile.layout.get("units_row")), time_rate=rate)
    mapping.apply_combined(sig, header_list, where)
    if time_spec.get("rate_hz"):
        sig.meta["semantics"]["time"] = f"SYNTHESISED at {float(time_spec['rate_hz']):g} Hz (no time column)"
        sig.meta["notes"].append(f"time synthesised at {float(time_spec['rate_hz']):g} Hz: the file has no time column")
    if time_spec.get("index"):
        sig.meta["semantics"]["time"] = "operating-point index (NOT seconds)"
        sig.meta["time_is_index"] = True
    if len(sig.time) and time_spec.get("epoch"):
        sig.meta["start_time"] = dt.datetime.fromtimestamp(float(sig.time[0]), dt.timezone.utc).isoformat()
        sig.meta["start_time_source"] = f"recording's clock (column {sig.meta['mapping'].get('time')}, Unix time)"
    if len(sig.time) and time_spec.get("zero_start"):
        t0 = float(sig.time[0])
        sig.time = sig.time - t0
        sig.meta["time_offset_s"] = t0
    _units(sig, profile, params, where,
           skip=set(overrides.columns) | set(overrides.combined) if overrides is not None else set())
    _sides(sig, profile, params, sides, where)
    if overrides is not None:
        sig.meta["notes"].append("--map over the input profile: " + ", ".join(
            f"{ch}={sig.meta['mapping'].get(ch, src)}" for ch, src in
            {**overrides.columns, **{c: e.text for c, e in overrides.combined.items()}}.items()))
    return _finish(sig, path, profile, params, joint, where)


def _normalise_negative_index(expr: str, width: int) -> str:
    m = re.match(r"^(\s*-?\s*)#(-\d+)(.*)$", expr)
    if m and width:
        return f"{m.group(1)}#{width + int(m.group(2))}{m.group(3)}"
    return expr


def _units(sig: Signals, profile: InputProfile, params, where: str, skip: set = frozenset()) -> None:
    pp = profile.pole_pairs or (params.motor.pole_pairs if params is not None else None)
    file_units = sig.meta.get("units") or {}
    for ch, unit in profile.units.items():
        if ch in skip:
            continue
        if ch == "time":
            scale, off = _unit_factor(unit, pp, f"{where}: units.time")
            sig.time = sig.time * scale + off
            continue
        if ch not in sig.channels:
            continue
        src = sig.meta["mapping"].get(ch, "")
        recorded = file_units.get(src.strip('"'))
        if recorded and recorded.lower().replace(" ", "") != unit.lower().replace(" ", ""):
            raise LoadError(f"{where}: units.{ch} says {unit!r} but the file's units row says {recorded!r} for "
                            f"column {src}: fix the profile's units.{ch}")
        scale, off = _unit_factor(unit, pp, f"{where}: units.{ch}")
        if scale != 1.0 or off != 0.0:
            sig.channels[ch] = sig.channels[ch] * scale + off
            sig.meta["semantics"][ch] = f"{sig.meta['semantics'].get(ch, ch)} [{unit}] -> SI"


def _sides(sig: Signals, profile: InputProfile, params, sides: dict, where: str) -> None:
    gear = profile.gear_ratio or (params.gear.gear_ratio if params is not None else None)
    sig.meta["gear_ratio"] = float(gear) if gear else sig.meta.get("gear_ratio")
    for ch, side in sides.items():
        if side != "output" or ch not in sig.channels:
            continue
        if ch in ("torque", "torque_command", "load_torque"):
            continue                                # canonical torque channels are output side already
        if not gear:
            raise LoadError(f"{where}: side.{ch} is output (after the gear) but no gear ratio is known: set the "
                            f"profile's gear_ratio or give --params")
        sig.channels[ch] = sig.channels[ch] * float(gear)
        sig.meta["semantics"][ch] = f"{sig.meta['semantics'].get(ch, ch)}, output side x gear ratio {float(gear):g}"


def _finish(sig: Signals, path: Path, profile: InputProfile, params, joint, where: str) -> Signals:
    meta = sig.meta
    meta["profile"] = profile.name
    meta["profile_path"] = profile.path
    meta["description"] = profile.description
    meta["licence"] = profile.licence
    meta["hints"] = dict(profile.hints)
    if profile.clean_limits:
        meta["clean_limits"] = {k: (tuple(v) if isinstance(v, list) else v) for k, v in profile.clean_limits.items()}
    if profile.steady_state_points:
        meta["steady_state_points"] = True
    meta["semantics"].update(profile.semantics)
    meta["notes"].extend(profile.notes)
    meta.setdefault("aux_semantics", {})
    if joint is not None:
        meta["joint"] = joint
    if profile.actuator_id:
        meta["actuator_id"] = profile.actuator_id.format(stem=path.stem, parent=path.parent.name,
                                                         j=joint if joint is not None else "")
    n = len(sig.time)
    for ch, rx in profile.from_file_name.items():
        m = re.search(rx, path.name)
        if m:
            sig.channels[ch] = np.full(n, float(m.group(1)))
            meta["semantics"][ch] = f"from the file name ({m.group(0)})"
        else:
            meta["notes"].append(f"from_file_name.{ch}: the file name does not match {rx!r}; {ch} absent")
    if profile.start_time.get("line"):
        _start_from_line(sig, path, int(profile.start_time["line"]))
    if profile.companion:
        _companion(sig, path, profile, where)
    constants = {"gear_ratio": profile.gear_ratio or (params.gear.gear_ratio if params is not None else None),
                 "pole_pairs": profile.pole_pairs or (params.motor.pole_pairs if params is not None else None)}
    _quirks.apply(sig, profile.quirks, constants, where)
    return sig


def _start_from_line(sig: Signals, path: Path, line: int) -> None:
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            for k, ln in enumerate(f, start=1):
                if k == line:
                    when = dt.datetime.fromisoformat(ln.strip().split(",")[0].strip())
                    when = when if when.tzinfo else when.replace(tzinfo=dt.timezone.utc)
                    sig.meta["start_time"] = when.isoformat()
                    sig.meta["start_time_source"] = f"recording's own date (line {line})"
                    sig.meta["recorded_at"] = ln.strip()
                    return
    except (OSError, ValueError):
        sig.meta["notes"].append(f"start_time: line {line} holds no date")


def _companion(sig: Signals, path: Path, profile: InputProfile, where: str) -> None:
    """A second file beside ``path`` supplying one channel, joined by time (linear interpolation, NaN
    outside its span)."""
    spec = profile.companion
    other = path.parent / spec["file"]
    target = spec["channel"]
    if not other.exists():
        sig.meta["notes"].append(f"companion file {spec['file']} absent: no {target}")
        return
    try:
        d = np.loadtxt(other, delimiter=",", ndmin=2)
    except ValueError as exc:
        raise LoadError(f"{other}: {exc}") from None
    cols = [int(c) for c in np.atleast_1d(spec.get("columns", [d.shape[1]]))]
    if d.shape[1] not in cols:
        raise LoadError(f"{other}: companion of profile {profile.name}: expected {cols} columns, got {d.shape[1]}")
    tc, vc = int(spec.get("time_column", 0)), int(spec.get("value_column", -1))
    t = d[:, tc] * float(spec.get("time_scale", 1.0)) + float(spec.get("time_shift_s", 0.0))
    raw = d[:, vc]
    v = raw * float(spec.get("scale", 1.0))
    if sig.meta.get("time_offset_s") and spec.get("same_clock"):
        t = t - sig.meta["time_offset_s"]
    sig.channels[target] = np.interp(sig.time, t, v, left=np.nan, right=np.nan)
    if spec.get("aux"):
        sig.meta["aux"][spec["aux"]] = np.interp(sig.time, t, raw, left=np.nan, right=np.nan)
    sig.meta["semantics"][target] = spec.get("semantics", f"from {other.name}")
    sig.meta["notes"].append(f"companion {other.name}: {len(t)} samples covering t = {t[0]:.2f}..{t[-1]:.2f} s on "
                             f"this time axis; {target} NaN outside")


# ------------------------------------------------------------------------------------------- checks

def check_fix_hint(profile: InputProfile | None, channel: str) -> str:
    """Which profile field (or ``--map``) fixes a suspected unit / side mismatch of ``channel``."""
    if profile is not None and profile.path:
        return f"profile {profile.name} ({profile.path}): fields units.{channel} / side.{channel}"
    return f"--map {channel}=COLUMN*FACTOR (or an input profile's units.{channel} / side.{channel})"


def describe(profile: InputProfile) -> str:
    return f"{profile.name} ({profile.path})" if profile.path else profile.name


__all__ = ["InputProfile", "ProfileError", "available", "get", "detect", "read", "joints", "UNITS", "DataIssue"]
