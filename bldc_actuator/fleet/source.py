"""Where a fleet recording comes from: which joints a file holds, and each joint's Signals, actuator id and
start time.

A thin adapter over :mod:`bldc_actuator.diagnosis.io.loaders` (``load(path, *, mapping, params, profile,
joint)`` and ``joints(path, profile)`` read every format through input profiles). The adapter only adds
what a fleet needs on top, in this order of preference:

actuator id   ``Signals.actuator_id`` (a profile field or the recording's metadata) -> the path relative to
              the search root without the file name (``robot7/knee/2026-01-02.mcap`` -> ``robot7/knee``;
              the folder's own name for files directly in the root)
              plus ``/<joint>`` for a multi-joint file
start time    ``Signals.start_time`` with ``Signals.start_time_source`` (the recording's own clock or
              metadata; a clock before 2000, e.g. the node's simulation time from 0, is not a date) -> a date (and time) in the file name -> a Unix epoch in the file name
              (``..._1666994786.44.csv``) -> the file's modification time; the source is always said
"""

from __future__ import annotations

import datetime as dt
import os
import re
from pathlib import Path

from ..diagnosis.io import loaders

_DATE = re.compile(r"(?<!\d)(20\d\d)[-_]?(0[1-9]|1[0-2])[-_]?([0-2]\d|3[01])"
                   r"(?:[T_ -]?([01]\d|2[0-3])[-:_]?([0-5]\d)(?:[-:_]?([0-5]\d))?)?(?!\d)")
#: a recording's clock earlier than this is a simulation / since-boot clock, not a date
WALL_CLOCK_EPOCH = dt.datetime(2000, 1, 1, tzinfo=dt.timezone.utc)
_EPOCH = re.compile(r"(?<!\d)(1[3-9]\d{8})(\.\d+)?(?!\d)")


def joints(path: str | Path, profile=None) -> list[str | None]:
    """Joint names in a file (``[None]`` for a single-actuator recording)."""
    found = list(loaders.joints(path, profile=profile) or [])
    return found if found else [None]


def load(path: str | Path, *, joint=None, profile=None, mapping=None, params=None):
    """Raw Signals of one joint of one file (see :func:`loaders.load`)."""
    return loaders.load(path, mapping=mapping, params=params, profile=profile, joint=joint)


def actuator_id(signals, path: str | Path, root: str | Path | None, joint=None) -> str:
    aid = getattr(signals, "actuator_id", None) or (getattr(signals, "meta", {}) or {}).get("actuator_id")
    if aid:
        aid = str(aid)
        if joint is not None and not aid.endswith(str(joint)):
            aid = f"{aid}/{joint}"
        return aid
    p = Path(path).resolve()
    try:
        rel = p.parent.relative_to(Path(root).resolve()) if root else Path(p.parent.name)
    except ValueError:
        rel = Path(p.parent.name)
    # a file directly in the search root: the folder's name (every day's file of one robot, one id)
    base = rel.as_posix() if rel.as_posix() not in ("", ".") else p.parent.name
    return f"{base}/{joint}" if joint is not None else base


def start_time(signals, path: str | Path) -> tuple[dt.datetime, str]:
    """(UTC datetime, source) -- see the module docstring for the order."""
    meta = getattr(signals, "meta", {}) or {}
    st = getattr(signals, "start_time", None) or meta.get("start_time")
    if st is not None:
        src = getattr(signals, "start_time_source", None) or meta.get("start_time_source") or "recording"
        when = _as_datetime(st)
        if when is not None and when >= WALL_CLOCK_EPOCH:
            return when, str(src)
        # a clock that starts at 0 (simulation time, time since boot) is no date: fall through
    name = Path(path).name
    m = _DATE.search(name)
    if m:
        y, mo, d, hh, mm, ss = m.groups()
        return dt.datetime(int(y), int(mo), int(d), int(hh or 0), int(mm or 0), int(ss or 0),
                           tzinfo=dt.timezone.utc), "file name (date)"
    m = _EPOCH.search(name)
    if m:
        return dt.datetime.fromtimestamp(float(m.group(0)), dt.timezone.utc), "file name (Unix time)"
    return dt.datetime.fromtimestamp(os.path.getmtime(path), dt.timezone.utc), "file modification time"


def _as_datetime(x) -> dt.datetime | None:
    if isinstance(x, dt.datetime):
        return x if x.tzinfo else x.replace(tzinfo=dt.timezone.utc)
    if isinstance(x, (int, float)):
        v = float(x)
        if v > 1e17:        # nanoseconds
            v *= 1e-9
        return dt.datetime.fromtimestamp(v, dt.timezone.utc) if v > 0 else None
    if isinstance(x, str):
        try:
            return _as_datetime(dt.datetime.fromisoformat(x.replace("Z", "+00:00")))
        except ValueError:
            return None
    return None
