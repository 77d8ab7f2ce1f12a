"""Command profiles: step, chirp, sine, or a CSV of commands; and running one through an actuator.

A profile is a zero-order-hold sequence: command ``values[k]`` applies from ``t[k]`` to ``t[k+1]``.
Commands are q-axis current [A] (``kind="current"``) or output torque [N·m] (``kind="torque"``);
an optional external load torque at the output [N·m] rides along.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

KINDS = ("current", "torque")


@dataclass(frozen=True)
class RunSummary:
    """A run's figures at the kernel's resolution: every current-loop tick (and the start), whatever the rate the
    signals were sampled at (a peak between two output samples is a peak)."""

    duration: float                     #: [s]
    ticks: int                          #: current-loop ticks the figures cover
    peak_abs_i_q: float                 #: max |i_q| [A]
    peak_abs_i_d: float                 #: max |i_d| [A]
    peak_abs_velocity_out: float        #: max |velocity_out| [rad/s, output side]
    saturated_fraction: float           #: fraction of the ticks whose held voltage is on the inverter's circle
    T_winding_start: float              #: [degC]
    T_winding_end: float                #: [degC]
    T_winding_peak: float               #: [degC]

    @classmethod
    def from_signals(cls, sig: dict[str, np.ndarray]) -> "RunSummary":
        """From :meth:`~bldc_actuator.model.Actuator.tick_signals` of the run's tick states (the start first)."""
        t = sig["t"]
        return cls(duration=float(t[-1] - t[0]), ticks=len(t) - 1,
                   peak_abs_i_q=float(np.max(np.abs(sig["i_q"]))), peak_abs_i_d=float(np.max(np.abs(sig["i_d"]))),
                   peak_abs_velocity_out=float(np.max(np.abs(sig["velocity_out"]))),
                   saturated_fraction=float(np.mean(sig["voltage_saturated"][1:])) if len(t) > 1 else 0.0,
                   T_winding_start=float(sig["T_winding"][0]), T_winding_end=float(sig["T_winding"][-1]),
                   T_winding_peak=float(np.max(sig["T_winding"])))


@dataclass
class SimResult:
    """Signals sampled over a run: each field an array over sample times (see :func:`Actuator.outputs`)."""

    signals: dict[str, np.ndarray]
    params: object                      #: the :class:`~bldc_actuator.params.ActuatorParams` of the run
    summary: RunSummary | None = None   #: the run's figures at every current-loop tick (:func:`run_profile`)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.signals[key]

    def keys(self):
        return self.signals.keys()


@dataclass
class Profile:
    t: np.ndarray                       #: sample times [s], strictly increasing, t[0] = 0 usually
    values: np.ndarray                  #: command at each sample (held until the next)
    kind: str = "current"               #: "current" [A, q-axis] or "torque" [N·m, output]
    load_torque: np.ndarray | None = None  #: external load at the output [N·m]
    name: str = "profile"
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.t = np.asarray(self.t, dtype=float)
        self.values = np.asarray(self.values, dtype=float)
        if self.kind not in KINDS:
            raise ValueError(f"profile kind: expected one of {KINDS}, got {self.kind!r}")
        if self.t.ndim != 1 or self.t.shape != self.values.shape or len(self.t) < 2:
            raise ValueError("profile: t and values must be 1-D arrays of the same length >= 2")
        if not np.all(np.diff(self.t) > 0):
            k = int(np.argmin(np.diff(self.t) > 0)) + 1
            raise ValueError(f"profile time: must be strictly increasing; sample {k} (t={self.t[k]!r} s) is not")
        if not np.all(np.isfinite(self.values)):
            k = int(np.argmin(np.isfinite(self.values)))
            raise ValueError(f"profile values: sample {k} is not finite ({self.values[k]!r})")
        if self.load_torque is not None:
            self.load_torque = np.asarray(self.load_torque, dtype=float)
            if self.load_torque.shape != self.t.shape:
                raise ValueError("profile load_torque: must have the same length as t")

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])


def _time(duration: float, rate: float) -> np.ndarray:
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"duration: expected > 0 s, got {duration!r}")
    if not (rate > 0 and math.isfinite(rate)):
        raise ValueError(f"rate: expected > 0 Hz, got {rate!r}")
    n = int(round(duration * rate))
    return np.arange(n + 1) / rate


