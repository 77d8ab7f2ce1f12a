"""JSON logs as a table of columns: a list of records ``[{"t": 0.0, "angle": 0.1, ...}, ...]``, JSON Lines (one
record per line) or an object of equal-length arrays ``{"t": [...], "angle": [...]}``.

Nested objects flatten to dotted keys (``{"motor": {"duty": 0.3}}`` -> ``motor.duty``); numbers and booleans
(1/0) are values, anything else (``null``, strings, lists) reads as NaN. The keys, in order of first appearance,
are the table's header: input profiles recognise a JSON format by them (``signature: header_has``) and name
them as columns, ``--map`` expressions name them as CSV columns. :func:`as_csv` writes the table as the CSV the
profile and mapping readers take (one row per record, row ``k + 2`` is record ``k``).
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from .mapping import LoadError

#: file suffixes read as JSON
SUFFIXES = (".json", ".jsonl", ".ndjson")


@dataclass
class JsonTable:
    """The columns of a JSON log: ``keys`` in order of first appearance, ``columns`` key -> float array."""

    keys: list[str]
    columns: dict[str, np.ndarray]
    layout: str          #: "records" | "json lines" | "columns"

    @property
    def n(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0


def _flatten(rec: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in rec.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _number(v) -> float:
    if isinstance(v, bool):
        return 1.0 if v else 0.0
    if isinstance(v, (int, float)):
        return float(v)
    return math.nan


def read_table(path: str | Path) -> JsonTable:
    """The table of a JSON / JSON Lines log; LoadError naming the file and the line or record at fault."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise LoadError(f"{path}: cannot read: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise LoadError(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None
    if not text.strip():
        raise LoadError(f"{path}: no data (empty file)")
    try:
        tree = json.loads(text)
        layout = "records"
    except json.JSONDecodeError as first:
        records = []
        for lineno, line in enumerate(text.splitlines(), 1):
            if not line.strip():
                continue
            try:
                records.append(json.loads(line))
            except json.JSONDecodeError as exc:
                where = first if len(records) == 0 else exc
                raise LoadError(f"{path}: line {lineno if records else where.lineno}: not JSON nor JSON Lines "
                                f"({where.msg})") from None
        tree, layout = records, "json lines"
    if isinstance(tree, dict):
        arrays = {k: v for k, v in _flatten(tree).items() if isinstance(v, list)}
        lens = {len(v) for v in arrays.values()}
        if not arrays or len(lens) != 1:
            raise LoadError(f"{path}: a JSON object must hold equal-length arrays, one per column "
                            f"(lengths: {', '.join(f'{k}={len(v)}' for k, v in arrays.items()) or 'none'}); "
                            f"or give a list of records [{{\"t\": ..., ...}}, ...]")
        cols = {k: np.array([_number(x) for x in v]) for k, v in arrays.items()}
        return JsonTable(list(arrays), cols, "columns")
    if not isinstance(tree, list) or not tree:
        raise LoadError(f"{path}: expected a list of records [{{\"t\": ..., ...}}, ...], JSON Lines or an object of "
                        f"arrays")
    flat = []
    for k, rec in enumerate(tree):
        if not isinstance(rec, dict):
            raise LoadError(f"{path}: record {k}: expected an object {{\"key\": value, ...}}, got "
                            f"{type(rec).__name__}")
        flat.append(_flatten(rec))
    keys = list(dict.fromkeys(k for rec in flat for k in rec))
    cols = {key: np.array([_number(rec.get(key)) for rec in flat]) for key in keys}
    return JsonTable(keys, cols, layout)


def header(path: str | Path, n: int = 8) -> list[str]:
    """The CSV lines (header and the first ``n - 1`` rows) a JSON log reads as, for profile signatures."""
    table = read_table(path)
    rows = [",".join(_quote(k) for k in table.keys)]
    for i in range(min(n - 1, table.n)):
        rows.append(",".join(repr(float(table.columns[k][i])) for k in table.keys))
    return rows


def _quote(key: str) -> str:
    return f'"{key}"' if any(c in key for c in ',;\t"') else key


@contextlib.contextmanager
def as_csv(path: str | Path) -> Iterator[tuple[Path, JsonTable]]:
    """The JSON log written as a temporary CSV (header = the keys) for the CSV readers; removed afterwards."""
    table = read_table(path)
    with tempfile.TemporaryDirectory(prefix="bldc_json_") as tmp:
        out = Path(tmp) / (Path(path).stem + ".csv")
        with open(out, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(table.keys)
            data = np.column_stack([table.columns[k] for k in table.keys])
            for row in data:
                w.writerow(["" if not math.isfinite(x) else repr(float(x)) for x in row])
        try:
            yield out, table
        except LoadError as exc:            # errors name the JSON log, not the temporary CSV
            raise LoadError(str(exc).replace(str(out), str(path))) from None


def finish(sig, path: str | Path, table: JsonTable) -> None:
    """A Signals read through :func:`as_csv` names the JSON file and its records again."""
    sig.source = str(path)
    sig.meta["format"] = "json"
    sig.meta["json_layout"] = table.layout
    sig.meta.setdefault("notes", []).append(
        f"JSON log ({table.layout}, {table.n} records, keys {', '.join(table.keys)}); a line number k in the "
        f"issues is record k - 2 (counted from 0)")
