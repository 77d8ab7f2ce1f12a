"""Read recordings into raw :class:`~..signals.Signals` (canonical names, SI, motor side).

:func:`load` decides how a file is read, in this order:

1. ``mapping`` (``--map``): the file is read with that mapping (:mod:`.csvio` / :mod:`.mcapio`);
2. ``profile`` (``--profile NAME|FILE``): the input profile says how (:mod:`.input_profiles`);
3. the file speaks for itself: a CSV whose header names canonical channels (``time``, ``current`` ...), or
   an MCAP of ``actuator_node``;
4. auto-detection: the shipped profile whose signature (header / schema, never the folder) the file
   matches — the chosen profile is in ``meta["profile"]`` and printed by the CLI;
5. otherwise an error that says what to map.

JSON logs (a list of records, JSON Lines, an object of arrays: :mod:`.jsonio`) take the same five steps: their
keys are the header, a profile with ``format: json`` names them, ``--map`` expressions combine them.

Loaders only translate; they never mask or drop samples (except rows with nothing parseable and what a
profile's quirks mask, which are reported). Problems are found and reported by :func:`.cleaning.clean`.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ... import drive_tuning
from ..signals import CANONICAL, DataIssue, Signals
from . import input_profiles, jsonio
from .csvio import load_csv
from .mapping import TARGETS, LoadError, Mapping, parse_expression
from .mcapio import load_mcap, mcap_topics

__all__ = ["load", "load_many", "joints", "load_csv", "load_mcap", "Mapping", "LoadError", "parse_expression",
           "TARGETS"]


def _has_canonical_header(path: Path) -> bool:
    if path.suffix.lower() in jsonio.SUFFIXES:
        try:
            names = set(jsonio.read_table(path).keys)
        except LoadError:
            return False
        return "time" in names and bool(names & set(CANONICAL))
    try:
        with open(path, newline="", encoding="utf-8-sig", errors="replace") as f:
            for line in f:
                if line.strip() and not line.lstrip().startswith("#"):
                    names = {c.strip() for c in re.split(r"[,;\t]", line)}
                    return "time" in names and bool(names & set(CANONICAL))
    except OSError:
        return False
    return False


def _own_mcap_joints(path: Path) -> list[str]:
    topics = mcap_topics(path)
    q = [t for t in topics if t.endswith("/q_axis_state")]
    if len(q) > 1 and any(t.endswith("joint_states") for t in topics):
        return sorted(t.rsplit("/", 2)[-2] for t in q)
    return []


def resolve_profile(path: str | Path, profile=None) -> "input_profiles.InputProfile | None":
    """The profile that reads ``path``: the one given, else auto-detected (None when the file speaks for
    itself or nothing matches)."""
    path = Path(path)
    if profile is not None:
        return input_profiles.get(profile)
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        if _own_mcap_joints(path) or any(t.endswith("/q_axis_state") for t in mcap_topics(path)):
            return None
        return input_profiles.detect(path)
    if _has_canonical_header(path):
        return None
    return input_profiles.detect(path)


def joints(path: str | Path, profile=None) -> list[str]:
    """Joint names of a multi-actuator file (``actuator_node`` MCAP of several joints, or a profile with
    per-joint columns); ``[]`` for a single-actuator file."""
    path = Path(path)
    if path.suffix.lower() == ".mcap" and profile is None:
        own = _own_mcap_joints(path)
        if own:
            return own
    prof = resolve_profile(path, profile)
    return input_profiles.joints(path, prof) if prof is not None else []


def load(path: str | Path, *, mapping: Mapping | None = None, params=None, joint: str | None = None,
         profile=None) -> Signals:
    """Read a recording (see the module docstring for how). The result is RAW: run
    :func:`.cleaning.clean` next. ``joint``: which actuator of a multi-actuator file."""
    path = Path(path)
    if not path.exists():
        raise LoadError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".tsv", ".txt", ".mcap") + jsonio.SUFFIXES:
        raise LoadError(f"{path}: unknown recording type {suffix!r} (expected .csv, .tsv, .txt, .mcap or "
                        f"{', '.join(jsonio.SUFFIXES)})")
    if mapping is not None and mapping.has_columns:
        if suffix == ".mcap":
            if mapping.combined:
                raise LoadError(f"{path}: --map {', '.join(f'{t}={e.text}' for t, e in mapping.combined.items())}"
                                f": expressions over several columns apply to CSV and JSON logs, not MCAP topics")
            return load_mcap(path, mapping=mapping, params=params, joint=joint)
        if joint is not None or profile is not None:
            # --map over a profile (--profile, or the one --joint needs): the profile reads the joint, the map
            # replaces or adds the channels it names
            prof = resolve_profile(path, profile)
            if prof is None:
                raise LoadError(f"{path}: --joint applies to files of several actuators (no input profile "
                                f"recognises this one as such; give --profile)")
            sig = input_profiles.read(path, prof, params=params, joint=joint, overrides=mapping)
            sig.meta["profile_how"] = ("given (--profile)" if profile is not None else
                                       "auto-detected from the header") + ", with --map over it"
            return sig
        return _table(path, mapping, params)
    prof = resolve_profile(path, profile)
    if prof is not None:
        sig = input_profiles.read(path, prof, params=params, joint=joint)
        sig.meta["profile_how"] = "given (--profile)" if profile is not None else "auto-detected from the header"
        return sig
    if suffix == ".mcap":
        return load_mcap(path, mapping=mapping, params=params, joint=joint)
    if joint is not None:
        raise LoadError(f"{path}: --joint applies to files of several actuators (this one holds one)")
    if not _has_canonical_header(path):
        shipped = ", ".join(p.name for p in input_profiles.available())
        raise LoadError(f"{path}: no input profile recognises this file and its header names no canonical "
                        f"channel: give --profile FILE (a YAML profile, see docs/realdata.md; shipped: {shipped}) "
                        f"or map the columns, e.g. --map time=t --map current=iq")
    return _table(path, mapping, params)


def _table(path: Path, mapping: Mapping | None, params) -> Signals:
    """A CSV (or a JSON log, as its table) read with ``mapping``: single-column targets by :func:`load_csv`, the
    combined expressions over the columns they name (read alongside, then evaluated)."""
    if path.suffix.lower() in jsonio.SUFFIXES:
        with jsonio.as_csv(path) as (tmp, table):
            sig = _table(tmp, mapping, params)
        jsonio.finish(sig, path, table)
        return sig
    if mapping is None or not mapping.combined:
        return load_csv(path, mapping=mapping, params=params)
    simple = Mapping(dict(mapping.columns), dict(mapping.scale), dict(mapping.offset))
    if not (set(simple.columns) - {"time"}):           # load_csv wants one single-column channel to read
        t0, e0 = next(iter(mapping.combined.items()))
        simple.columns[t0] = e0.columns[0]
    sig = load_csv(path, mapping=simple, params=params, aux=mapping.combined_sources())
    mapping.apply_combined(sig, where=str(path))
    return sig


def load_many(paths: list[str | Path], *, params=None, profile=None) -> Signals:
    """Several files of one format as one :class:`Signals`: one segment per file, time from each file's
    own clock (``meta["time_offset_s"]`` when the profile zeroes it), issues merged per kind."""
    parts = [load(p, params=params, profile=profile) for p in paths]
    parts = [p for p in parts if len(p.time)]
    if not parts:
        raise LoadError(f"{', '.join(map(str, paths))}: no data")
    parts.sort(key=lambda p: p.meta.get("time_offset_s", 0.0))
    t0 = parts[0].meta.get("time_offset_s", 0.0)
    names = sorted({n for p in parts for n in p.channels})
    anames = sorted({n for p in parts for n in p.meta["aux"]})
    time, chans, aux, segs, issues = [], {n: [] for n in names}, {n: [] for n in anames}, [], []
    k = 0
    for p in parts:
        n = len(p.time)
        off = p.meta.get("time_offset_s", 0.0) - t0
        if time and off == 0.0:                       # files without their own clock: back to back
            off = time[-1][-1] + (p.time[1] - p.time[0] if n > 1 else 1.0) - p.time[0]
        time.append(p.time + off)
        for c in names:
            chans[c].append(p.channels.get(c, np.full(n, np.nan)))
        for c in anames:
            v = p.meta["aux"].get(c)
            aux[c].append(v if isinstance(v, np.ndarray) and len(v) == n else np.full(n, np.nan))
        segs.append((k, k + n))
        k += n
        for i in p.issues:
            i.detail = f"{Path(p.source).name}: {i.detail}"
            if i.first_time is not None:
                i.first_time += off
            issues.append(i)
    first = parts[0].meta
    meta = {k_: first.get(k_) for k_ in ("profile", "profile_path", "description", "licence", "hints",
                                          "clean_limits", "gear_ratio", "steady_state_points", "voltage_timing",
                                          "declared")
            if k_ in first}
    declared = [p.meta.get("voltage_timing") for p in parts]
    if len({None if d is None else (d.convention, d.acts_after_sample_s) for d in declared}) > 1:
        raise LoadError(f"{', '.join(map(str, paths))}: the files declare different voltage timings ("
                        + ", ".join(f"{Path(p.source).name}: {d.convention if d else 'none'}"
                                    for p, d in zip(parts, declared)) + "): load them apart")
    try:
        drive_tuning.declared(parts)
    except ValueError as exc:
        raise LoadError(f"{', '.join(map(str, paths))}: {exc}") from None
    meta.update({"aux": {c: np.concatenate(v) for c, v in aux.items()}, "notes": [],
                 "semantics": dict(parts[-1].meta["semantics"]), "files": [Path(p.source).name for p in parts],
                 "time_offset_s": t0})
    for p in parts:
        for name, cnt in p.meta.get("premasked", {}).items():
            meta.setdefault("premasked", {})
            meta["premasked"][name] = meta["premasked"].get(name, 0) + cnt
    meta["notes"].append(f"{len(parts)} files, one segment per file; per-file decisions are in the issues")
    src = str(Path(paths[0]).parent) if len({Path(p).parent for p in paths}) == 1 else ", ".join(map(str, paths))
    return Signals(np.concatenate(time), {c: np.concatenate(v) for c, v in chans.items()}, src,
                   _merge_issues(issues, len(parts)), segs, meta)


def _merge_issues(issues: list[DataIssue], n_files: int) -> list[DataIssue]:
    """One issue per (kind, channel, action) for a set of files: counts summed, details of the first few."""
    groups: dict[tuple, list[DataIssue]] = {}
    for i in issues:
        groups.setdefault((i.kind, i.channel, i.action), []).append(i)
    out = []
    for (kind, chan, action), items in groups.items():
        if len(items) == 1:
            out.append(items[0])
            continue
        firsts = [i.first_time for i in items if i.first_time is not None]
        shown = "; ".join(i.detail for i in items[:2])
        out.append(DataIssue(kind, chan, sum(i.count for i in items), min(firsts) if firsts else None,
                             f"in {len(items)} of {n_files} files: {shown}"
                             + (f"; ... ({len(items) - 2} more)" if len(items) > 2 else ""), action))
    return out