def step(amplitude: float, duration: float = 0.5, t_step: float = 0.05, rate: float = 1000.0,
         kind: str = "current", initial: float = 0.0) -> Profile:
    """Step from ``initial`` to ``amplitude`` at ``t_step``."""
    t = _time(duration, rate)
    return Profile(t, np.where(t >= t_step, amplitude, initial), kind, name=f"step {amplitude:g}")


def sine(amplitude: float, frequency: float, duration: float = 1.0, rate: float = 1000.0,
         kind: str = "current", offset: float = 0.0) -> Profile:
    t = _time(duration, rate)
    return Profile(t, offset + amplitude * np.sin(2 * np.pi * frequency * t), kind,
                   name=f"sine {amplitude:g} @ {frequency:g} Hz")


def chirp(amplitude: float, f0: float, f1: float, duration: float = 2.0, rate: float = 1000.0,
          kind: str = "current", method: str = "logarithmic") -> Profile:
    """Swept sine from ``f0`` to ``f1`` Hz (scipy.signal.chirp)."""
    from scipy.signal import chirp as _chirp

    t = _time(duration, rate)
    return Profile(t, amplitude * _chirp(t, f0, duration, f1, method=method, phi=-90), kind,
                   name=f"chirp {f0:g}-{f1:g} Hz")


#: time units a command CSV may be in -> seconds per unit
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
#: a time column's name: ``time`` (seconds, checked), or ``time``/``t`` with its unit (``time_ms``, ``t [ms]``)
_TIME_COLUMN = re.compile(r"^(?:time|t)(?:_(s|ms|us|ns)|\s*\[\s*(s|ms|us|µs|ns)\s*\])$|^time$")
#: a unit-less ``time`` column is taken for milliseconds (an error) when it has at least this many rows spaced
#: >= 1 s (as seconds a table of commands at <= 1 Hz, as milliseconds an ordinary log at <= 1 kHz), or when it
#: lasts at least this long in whole numbers
SUSPECT_MS_ROWS = 20
SUSPECT_MS_DURATION_S = 60.0


def _time_column(header: list[str]) -> tuple[int, str | None]:
    """(index, unit named in the header or None) of the time column; ValueError when there is none."""
    for k, name in enumerate(header):
        m = _TIME_COLUMN.match(name)
        if m:
            unit = m.group(1) or m.group(2)
            return k, (None if unit is None else unit.replace("µ", "u"))
    raise ValueError("header needs a 'time' column [s] (or one naming its unit: time_s, time_ms, t_ms, "
                     f"'time [ms]', time_us, time_ns), got {header}")


def looks_like_milliseconds(t: np.ndarray) -> bool:
    """Whether a time column read as seconds looks like milliseconds (see :data:`SUSPECT_MS_ROWS`)."""
    t = np.asarray(t, float)
    if len(t) < 2:
        return False
    dt = np.diff(t)
    dense_slow = len(t) >= SUSPECT_MS_ROWS and float(np.median(dt)) >= 1.0
    long_whole = float(t[-1] - t[0]) >= SUSPECT_MS_DURATION_S and bool(np.all(t == np.round(t)))
    return dense_slow or long_whole


