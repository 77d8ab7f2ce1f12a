"""The data layer's one currency: :class:`Signals` (time series in canonical SI channels) and
:class:`DataIssue` (one thing found wrong with the data, with numbers, and what was done about it).

Canonical channels (:data:`CANONICAL`) are SI and on the MOTOR side unless the name says otherwise
(``torque``, ``torque_command`` and ``load_torque`` are at the OUTPUT, after the gear). Loaders
(:mod:`.io.loaders`, through :mod:`.io.input_profiles` for foreign formats) translate recordings into these names; :func:`.io.cleaning.clean` finds
and reports problems. A masked sample is ``NaN``: it stays in the arrays (so indices and time line up)
and is excluded from fits.

Time is in seconds and, after cleaning, strictly increasing. ``segments`` are ``[start, stop)`` index
ranges without gaps; derivatives and filters should run per segment.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: canonical channel name -> (unit, description). All SI, motor side unless the name ends in the output.
CANONICAL: dict[str, tuple[str, str]] = {
    "current_command": ("A", "q-axis current command"),
    "torque_command": ("N*m", "output torque command"),
    "current": ("A", "measured q-axis current"),
    "current_d": ("A", "measured d-axis current"),
    "position": ("rad", "rotor (motor-side) angle, unwrapped"),
    "load_position": ("rad", "load (joint-side) angle behind the transmission, at the OUTPUT, unwrapped: a second "
                             "encoder after a compliant gear, belt or series-elastic spring"),
    "velocity": ("rad/s", "rotor speed"),
    "bus_voltage": ("V", "DC bus voltage"),
    "voltage_q": ("V", "applied q-axis voltage (power-invariant)"),
    "voltage_d": ("V", "applied d-axis voltage (power-invariant)"),
    "winding_temperature": ("degC", "winding temperature"),
    "housing_temperature": ("degC", "housing / stator / case temperature"),
    "torque": ("N*m", "measured torque at the OUTPUT (sensor), positive = actuator drives in + direction"),
    "load_torque": ("N*m", "known external load at the output"),
    "bus_current": ("A", "DC bus current"),
}

#: commands (what was asked); every other canonical channel is a measurement
COMMAND_CHANNELS = ("current_command", "torque_command")

#: DataIssue kinds. The first nine are the contract; ``sign_convention`` (a channel's sign disagrees with
#: the reference channel) and ``wrapped`` (an angle that wraps around) were added for the real data, ``clock_jitter``
#: (stamps that scatter around the samples' clock, or samples that scatter around their stamps: ``io/clock.py``) for
#: a logger's odd clock.
ISSUE_KINDS = ("outlier", "gap", "duplicate_time", "non_monotonic_time", "unit_suspect", "constant", "nan",
               "clipped", "missing_channel", "sign_convention", "wrapped", "clock_jitter")


@dataclass
class DataIssue:
    """One problem found in a recording.

    kind       one of :data:`ISSUE_KINDS`
    channel    canonical name, or ``"time"``
    count      samples (or events, for gaps) affected
    first_time time [s] of the first affected sample (``None`` when it does not apply)
    detail     plain words with numbers, e.g. ``current: 3 samples beyond ±60 A physical limit (min -504 A
               at t=12.31 s)``
    action     what was done: ``masked (NaN), excluded from fits`` | ``segment split`` |
               ``dropped later duplicate`` | ``none`` | ...
    """

    kind: str
    channel: str
    count: int
    first_time: float | None
    detail: str
    action: str

    def __post_init__(self):
        if self.kind not in ISSUE_KINDS:
            raise ValueError(f"DataIssue.kind: {self.kind!r} is not one of {', '.join(ISSUE_KINDS)}")
        self.count = int(self.count)
        self.first_time = None if self.first_time is None else float(self.first_time)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def __str__(self) -> str:
        return f"[{self.kind}] {self.detail} -> {self.action}"


@dataclass
class Signals:
    """Canonical time series of one recording.

    time      [s], strictly increasing after :func:`.io.cleaning.clean` (raw loader output may not be)
    channels  canonical name -> float array, same length as ``time``; ``NaN`` = masked / not sampled
    source    file path or description
    issues    what was found (loaders add parse-level issues, cleaning adds the rest)
    segments  ``[start, stop)`` index ranges without gaps
    meta      ``gear_ratio`` (used to bring output-side signals to the motor side), ``mapping`` (applied
              column expressions), ``rate_hz``, ``sampling`` (dt statistics), ``semantics`` (channel ->
              what it really is in this recording), ``notes`` (list of plain-word remarks),
              ``params_from_recording`` (ActuatorParams or None), ``aux`` (non-canonical arrays aligned
              with ``time``), ``accounting`` (rows in / kept / dropped, samples masked), and for tables of
              operating points ``steady_state_points=True``.
    """

    time: np.ndarray
    channels: dict[str, np.ndarray]
    source: str = ""
    issues: list[DataIssue] = field(default_factory=list)
    segments: list[tuple[int, int]] = field(default_factory=list)
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.time = np.asarray(self.time, dtype=float)
        if self.time.ndim != 1:
            raise ValueError(f"Signals.time: expected a 1-D array, got shape {self.time.shape}")
        n = len(self.time)
        chans = {}
        for name, arr in self.channels.items():
            if name not in CANONICAL:
                raise ValueError(f"Signals.channels: {name!r} is not a canonical channel "
                                 f"(known: {', '.join(CANONICAL)})")
            a = np.asarray(arr, dtype=float)
            if a.shape != (n,):
                raise ValueError(f"Signals.channels[{name!r}]: length {a.shape} differs from time ({n})")
            chans[name] = a
        self.channels = chans
        if not self.segments and n:
            self.segments = [(0, n)]
        for key, default in (("notes", []), ("aux", {}), ("semantics", {}), ("mapping", {}),
                             ("gear_ratio", None), ("params_from_recording", None)):
            self.meta.setdefault(key, default)
        if "rate_hz" not in self.meta:
            self.meta["rate_hz"] = self.rate()

    # -- queries ---------------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.time)

    def has(self, name: str) -> bool:
        """The channel exists and holds at least one finite sample."""
        a = self.channels.get(name)
        return a is not None and bool(np.isfinite(a).any())

    def missing_for(self, needed: list[str]) -> list[str]:
        """Names from ``needed`` that this recording cannot supply. An entry ``"a|b"`` is satisfied by
        either channel (returned unchanged when neither exists)."""
        out = []
        for item in needed:
            if not any(self.has(n.strip()) for n in item.split("|")):
                out.append(item)
        return out

    def rate(self) -> float:
        """Median sample rate [Hz] (``nan`` with fewer than two samples)."""
        if len(self.time) < 2:
            return float("nan")
        dt = np.diff(self.time)
        dt = dt[np.isfinite(dt) & (dt > 0)]
        return float(1.0 / np.median(dt)) if len(dt) else float("nan")

    def duration(self) -> float:
        return float(self.time[-1] - self.time[0]) if len(self.time) else 0.0

    def valid(self, name: str) -> np.ndarray:
        """Boolean mask of the channel's finite (unmasked) samples (all False when absent)."""
        a = self.channels.get(name)
        return np.zeros(len(self.time), bool) if a is None else np.isfinite(a)

    # -- transforms ------------------------------------------------------------------------------
    def slice(self, t0: float, t1: float) -> "Signals":
        """Samples with ``t0 <= time < t1`` (segments clipped, issues and meta kept, aux sliced)."""
        idx = np.flatnonzero((self.time >= t0) & (self.time < t1))
        if len(idx) == 0:
            i0 = i1 = 0
        else:
            i0, i1 = int(idx[0]), int(idx[-1]) + 1
        return self._index_range(i0, i1, note=f"slice [{t0:g}, {t1:g}) s")

    def _index_range(self, i0: int, i1: int, note: str = "") -> "Signals":
        segs = [(max(a, i0) - i0, min(b, i1) - i0) for a, b in self.segments if min(b, i1) > max(a, i0)]
        n = len(self.time)
        # per-sample arrays in meta (e.g. CSV line numbers) follow the slice; ``masked`` keeps full-record indices
        meta = {k: (v[i0:i1] if isinstance(v, np.ndarray) and v.shape[:1] == (n,) else v) for k, v in self.meta.items()}
        meta["aux"] = {k: v[i0:i1] if isinstance(v, np.ndarray) and v.shape[:1] == (n,) else v
                       for k, v in self.meta.get("aux", {}).items()}
        meta["notes"] = list(self.meta.get("notes", [])) + ([note] if note else [])
        return Signals(self.time[i0:i1].copy(), {k: v[i0:i1].copy() for k, v in self.channels.items()},
                       self.source, list(self.issues), segs, meta)

    def segment_signals(self, min_samples: int = 1) -> list["Signals"]:
        """One :class:`Signals` per gap-free segment with at least ``min_samples`` samples."""
        return [self._index_range(a, b, note=f"segment [{a}, {b})") for a, b in self.segments
                if b - a >= min_samples]

    # -- reporting -------------------------------------------------------------------------------
    def to_json_issues(self) -> list[dict]:
        return [i.to_dict() for i in self.issues]

    def summary(self) -> dict[str, Any]:
        """Per-channel ranges and counts, for reports (plain Python types, JSON-ready)."""
        chans = {}
        for name, a in self.channels.items():
            ok = np.isfinite(a)
            if ok.any():
                chans[name] = {"unit": CANONICAL[name][0], "finite": int(ok.sum()), "masked": int((~ok).sum()),
                               "min": float(np.min(a[ok])), "max": float(np.max(a[ok])),
                               "median": float(np.median(a[ok]))}
            else:
                chans[name] = {"unit": CANONICAL[name][0], "finite": 0, "masked": int(len(a))}
        return {"source": self.source, "samples": len(self.time), "duration_s": self.duration(),
                "rate_hz": self.rate(), "segments": len(self.segments), "channels": chans,
                "issues": len(self.issues)}

    def describe(self) -> str:
        """Multi-line plain-text description (what ``record-info``-like output would print)."""
        s = self.summary()
        lines = [f"{self.source}: {s['samples']} samples, {s['duration_s']:.2f} s, {s['rate_hz']:.4g} Hz, "
                 f"{s['segments']} segment(s)"]
        for name, c in s["channels"].items():
            if c["finite"]:
                lines.append(f"  {name:20s} [{c['unit']}] {c['min']:.4g} .. {c['max']:.4g} "
                             f"(median {c['median']:.4g}), {c['masked']} masked")
            else:
                lines.append(f"  {name:20s} [{c['unit']}] no finite samples")
        lines += [f"  issue: {i}" for i in self.issues]
        lines += [f"  note: {n}" for n in self.meta.get("notes", [])]
        return "\n".join(lines)


def fill_gaps(x: np.ndarray) -> np.ndarray:
    """A copy of ``x`` with its non-finite samples interpolated linearly from their finite neighbours (by index;
    held flat beyond the ends); all zeros where nothing is finite."""
    x = np.asarray(x, float).copy()
    ok = np.isfinite(x)
    if ok.all() or not ok.any():
        return np.nan_to_num(x)
    idx = np.arange(len(x))
    x[~ok] = np.interp(idx[~ok], idx[ok], x[ok])
    return x
