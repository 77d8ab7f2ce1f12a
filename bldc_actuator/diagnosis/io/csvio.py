"""CSV recordings -> raw :class:`~..signals.Signals` (a header row, or header-less with ``#k`` columns).

Loaders only translate; they never mask or drop samples (except rows with nothing parseable, which are
reported). Problems are found and reported by :func:`.cleaning.clean`.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ... import drive_tuning
from ... import voltage_timing as vt
from ..signals import CANONICAL, DataIssue, Signals
from .mapping import TARGETS, LoadError, Mapping, parse_expression

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
             aux: dict[str, str] | None = None, only_mapped: bool = False, skip_lines: int = 0,
             units_row: bool = False, time_rate: float | None = None) -> Signals:
    """CSV with a header row. Default columns: ``time`` plus any canonical names (SI units, see
    :data:`~..signals.CANONICAL`); ``mapping`` renames/scales other columns (``#k`` for header-less files).
    Empty cells are NaN; a row with fewer fields than the header gets NaN for the missing ones (reported);
    a non-numeric cell in a used column is an error naming the line and column.
    ``aux`` (name -> expression, same syntax as a mapping) reads extra non-canonical columns into
    ``meta["aux"]``; a missing aux column is skipped (listed in ``meta["aux_missing"]``).
    ``only_mapped``: use the mapping alone (do not also pick up columns that happen to carry canonical
    names; the real-data adapters use this). ``# key: value`` comment lines before the header are the file's
    declarations (``meta["declared"]``); the voltage timing among them (this project's writers declare it:
    :mod:`bldc_actuator.voltage_timing`) is ``meta["voltage_timing"]``."""
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
    numbered = numbered[skip_lines:]
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
    units: dict[str, str] = {}
    if units_row and not headerless and data_rows:
        urow = [u.strip() for u in next(csv.reader([data_rows[0][1]], delimiter=delim))]
        units = dict(zip(header, urow))
        data_rows = data_rows[1:]
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
    if "time" not in targets and time_rate is None:
        raise LoadError(f"{path}: no 'time' column (columns: {', '.join(header)}); name it 'time' [s] or map "
                        f"one, e.g. --map time=timestamp (scale it: --map time=t_ms*0.001)")
    if len(targets) == (0 if "time" not in targets else 1):
        raise LoadError(f"{path}: no canonical channel found (columns: {', '.join(header)}; canonical: "
                        f"{', '.join(CANONICAL)}); map some with --map NAME=COLUMN")

    need = max(targets.values()) + 1 if targets else 1
    cols: dict[str, list[str]] = {t: [] for t in targets}
    acols: dict[str, list[str]] = {a: [] for a in aux_cols}
    short: list[int] = []
    long_rows = 0
    rows = list(csv.reader([ln for _, ln in data_rows], delimiter=delim))
    lines = [lineno for lineno, _ in data_rows]
    if rows and len(set(map(len, rows))) == 1 and len(rows[0]) >= need:
        # every row as wide as the others and wide enough (the common file): the columns by one transposition
        n = len(rows[0])
        if n > max(width, need):
            long_rows = len(rows)
        by_column = list(zip(*rows))
        for t, k in targets.items():
            cols[t] = list(by_column[k])
        for a, (k, _, _) in aux_cols.items():
            acols[a] = list(by_column[k]) if k < n else [""] * len(rows)
    else:
        for lineno, row in zip(lines, rows):
            n = len(row)
            if n < need:
                short.append(lineno)
            if n > max(width, need):
                long_rows += 1
            for t, k in targets.items():
                cols[t].append(row[k] if k < n else "")
            for a, (k, _, _) in aux_cols.items():
                acols[a].append(row[k] if k < n else "")
    values = {}
    for t, k in targets.items():
        name = mapping.columns.get(t, header[k] if k < width else f"#{k}")
        values[t] = mapping.apply(t, _to_float_column(cols[t], lines, path, name)) if t in mapping.columns \
            else _to_float_column(cols[t], lines, path, name)
    aux_values = {}
    for a, (k, sc, off) in aux_cols.items():
        aux_values[a] = _to_float_column(acols[a], lines, path, header[k] if k < width else f"#{k}") * sc + off
    t_all = values.pop("time") if "time" in values else np.arange(len(lines)) / float(time_rate)
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
    declared = vt.parse_csv_comments(raw_lines)
    try:
        timing = vt.from_metadata(declared, f"{path.name} comment lines")
        drive_tuning.from_metadata(declared, f"{path.name} comment lines")
    except ValueError as exc:
        raise LoadError(f"{path}: {exc}") from None
    if timing is not None:
        notes.append(f"the file declares its voltage timing: {timing.convention}"
                     + (f" (acts {1e6 * timing.acts_after_sample_s:+.3g} µs after its sample)"
                        if timing.acts_after_sample_s is not None else ""))
    meta = {"format": "csv", "mapping": mapping.describe(), "semantics": semantics, "notes": notes,
            "declared": declared, "voltage_timing": timing,
            "unused_columns": unused, "gear_ratio": float(params.gear.gear_ratio) if params is not None else None,
            "params_from_recording": None, "first_data_line": data_rows[0][0],
            "line_numbers": np.asarray(lines, dtype=np.int64), "aux": aux_values, "aux_missing": aux_missing,
            "header": header, "units": units}
    return Signals(t_all, values, str(path), issues, [], meta)