def from_csv(path: str | Path, time_unit: str | None = None) -> Profile:
    """CSV with a header: a time column and ``current_command`` [A] or ``torque_command`` [N·m], optional
    ``load_torque`` [N·m]. Errors name the line.

    Time: ``time`` in seconds, or a name with its unit (``time_s``, ``time_ms``/``t_ms``, ``time [ms]``, ``_us``,
    ``_ns``), or ``time_unit`` (one of :data:`TIME_UNITS`; ``simulate --time-unit``) for a unit-less ``time``. A
    unit-less ``time`` without ``time_unit`` that looks like milliseconds (:func:`looks_like_milliseconds`: a 900 ms
    log would run for 900 s) is an error saying how to declare the unit; ``time_unit="s"`` confirms seconds."""
    path = Path(path)
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise ValueError(f"time unit: expected one of {', '.join(TIME_UNITS)}, got {time_unit!r}")
    with path.open(newline="") as fh:
        reader = csv.reader(line for line in fh if not line.lstrip().startswith("#"))
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise ValueError(f"{path}: empty file, expected a header line") from None
        try:
            k_time, header_unit = _time_column(header)
        except ValueError as exc:
            raise ValueError(f"{path}:1: {exc}") from None
        if header_unit is not None and time_unit is not None and header_unit != time_unit:
            raise ValueError(f"{path}:1: column {header[k_time]!r} says {header_unit}, the time unit given is "
                             f"{time_unit}: drop one of them")
        kind = "current" if "current_command" in header else "torque" if "torque_command" in header else None
        if kind is None:
            raise ValueError(f"{path}:1: header needs 'current_command' [A] or 'torque_command' [N*m]")
        cols = {"time": k_time, "cmd": header.index(f"{kind}_command")}
        if "load_torque" in header:
            cols["load"] = header.index("load_torque")
        rows = []
        for lineno, row in enumerate(reader, start=2):
            if not row or all(not x.strip() for x in row):
                continue
            try:
                rows.append([float(row[cols[k]]) for k in cols])
            except (ValueError, IndexError):
                raise ValueError(f"{path}:{lineno}: expected numbers in columns "
                                 f"{', '.join(header[i] for i in cols.values())}, got {row!r}") from None
    if len(rows) < 2:
        raise ValueError(f"{path}: need at least two command rows")
    data = np.array(rows)
    unit = header_unit or time_unit
    if unit is None and looks_like_milliseconds(data[:, 0]):
        span = float(data[-1, 0] - data[0, 0])
        raise ValueError(
            f"{path}: column {header[k_time]!r} looks like milliseconds, expected seconds: {len(data)} rows "
            f"{float(np.median(np.diff(data[:, 0]))):g} apart would run for {span:g} s ({span / 60:.1f} min) as "
            f"seconds, {span * 1e-3:g} s as milliseconds. Declare the unit: --time-unit ms (time_unit='ms'), or "
            f"name the column time_ms / t_ms / 'time [ms]'; --time-unit s (or a column time_s) if it is seconds")
    data[:, 0] *= TIME_UNITS[unit or "s"]
    meta = {"time_column": header[k_time], "time_unit": unit or "s"}
    try:
        return Profile(data[:, 0], data[:, 1], kind, data[:, 2] if "load" in cols else None, name=path.name,
                       meta=meta)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


#: signals recorded by :func:`run_profile` (all of :func:`Actuator.outputs` that are numbers)
def run_profile(actuator, profile: Profile, *, record_every: float | None = None):
    """Drive ``actuator`` (an :class:`~bldc_actuator.model.Actuator`) with ``profile``; record outputs at every
    profile sample (or every ``record_every`` seconds). Returns a :class:`SimResult` whose ``summary`` covers every
    current-loop tick (:class:`RunSummary`), not only the recorded samples."""

    setter = actuator.set_current_command if profile.kind == "current" else actuator.set_torque_command
    t_ns = np.round(profile.t * 1e9).astype(np.int64)
    start = actuator.t_ns
    if record_every:
        rec_ns = np.arange(t_ns[0], t_ns[-1] + 1, int(round(record_every * 1e9)), dtype=np.int64)
    else:
        rec_ns = t_ns
    events = np.union1d(t_ns, rec_ns)
    cmd_idx = np.searchsorted(t_ns, events, side="right") - 1
    is_rec = np.isin(events, rec_ns)
    rows: list[dict] = []
    commanded: list[float] = []                            # the q-axis current command from each sample on
    load = profile.load_torque
    ticks = actuator.tick_trace(int(profile.duration * actuator.params.drive.current_loop_rate) + 2)
    ticks.record_now()                                     # the summary's states: the start and every tick
    for k, (ev, ci, rec) in enumerate(zip(events, cmd_idx, is_rec)):
        target = start + int(ev - t_ns[0])
        if target > actuator.t_ns:
            ticks.step_ns(target - actuator.t_ns)
        if rec:
            rows.append(actuator.outputs())
        setter(float(profile.values[ci]))
        if rec:
            commanded.append(actuator.current_command)
        if load is not None:
            actuator.set_load_torque(float(load[ci]))
    keys = [k for k, v in rows[0].items() if isinstance(v, (int, float, bool, np.bool_))]
    signals = {k: np.array([r[k] for r in rows], dtype=float) for k in keys}
    signals["command"] = profile.values[np.searchsorted(t_ns, rec_ns, side="right") - 1]
    signals["i_q_command"] = np.array(commanded)
    summary = RunSummary.from_signals(actuator.tick_signals(ticks.states()))
    return SimResult(signals, actuator.params, summary)
