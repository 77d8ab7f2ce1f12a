"""Find, report and (only where it is safe) repair dirty recordings. Nothing is dropped silently: every
change is a :class:`~..signals.DataIssue` with numbers, and ``meta["accounting"]`` balances the rows
(``rows_in == rows_out + sum(dropped)``); masked values are kept in ``meta["masked"]``.

What :func:`clean` does, in order
1. time: rows without a finite timestamp are dropped (no place for them). Out-of-order timestamps:
   a sample that lies at most ``max_reorder_periods`` median periods before the latest time seen is
   jitter / a swapped message -> re-ordered by a stable sort (reported). A larger backward jump is a
   clock reset or a concatenated file: those samples cannot be placed on this time axis -> dropped
   (reported with their count and the size of the jump) and a segment boundary is put there.
   Equal timestamps -> the first sample is kept, later duplicates dropped (reported, saying whether
   their values differed).
2. gaps: an interval longer than ``gap_factor`` x the median period splits the recording into
   segments; for irregular (jittery) logs the threshold is at least 2 x the 99th-percentile period so
   that logger jitter is not taken for gaps (noted in meta["sampling"]).
3. per channel: NaN/inf (inf -> NaN); all-NaN channel -> ``missing_channel``.
4. unit suspects (report only, with the ``--map`` that would fix it; values are NOT changed - apply a
   fix through the mapping): temperature in kelvin, current in mA, torque in N*mm, position in degrees /
   revolutions / output side, velocity in rpm / deg/s / output side / ERPM (from the ratio of position
   increments to integrated velocity); sign disagreements (torque vs current, command vs measurement).
   A unit-suspect channel is exempt from the physical limits below (they would mask all of it).
   A position that wraps around is unwrapped (reported as ``wrapped``): canonical position is unwrapped.
5. physical limits -> masked (NaN): |current| > current_factor x drive.current_limit (else 1000 A),
   temperature outside -40..250 degC, |velocity| > speed_factor x the no-load speed (else 1e5 rad/s),
   |voltage| > 2 x bus voltage, bus voltage <= 0, |torque| > 3 x K_t_q x current_limit x gear ratio.
   ``limits`` overrides any of them per channel: ``{"current": 60}`` (symmetric) or
   ``{"bus_voltage": (5, 60)}``; a recording's ``meta["clean_limits"]`` (set by the real-data adapters
   from its input profile, e.g. a dataset's SOURCE.txt) applies unless ``limits`` says otherwise.
6. spikes (Hampel on a 7-sample window): a sample more than ``spike_sigma`` robust sigmas (local MAD,
   floored by the noise of the first differences, by 4 quantisation steps and by 10 % of the channel's
   size (max of p1..p99 range and 99th-percentile magnitude): gross errors only) from the
   window median, which leaves and returns to the same level -> masked. Step edges and overshoot at a
   step are not spikes. Commands are never masked (they are what was sent).
6b. the clock (:mod:`.clock`): stamps that scatter around a uniform clock the samples follow (the angle says so)
   are replaced by that clock; stamps the samples follow are kept; instants that scatter around the time axis kept
   are measured. Each a ``clock_jitter`` issue with its size.
7. constant channels, stuck runs (identical values for >= 2 s in a channel that normally changes every
   sample) and clipping (a histogram spike exactly at the channel's max or min: >= 1 % of the samples and
   >= 10 x the typical count per level, not a rest value near 0, not a coarse sensor with < 20 levels)
   -> reported, values kept.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from . import clock
from ..signals import CANONICAL, COMMAND_CHANNELS, DataIssue, Signals

DEFAULTS: dict[str, Any] = {
    "gap_factor": 5.0,            # gap = interval > gap_factor x median period
    "max_reorder_periods": 5.0,   # backward time steps up to this many periods are re-ordered, else dropped
    "spike_sigma": 8.0,           # Hampel threshold in robust sigmas (None: no spike search, e.g. tables)
    "hampel_half_window": 3,      # window = 2k+1 samples
    "spike_range_fraction": 0.1,  # a spike must also exceed this fraction of the robust (p1..p99) range (gross errors only)
    "current_factor": 3.0,        # physical current limit = factor x drive.current_limit
    "speed_factor": 2.0,          # physical speed limit = factor x no-load speed
    "torque_factor": 3.0,         # physical torque limit = factor x K_t_q x current_limit x gear ratio
    "stuck_seconds": 2.0,
    "stuck_samples": 200,
}
#: bounds used when no parameters are given (loose: they only catch impossible values)
GENERIC_BOUNDS: dict[str, tuple[float, float]] = {
    "current": (-1000.0, 1000.0), "current_d": (-1000.0, 1000.0), "current_command": (-1000.0, 1000.0),
    "bus_current": (-1000.0, 1000.0), "velocity": (-1e5, 1e5), "voltage_q": (-1000.0, 1000.0),
    "voltage_d": (-1000.0, 1000.0), "bus_voltage": (0.0, 1000.0), "torque": (-1e5, 1e5),
    "load_torque": (-1e5, 1e5), "torque_command": (-1e5, 1e5),
    "winding_temperature": (-40.0, 250.0), "housing_temperature": (-40.0, 250.0),
}
CURRENTS = ("current", "current_d", "current_command", "bus_current")
TORQUES = ("torque", "load_torque", "torque_command")
TEMPERATURES = ("winding_temperature", "housing_temperature")
VOLTAGES = ("voltage_q", "voltage_d")


def _g(x: float) -> str:
    """Compact number for messages."""
    if x is None or not np.isfinite(x):
        return str(x)
    ax = abs(x)
    if ax != 0 and (ax >= 1e5 or ax < 1e-3):
        return f"{x:.3g}"
    return f"{x:.4g}"


class _Ctx:
    """State shared by the steps of one clean() call."""

    def __init__(self, raw: Signals, limits: dict | None, params):
        self.lim = dict(DEFAULTS)
        self.bounds_override: dict[str, tuple[float, float]] = {}
        for k, v in (limits or {}).items():
            if k in CANONICAL:
                if isinstance(v, (int, float)):
                    self.bounds_override[k] = (-abs(float(v)), abs(float(v)))
                else:
                    lo, hi = v
                    self.bounds_override[k] = (-math.inf if lo is None else float(lo),
                                               math.inf if hi is None else float(hi))
            elif k in DEFAULTS:
                self.lim[k] = v
            else:
                raise ValueError(f"clean(limits): unknown key {k!r} (channels: {', '.join(CANONICAL)}; "
                                 f"settings: {', '.join(DEFAULTS)})")
        self.params = params
        self.issues: list[DataIssue] = list(raw.issues)
        self.notes: list[str] = list(raw.meta.get("notes", []))
        self.masked: dict[str, dict[str, list]] = {}
        self.exempt: set[str] = set()

    def issue(self, *args) -> None:
        self.issues.append(DataIssue(*args))


# ================================================================================================ time

def _clean_time(ctx: _Ctx, raw: Signals) -> tuple[np.ndarray, dict[str, int], set[int]]:
    """Indices (into raw) of the rows kept, in time order; dropped counts; forced segment starts
    (positions in the kept array)."""
    t = raw.time
    n = len(t)
    lines = raw.meta.get("line_numbers")

    def where(i: int) -> str:
        if lines is not None and len(lines) == n:
            return f"line {int(lines[i])}"
        return f"sample {i}"

    dropped = {"nan_time": 0, "non_monotonic_time": 0, "duplicate_time": 0}
    idx = np.arange(n)
    fin = np.isfinite(t)
    if not fin.all():
        bad = np.flatnonzero(~fin)
        dropped["nan_time"] = len(bad)
        ctx.issue("nan", "time", len(bad), None,
                  f"time: {len(bad)} row(s) without a finite timestamp (first at {where(bad[0])})",
                  "dropped row(s): no place on the time axis")
        idx = idx[fin]
    tt = t[idx]
    forced: set[int] = set()
    if len(tt) > 1:
        dt = np.diff(tt)
        pos = dt[dt > 0]
        dt_med = float(np.median(pos)) if len(pos) else 0.0
        tol = ctx.lim["max_reorder_periods"] * dt_med
        runmax = np.maximum.accumulate(tt)
        prev = np.concatenate([[-np.inf], runmax[:-1]])
        back = tt < prev
        # a run of consecutive backward samples is one event: a clock jump when its first sample lies more
        # than tol behind (then the whole run is unplaceable), else jitter (re-ordered)
        far = np.zeros(len(tt), bool)
        if back.any():
            edges = np.flatnonzero(np.diff(np.concatenate([[0], back.astype(np.int8), [0]])))
            for a, b in zip(edges[::2], edges[1::2]):
                if prev[a] - tt[a] > tol:
                    far[a:b] = True
        local = back & ~far
        if far.any():
            fi = np.flatnonzero(far)
            jump = float(np.max(prev[fi] - tt[fi]))
            ctx.issue("non_monotonic_time", "time", len(fi), float(prev[fi[0]]),
                      f"time: {len(fi)} sample(s) stamped before already-recorded time (clock jumped back by up "
                      f"to {_g(jump)} s, first at {where(idx[fi[0]])}, after t={_g(prev[fi[0]])} s); they cannot "
                      f"be placed on this time axis (a reset clock or two recordings in one file?)",
                      "dropped; segment split at the jump")
            dropped["non_monotonic_time"] = len(fi)
            # a boundary wherever kept samples resume after dropped ones
            keep_mask = ~far
            kept_pos = np.cumsum(keep_mask) - 1
            for i in fi:
                j = i + 1
                while j < len(tt) and far[j]:
                    j += 1
                if j < len(tt):
                    forced.add(int(kept_pos[j]))
            idx, tt = idx[keep_mask], tt[keep_mask]
            local = local[keep_mask]
        if local.any():
            li = np.flatnonzero(local)
            order = np.argsort(tt, kind="stable")
            shift = float(np.max(np.maximum.accumulate(tt)[li] - tt[li]))
            ctx.issue("non_monotonic_time", "time", len(li), float(tt[li[0]]),
                      f"time: {len(li)} sample(s) out of order by up to {_g(shift * 1e3)} ms (first at "
                      f"{where(idx[li[0]])}, t={_g(tt[li[0]])} s)", "re-ordered by time (stable sort)")
            # forced boundaries refer to positions; re-map through the permutation
            if forced:
                inv = np.empty_like(order)
                inv[order] = np.arange(len(order))
                forced = {int(inv[p]) for p in forced}
            idx, tt = idx[order], tt[order]
        dup = np.flatnonzero(np.diff(tt) == 0) + 1
        if len(dup):
            differ = 0
            for j in dup:
                a, b = idx[j - 1], idx[j]
                for arr in raw.channels.values():
                    x, y = arr[a], arr[b]
                    if not (x == y or (np.isnan(x) and np.isnan(y))):
                        differ += 1
                        break
            ctx.issue("duplicate_time", "time", len(dup), float(tt[dup[0]]),
                      f"time: {len(dup)} sample(s) repeat the previous timestamp (first at {where(idx[dup[0]])}, "
                      f"t={_g(tt[dup[0]])} s); {differ} of them with different values",
                      "dropped later duplicate")
            dropped["duplicate_time"] = len(dup)
            keep = np.ones(len(tt), bool)
            keep[dup] = False
            newpos = np.cumsum(keep) - 1
            forced = {int(newpos[p]) if keep[p] else int(newpos[p]) + 1 for p in forced}
            idx = idx[keep]
    return idx, dropped, forced


def _segments(ctx: _Ctx, t: np.ndarray, forced: set[int]) -> tuple[list[tuple[int, int]], dict]:
    n = len(t)
    if n < 2:
        return ([(0, n)] if n else []), {}
    dt = np.diff(t)
    med = float(np.median(dt))
    p99 = float(np.percentile(dt, 99))
    irregular = p99 > 3 * med
    thr = ctx.lim["gap_factor"] * med
    if irregular:
        thr = max(thr, 2 * p99)
    sampling = {"dt_median": med, "dt_p99": p99, "dt_max": float(dt.max()), "irregular": bool(irregular),
                "gap_threshold": thr, "rate_hz": 1.0 / med if med > 0 else float("nan")}
    if irregular:
        ctx.notes.append(f"irregular sampling: median period {_g(med * 1e3)} ms, 99th percentile "
                         f"{_g(p99 * 1e3)} ms; gap threshold raised to {_g(thr * 1e3)} ms; use actual time "
                         f"stamps for derivatives")
    gaps = np.flatnonzero(dt > thr)
    if len(gaps):
        longest = int(gaps[np.argmax(dt[gaps])])
        ctx.issue("gap", "time", len(gaps), float(t[gaps[0]]),
                  f"time: {len(gaps)} gap(s) longer than {_g(thr)} s ({_g(ctx.lim['gap_factor'])} x median "
                  f"period {_g(med)} s{', jitter-adjusted' if irregular else ''}): first at t={_g(t[gaps[0]])} s, "
                  f"longest {_g(dt[longest])} s at t={_g(t[longest])} s, {_g(float(dt[gaps].sum()))} s in total",
                  "segment split")
    cuts = sorted({0, n} | {int(g) + 1 for g in gaps} | {p for p in forced if 0 < p < n})
    return [(a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a], sampling


def _clock(ctx: _Ctx, t: np.ndarray, ch: dict, segments) -> tuple[np.ndarray, "clock.ClockCheck"]:
    """Which clock the samples follow (:mod:`.clock`): stamps that scatter around a uniform clock the samples follow
    are replaced by it; stamps the samples follow are kept; samples whose instants scatter around the time column
    kept are reported with the size of the scatter. Every case is a ``clock_jitter`` issue."""
    cc = clock.check(t, ch, segments)
    T = cc.period_s
    t0 = float(t[0]) if len(t) else None

    def ms(x: float) -> str:
        return f"{_g(1e3 * x)} ms ({_g(100 * x / T)} % of the {_g(1e3 * T)} ms period)"

    def sc(s) -> str:
        return "not measured" if s is None else f"{_g(1e3 * s.sigma_s)} ± {_g(1e3 * s.sd_s)} ms"

    if cc.irregular_stamps:
        head = f"time: the stamps scatter {ms(cc.stamp_scatter_s)} around the uniform clock their moving average makes"
        how = (f"; the {cc.channel} places the samples' instants {sc(cc.on_stamps)} around the stamps and "
               f"{sc(cc.on_uniform)} around the uniform clock (its 4-point interpolation residual against its "
               f"derivative squared)") if cc.channel else ""
        if cc.follows == "uniform":
            ctx.issue("clock_jitter", "time", len(t), t0,
                      f"{head}, and the samples follow that clock (a logger that stamps a sample when it receives "
                      f"it){how}", "time column replaced by the uniform clock (the stamps kept in "
                      "meta['recorded_time']); derivatives taken on it")
        elif cc.follows == "stamps":
            ctx.issue("clock_jitter", "time", len(t), t0,
                      f"{head}, and the samples follow the stamps (each taken when stamped){how}",
                      "none: the recorded time axis is kept; derivatives taken on it (filters treat the samples "
                      "as evenly spaced)")
        else:
            why = "no angle recorded" if cc.channel is None else "the motion cannot tell"
            ctx.issue("clock_jitter", "time", len(t), t0,
                      f"{head}; whether the samples follow the stamps or that clock is undecided ({why}){how}",
                      "none: the recorded time axis is kept")
    s = cc.instant_scatter
    if cc.instant_scatter_s > 0:
        axis = "the uniform clock the time column was replaced by" if cc.follows == "uniform" else "their stamps"
        ctx.issue("clock_jitter", "time", s.samples, t0,
                  f"time: the samples were taken at instants that scatter {ms(s.sigma_s)} ± {_g(1e3 * s.sd_s)} ms "
                  f"around {axis} (the {cc.channel}'s 4-point interpolation residual grows with its derivative "
                  f"squared, z = {_g(s.z)}; the white part: a slowly wandering clock does not show): speed and "
                  f"acceleration from the samples carry noise in proportion to the speed",
                  "none: the instants cannot be recovered from the log; the equation error counts that noise "
                  "in the acceleration")
    return cc.time, cc


# ====================================================================================== helpers / checks

def _mask(ctx: _Ctx, ch: dict, name: str, bad: np.ndarray, reason: str) -> None:
    idx = np.flatnonzero(bad)
    if not len(idx):
        return
    rec = ctx.masked.setdefault(name, {"index": [], "value": [], "reason": []})
    rec["index"].extend(idx.tolist())
    rec["value"].extend(ch[name][idx].tolist())
    rec["reason"].extend([reason] * len(idx))
    ch[name][idx] = np.nan


def _robust_range(x: np.ndarray) -> float:
    if len(x) < 2:
        return 0.0
    lo, hi = np.percentile(x, [1, 99])
    return float(hi - lo)


def _diff_sigma(x: np.ndarray, segments) -> float:
    """Noise scale from first differences within segments (1.4826 MAD / sqrt 2)."""
    d = np.concatenate([np.diff(x[a:b]) for a, b in segments if b - a > 1] or [np.array([])])
    d = d[np.isfinite(d)]
    if len(d) < 3:
        return 0.0
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2))


def _run_explained_by_position(t: np.ndarray, ch: dict, name: str, i0: int, i1: int, value: float) -> bool:
    """Does the position explain a run of one repeated ``value`` of channel ``name`` from sample ``i0`` to ``i1``?
    A speed channel: the position moved by ``value`` x the run's duration (within 5 % and the position's own noise:
    at rest, 0 rad/s while the angle stands still). A current or torque at exactly 0 while the angle stands still:
    an idle or disabled drive. Without a position channel nothing is explained."""
    pos = ch.get("position")
    if pos is None or name not in ("velocity",) + CURRENTS + TORQUES:
        return False
    if name != "velocity" and value != 0.0:
        return False
    seg = np.flatnonzero(np.isfinite(pos[i0:i1 + 1])) + i0
    if len(seg) < 2:
        return False
    x = pos[seg]
    d2 = np.diff(x, 2)
    noise = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0) if len(d2) >= 3 else 0.0
    steps = np.abs(np.diff(x))
    quantum = float(steps[steps > 0].min()) if (steps > 0).any() else 0.0
    duration = float(t[seg[-1]] - t[seg[0]])
    speed = value if name == "velocity" else 0.0
    moved = float(x[-1] - x[0])
    return abs(moved - speed * duration) <= 0.05 * abs(speed) * duration + max(5.0 * noise, 3.0 * quantum)


def _no_load_speed(params, bus: float) -> float | None:
    try:
        from ... import frames

        return float(frames.no_load_speed_max(bus, params.motor.torque_constant_q, params.motor.winding))
    except Exception:  # noqa: BLE001
        return None


def _bounds(ctx: _Ctx, name: str, ch: dict) -> tuple[tuple[float, float], str] | None:
    if name in ctx.bounds_override:
        return ctx.bounds_override[name], "given limit"
    if name in TEMPERATURES:
        return (-40.0, 250.0), "physical range"
    p = ctx.params
    if p is not None:
        ilim = ctx.lim["current_factor"] * p.drive.current_limit
        if name in CURRENTS:
            return (-ilim, ilim), f"{_g(ctx.lim['current_factor'])} x drive.current_limit"
        bus = p.drive.bus_voltage
        if "bus_voltage" in ch and np.isfinite(ch["bus_voltage"]).any():
            bus = max(bus, float(np.nanmax(ch["bus_voltage"])))
        if name == "bus_voltage":
            return (0.0, 3.0 * p.drive.bus_voltage), "3 x drive.bus_voltage"
        if name in VOLTAGES:
            return (-2.0 * bus, 2.0 * bus), "2 x bus voltage"
        if name == "velocity":
            w = _no_load_speed(p, bus)
            if w:
                s = ctx.lim["speed_factor"] * w
                return (-s, s), f"{_g(ctx.lim['speed_factor'])} x no-load speed at {_g(bus)} V"
        if name in TORQUES:
            tau = ctx.lim["torque_factor"] * p.motor.torque_constant_q * p.drive.current_limit * p.gear.gear_ratio
            return (-tau, tau), f"{_g(ctx.lim['torque_factor'])} x K_t_q x current_limit x gear ratio"
    if name in GENERIC_BOUNDS:
        return GENERIC_BOUNDS[name], "generic sanity bound (no parameters given)"
    return None


def _where_minmax(t, x, bad) -> str:
    i = np.flatnonzero(bad)
    v = x[i]
    lo, hi = int(i[np.argmin(v)]), int(i[np.argmax(v)])
    parts = [f"min {_g(x[lo])} at t={_g(t[lo])} s"]
    if hi != lo:
        parts.append(f"max {_g(x[hi])} at t={_g(t[hi])} s")
    return ", ".join(parts)


def _window_median(w: np.ndarray) -> np.ndarray:
    """``np.nanmedian(w, axis=1)`` (NaN where a row has no finite value): rows without a NaN by ``np.median``
    (the same value, several times faster than numpy's masked-array route for NaN-holding input)."""
    import warnings

    full = np.isfinite(w).all(axis=1)
    out = np.empty(len(w))
    out[full] = np.median(w[full], axis=1)
    if not full.all():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out[~full] = np.nanmedian(w[~full], axis=1)
    return out


def _hampel(x: np.ndarray, k: int, sigma: float, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """Isolated spikes of a segment (bool mask) and each sample's distance from its window median."""
    n = len(x)
    if n < 2 * k + 1:
        return np.zeros(n, bool), np.zeros(n)
    pad = np.concatenate([np.full(k, np.nan), x, np.full(k, np.nan)])
    from numpy.lib.stride_tricks import sliding_window_view

    w = sliding_window_view(pad, 2 * k + 1)
    med = _window_median(w)
    mad = 1.4826 * _window_median(np.abs(w - med[:, None]))
    left = _window_median(w[:, :k])
    right = _window_median(w[:, k + 1:])
    scale = np.maximum(mad, 0.0)
    dev = np.abs(x - med)
    thr = np.maximum(sigma * scale, floor)
    el, er = np.abs(x - left), np.abs(x - right)
    returns = np.abs(left - right) < 0.5 * np.minimum(el, er)
    # both sides need support: next to masked stretches the window says nothing
    support = (np.isfinite(w[:, :k]).sum(axis=1) >= 2) & (np.isfinite(w[:, k + 1:]).sum(axis=1) >= 2)
    spike = (dev > thr) & (el > thr) & (er > thr) & returns & support
    return spike & np.isfinite(x), np.where(np.isfinite(dev), dev, 0.0)


def _ratio(a: np.ndarray, b: np.ndarray) -> tuple[float, float] | None:
    """Least-squares slope a ~ r b through the origin and the correlation, on finite pairs."""
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 10:
        return None
    a, b = a[ok], b[ok]
    bb = float(np.dot(b, b))
    if bb == 0 or np.std(a) == 0 or np.std(b) == 0:
        return None
    return float(np.dot(a, b) / bb), float(np.corrcoef(a, b)[0, 1])


def _factor_table(params) -> list[tuple[float, str, str]]:
    """(ratio of position increments to integrated velocity, explanation, suggested fix)."""
    d2r = math.pi / 180
    rows = [(-1.0, "position and velocity have opposite signs", "negate one of them (--map velocity=-COL)"),
            (1 / d2r, "position looks like degrees", "--map position=COL*0.0174533"),
            (d2r, "velocity looks like deg/s", "--map velocity=COL*0.0174533"),
            (2 * math.pi / 60, "velocity looks like rpm", "--map velocity=COL*0.10472"),
            (1 / (2 * math.pi), "position looks like revolutions", "--map position=COL*6.28319"),
            (2 * math.pi, "velocity looks like rev/s", "--map velocity=COL*6.28319")]
    if params is not None:
        n, p = params.gear.gear_ratio, params.motor.pole_pairs
        if n != 1:
            rows += [(n, f"velocity looks like output side (x gear ratio {_g(n)})", f"--map velocity=COL*{_g(n)}"),
                     (1 / n, f"position looks like output side (x gear ratio {_g(n)})", f"--map position=COL*{_g(n)}")]
        rows += [(p, f"position looks electrical (x pole pairs {p})", f"--map position=COL/{p}"),
                 (1 / p, f"velocity looks electrical (x pole pairs {p})", f"--map velocity=COL/{p}"),
                 (2 * math.pi / 60 / p, "velocity looks like ERPM", f"--map velocity=COL*{_g(2 * math.pi / 60 / p)}")]
    rows += [(-r, f"{txt}, and the signs differ", fix) for r, txt, fix in rows[1:]]
    return rows


# ============================================================================================== checks

def _unwrap_position(ctx: _Ctx, t, ch, segments) -> None:
    x = ch.get("position")
    if x is None:
        return
    jumps_all, periods = [], []
    for a, b in segments:
        seg = x[a:b]
        ok = np.flatnonzero(np.isfinite(seg))
        if len(ok) < 3:
            continue
        d = np.diff(seg[ok])
        base = float(np.median(np.abs(d))) if len(d) else 0.0
        cand = np.flatnonzero(np.abs(d) > max(50 * base, 1.0))
        if "velocity" in ch:
            v = ch["velocity"][a:b][ok]
            dtt = np.diff(t[a:b][ok])
            expect = 0.5 * (v[:-1] + v[1:]) * dtt
            cand = cand[~(np.abs(d[cand] - expect[cand]) < 0.5 * np.abs(d[cand]))]
        if not len(cand):
            continue
        # the jump minus the ordinary step that happened with it: the mean of the neighbouring steps (the channel's
        # own local motion; a wrapped angle moving ~1 rad per sample jumps by 2 pi - 1, not by 2 pi - the median)
        ordinary = np.ones(len(d), bool)
        ordinary[cand] = False
        prev_i, next_i = np.clip(cand - 1, 0, len(d) - 1), np.clip(cand + 1, 0, len(d) - 1)
        w_prev = ordinary[prev_i] & (cand > 0)
        w_next = ordinary[next_i] & (cand < len(d) - 1)
        cnt = w_prev.astype(float) + w_next
        step = np.where(cnt > 0, (np.where(w_prev, d[prev_i], 0.0) + np.where(w_next, d[next_i], 0.0))
                        / np.maximum(cnt, 1.0), 0.0)
        mags = np.abs(d[cand] - step)
        P = float(np.median(mags))
        if np.all(np.abs(mags - P) < 0.05 * P) and (np.nanmax(seg) - np.nanmin(seg)) <= 1.1 * P:
            jumps_all.append((a, ok, cand, d))
            periods.append(P)
    if not jumps_all:
        return
    P = float(np.median(periods))
    for known in (2 * math.pi, 360.0, 1.0, 4096.0, 16384.0, 65536.0):   # rad, deg, rev, encoder counts
        if abs(P / known - 1) < 0.02:
            P = known
            break
    n = 0
    first = None
    for a, ok, cand, d in jumps_all:
        corr = np.zeros(len(ok))
        corr[cand + 1] = -np.sign(d[cand]) * P
        x[a + ok] += np.cumsum(corr)
        n += len(cand)
        first = float(t[a + ok[cand[0] + 1]]) if first is None else first
    hint = ""
    if abs(P - 360) < 5:
        hint = "; a 360 period means degrees"
    elif abs(P - 2 * math.pi) < 0.05:
        hint = " (2 pi: radians)"
    ctx.issue("wrapped", "position", n, first,
              f"position: wraps around every {_g(P)} ({n} jump(s) of ~{_g(P)}{hint})",
              f"unwrapped (period {_g(P)})")


def _unit_suspects_self(ctx: _Ctx, t, ch) -> None:
    """Unit checks that look at one channel alone (temperatures, currents)."""
    p = ctx.params
    for name in TEMPERATURES:
        x = ch.get(name)
        if x is None or not np.isfinite(x).any():
            continue
        med = float(np.nanmedian(x))
        if 200.0 < med < 700.0:
            ctx.exempt.add(name)
            ctx.issue("unit_suspect", name, int(np.isfinite(x).sum()), float(t[np.flatnonzero(np.isfinite(x))[0]]),
                      f"{name}: median {_g(med)} looks like kelvin ({_g(med - 273.15)} degC); values kept as "
                      f"recorded", f"none; fix with --map {name}=COL-273.15")
    for name in CURRENTS:
        x = ch.get(name)
        if x is None or not np.isfinite(x).any():
            continue
        p99 = float(np.nanpercentile(np.abs(x), 99))
        ref = p.drive.current_limit if p is not None else 10.0
        if p99 > 100 * ref and p99 / 1000 < 20 * ref:
            ctx.exempt.add(name)
            ctx.issue("unit_suspect", name, int(np.isfinite(x).sum()), float(t[np.flatnonzero(np.isfinite(x))[0]]),
                      f"{name}: 99th percentile |value| {_g(p99)} is {_g(p99 / ref)} x "
                      f"{'drive.current_limit' if p is not None else 'a typical 10 A'}; looks like mA "
                      f"({_g(p99 / 1000)} A)", f"none; fix with --map {name}=COL*0.001")


def _unit_suspects_torque(ctx: _Ctx, t, ch) -> None:
    """Torque in N*mm? Judged from torque per ampere of (already cleaned) current, else magnitude."""
    p = ctx.params
    for name in TORQUES:
        x = ch.get(name)
        if x is None or not np.isfinite(x).any():
            continue
        p99 = float(np.nanpercentile(np.abs(x), 99))
        verdict = None
        cur = ch.get("current") if name != "torque_command" else ch.get("current_command", ch.get("current"))
        r = _ratio(x, cur) if cur is not None else None
        if p is not None:
            kt_out = p.motor.torque_constant_q * p.gear.gear_ratio
            if r is not None and abs(r[1]) > 0.5 and 200 < abs(r[0]) / kt_out < 5000:
                verdict = (f"{name}: {_g(abs(r[0]))} per A of current vs K_t_q x gear ratio = {_g(kt_out)} N*m/A "
                           f"({_g(abs(r[0]) / kt_out)} x); looks like N*mm")
            elif r is None:
                tau_max = kt_out * p.drive.current_limit
                if p99 > 100 * tau_max and p99 / 1000 < 10 * tau_max:
                    verdict = (f"{name}: 99th percentile |value| {_g(p99)} is {_g(p99 / tau_max)} x the "
                               f"actuator's torque at its current limit ({_g(tau_max)} N*m); looks like N*mm")
        elif r is not None and abs(r[1]) > 0.5 and abs(r[0]) > 200:
            verdict = f"{name}: {_g(abs(r[0]))} per A of current is implausible in N*m/A; looks like N*mm"
        elif p99 > 5000:
            verdict = f"{name}: 99th percentile |value| {_g(p99)} is implausible in N*m; looks like N*mm"
        if verdict:
            ctx.exempt.add(name)
            ctx.issue("unit_suspect", name, int(np.isfinite(x).sum()), float(t[np.flatnonzero(np.isfinite(x))[0]]),
                      verdict + "; values kept as recorded", f"none; fix with --map {name}=COL*0.001")


def _pv_ratio(ctx: _Ctx | None, t, ch, segments) -> tuple[float, str, int] | None:
    """Ratio of position increments to integrated velocity and how it was obtained (None: cannot tell)."""
    x, v = ch.get("position"), ch.get("velocity")
    if x is None or v is None:
        return None
    A, B = [], []
    for a, b in segments:
        n = b - a
        if n < 4:
            continue
        dur = t[b - 1] - t[a]
        w = max(3, int(round(n * min(0.5, dur / 4) / dur))) if dur > 0 else n
        for s in range(a, b - w, w):
            e = s + w
            xs, vs, ts = x[s:e + 1], v[s:e + 1], t[s:e + 1]
            if not (np.isfinite(xs[[0, -1]]).all() and np.isfinite(vs).all()):
                continue
            A.append(xs[-1] - xs[0])
            B.append(float(np.sum(0.5 * (vs[1:] + vs[:-1]) * np.diff(ts))))
    if len(A) < 5:
        return None
    A, B = np.asarray(A), np.asarray(B)
    moved = float(np.sum(np.abs(A)))
    if moved < 1.0 or np.sum(np.abs(B)) < 1e-12:
        return None
    if abs(B.sum()) > 0.5 * np.sum(np.abs(B)):
        return float(A.sum() / B.sum()), "net displacement / integrated velocity", len(A)
    rr = _ratio(A, B)
    if rr is None or abs(rr[1]) < 0.7:
        if rr is not None and ctx is not None:
            ctx.issue("unit_suspect", "position", len(A), None,
                      f"position increments and integrated velocity disagree (correlation {_g(rr[1])} over "
                      f"{len(A)} windows): different sides of a gear, a different time base, or a bad sensor",
                      "none")
        return None
    return rr[0], "least squares over windows", len(A)


#: clocks that are not seconds: (seconds per tick, name)
CLOCK_UNITS = ((1e-3, "milliseconds"), (1e-6, "microseconds"), (1e-9, "nanoseconds"))


def _time_unit(ctx: _Ctx, t, ch, segments) -> float:
    """A time column counting ms / us / ns, recognised from position increments = that factor x the velocity
    integrated over the column's values (the velocity being per second). Returns the factor to apply to t
    (1.0: seconds)."""
    got = _pv_ratio(None, t, ch, segments)
    if got is None:
        return 1.0
    r, how, _ = got
    for f, name in CLOCK_UNITS:
        if abs(abs(r) / f - 1) < 0.03:
            dt = float(np.median(np.diff(t))) if len(t) > 1 else float("nan")
            ctx.issue("unit_suspect", "time", len(t), float(t[0]) * f,
                      f"time: position increments are {_g(r)} x the velocity integrated over the time column "
                      f"({how}): the clock counts {name}, not seconds (read as seconds the rate would be "
                      f"{_g(1 / dt) if dt > 0 else 'nan'} Hz; it is {_g(1 / (dt * f)) if dt > 0 else 'nan'} Hz)",
                      f"time rescaled to seconds (x{f:g}); to override, map the time column yourself, e.g. "
                      f"--map time=COL*{f:g}")
            return f
    return 1.0


def _position_velocity(ctx: _Ctx, t, ch, segments) -> None:
    got = _pv_ratio(ctx, t, ch, segments)
    if got is None:
        return
    r, how, nwin = got
    ctx.notes.append(f"position/velocity consistency: ratio {_g(r)} ({how})")
    if abs(r - 1) < 0.1:
        return
    best = None
    for f, txt, fix in _factor_table(ctx.params):
        if abs(r / f - 1) < 0.07 and (best is None or abs(r / f - 1) < abs(r / best[0] - 1)):
            best = (f, txt, fix)
    if best is not None and best[0] == -1.0:
        ctx.issue("sign_convention", "velocity", nwin, None,
                  f"velocity: position increments are {_g(r)} x the integrated velocity; {best[1]}",
                  f"none; {best[2]}")
        return
    detail = (f"position increments are {_g(r)} x the integrated velocity ({how}); "
              + (best[1] if best else "no known unit or gear factor explains it"))
    ctx.issue("unit_suspect", "position", nwin, None, detail, f"none; {best[2]}" if best else "none")


def _signs(ctx: _Ctx, t, ch) -> None:
    pairs = [("torque", "current", "measured torque", "measured current"),
             ("current", "current_command", "measured current", "current command"),
             ("torque", "torque_command", "measured torque", "torque command")]
    # only where the drive's own current is valid (a masked current means the sample is garbage)
    valid = np.isfinite(ch["current"]) if "current" in ch else np.ones(len(t), bool)
    for a, b, ta, tb in pairs:
        if a in ch and b in ch and a not in ctx.exempt:
            r = _ratio(np.where(valid, ch[a], np.nan), ch[b])
            if r is not None and r[1] < -0.5:
                ctx.issue("sign_convention", a, int(np.sum(np.isfinite(ch[a]) & np.isfinite(ch[b]))), None,
                          f"{a}: {ta} is anti-correlated with the {tb} (correlation {_g(r[1])}); the sign "
                          f"conventions probably differ", f"none; if so, fix with --map {a}=-COL")


def _limits_and_spikes(ctx: _Ctx, t, ch, segments, names) -> None:
    # physical limits
    for name in names:
        if name in ctx.exempt or name == "position":
            continue
        b = _bounds(ctx, name, ch)
        if b is None:
            continue
        (lo, hi), why = b
        x = ch[name]
        with np.errstate(invalid="ignore"):
            bad = np.isfinite(x) & ((x < lo) | (x > hi) | ((x <= 0) if name == "bus_voltage" and lo == 0 else False))
        if not bad.any():
            continue
        unit = CANONICAL[name][0]
        rng = f"±{_g(hi)}" if lo == -hi else f"{_g(lo)}..{_g(hi)}"
        detail = (f"{name}: {int(bad.sum())} sample(s) beyond {rng} {unit} physical limit ({why}) "
                  f"({_where_minmax(t, x, bad)})")
        if name in COMMAND_CHANNELS:
            ctx.issue("outlier", name, int(bad.sum()), float(t[np.flatnonzero(bad)[0]]), detail,
                      "none (commands are kept as sent)")
            continue
        ctx.issue("outlier", name, int(bad.sum()), float(t[np.flatnonzero(bad)[0]]), detail,
                  "masked (NaN), excluded from fits")
        _mask(ctx, ch, name, bad, f"beyond {rng} {unit}")

    # spikes
    k = int(ctx.lim["hampel_half_window"])
    sig = float(ctx.lim["spike_sigma"]) if ctx.lim["spike_sigma"] is not None else math.inf
    for name in names:
        if name in COMMAND_CHANNELS or not math.isfinite(sig):
            continue
        x = ch[name]
        fin = x[np.isfinite(x)]
        if len(fin) < 2 * k + 1:
            continue
        size = max(_robust_range(fin), float(np.percentile(np.abs(fin), 99)))
        steps = np.abs(np.diff(fin))
        steps = steps[steps > 1e-9 * max(size, 1e-300)]
        resolution = float(steps.min()) if len(steps) else 0.0      # quantisation step of the sensor
        floor = max(sig * _diff_sigma(x, segments), ctx.lim["spike_range_fraction"] * size, 4 * resolution, 1e-12)
        spikes = np.zeros(len(x), bool)
        dev = np.zeros(len(x))
        for a, b in segments:
            spikes[a:b], dev[a:b] = _hampel(x[a:b], k, sig, floor)
        if spikes.any():
            si = np.flatnonzero(spikes)
            worst = int(si[np.argmax(dev[si])])
            unit = CANONICAL[name][0]
            ctx.issue("outlier", name, len(si), float(t[si[0]]),
                      f"{name}: {len(si)} isolated spike(s) (> {_g(sig)} robust sigma and > {_g(floor)} {unit} from "
                      f"the {2 * k + 1}-sample median, returning to the same level; largest {_g(x[worst])} {unit} at "
                      f"t={_g(t[worst])} s; first at t={_g(t[si[0]])} s)", "masked (NaN), excluded from fits")
            _mask(ctx, ch, name, spikes, "spike")



def _supply_voltage(ctx: _Ctx, t, ch) -> None:
    """A supply (bus) voltage far below anything that drives a motor: a mis-mapped column or a per-unit value.
    Masked (it would set voltage limits) and reported."""
    x = ch.get("bus_voltage")
    if x is None or "bus_voltage" in ctx.bounds_override or not np.isfinite(x).any():
        return
    med = float(np.nanmedian(x))
    p = ctx.params
    ref, why = (0.2 * p.drive.bus_voltage, f"0.2 x drive.bus_voltage {_g(p.drive.bus_voltage)} V") if p is not None \
        else (3.0, "3 V (no parameters given)")
    if med >= ref:
        return
    fin = np.isfinite(x)
    ctx.issue("unit_suspect", "bus_voltage", int(fin.sum()), float(t[np.flatnonzero(fin)[0]]),
              f"bus_voltage: median {_g(med)} V is implausible for a supply voltage (below {why}): a mis-mapped "
              f"column, a per-unit / duty value or a different unit", "masked (NaN), excluded from fits; map the "
              "supply voltage column (--map bus_voltage=COL) or fix the input profile")
    ctx.exempt.add("bus_voltage")
    _mask(ctx, ch, "bus_voltage", fin, "implausible supply voltage")


def _current_vs_command(ctx: _Ctx, t, ch) -> None:
    """The measured current as a fixed multiple of its command that is not 1: a frame factor (amplitude- vs
    power-invariant, peak vs RMS) between what the drive reports and what it was sent?"""
    i, c = ch.get("current"), ch.get("current_command")
    if i is None or c is None:
        return
    r = _ratio(i, c)
    if r is None or r[1] < 0.9 or abs(r[0] - 1) < 0.03:
        return
    from ... import frames

    best = None
    for name, (f, _) in frames.torque_constant_frame_factors().items():
        if abs(r[0] / f - 1) < 0.02 and (best is None or abs(r[0] / f - 1) < abs(r[0] / best[0] - 1)):
            best = (f, name)
    n = int(np.sum(np.isfinite(i) & np.isfinite(c)))
    ctx.issue("unit_suspect", "current", n, None,
              f"current: the measured current is {_g(r[0])} x its command (correlation {_g(r[1])}); "
              + (f"that is the frame factor {best[1]} = {_g(best[0])}: the drive reports the current in another "
                 f"frame than it is commanded in" if best else "no frame factor explains it"),
              "none; " + (f"check which frame each column is in (--map current=COL*{_g(1 / r[0])} to read it in "
                          "the command's frame)" if best else "check the current scaling"))


# =============================================================================================== clean

def clean(raw: Signals, limits: dict | None = None, params=None) -> Signals:
    """Detect and report problems; mask impossible samples; return a new :class:`Signals` whose time is
    strictly increasing and split into gap-free segments. ``params`` (ActuatorParams) sets the physical
    limits; ``limits`` overrides them (see module docstring)."""
    # a recording may carry its own limits (its input profile's clean_limits)
    ctx = _Ctx(raw, {**raw.meta.get("clean_limits", {}), **(limits or {})}, params)
    n_in = len(raw.time)
    idx, dropped, forced = _clean_time(ctx, raw)
    # raw segment boundaries (loaders that concatenate) survive
    if len(raw.segments) > 1:
        pos_of = {int(r): k for k, r in enumerate(idx)}
        for a, _ in raw.segments[1:]:
            k = next((pos_of[j] for j in range(a, n_in) if j in pos_of), None)
            if k:
                forced.add(k)
    t = raw.time[idx].astype(float)
    ch = {k: np.array(v[idx], dtype=float) for k, v in raw.channels.items()}
    segments, sampling = _segments(ctx, t, forced)
    f_clock = _time_unit(ctx, t, ch, segments)
    if f_clock != 1.0:      # a ms / us clock: the gaps found above were measured in its ticks
        ctx.issues = [i for i in ctx.issues if not (i.kind == "gap" and i.channel == "time")]
        ctx.notes = [n for n in ctx.notes if not n.startswith("irregular sampling")]
        t = t * f_clock
        segments, sampling = _segments(ctx, t, forced)
        raw_meta_time_scale = f_clock
    else:
        raw_meta_time_scale = 1.0

    # NaN / inf / empty channels
    for name in list(ch):
        x = ch[name]
        inf = np.isinf(x)
        x[inf] = np.nan
        bad = ~np.isfinite(x)
        if bad.all():
            ctx.issue("missing_channel", name, len(x), None, f"{name}: no finite sample in {len(x)}",
                      "none; channel unusable")
            continue
        pre = int(raw.meta.get("premasked", {}).get(name, 0))  # masked and reported by the loader
        if bad.sum() > pre:
            first = int(np.flatnonzero(bad)[0])
            extra = f"; {pre} more were masked by the loader, see its issue" if pre else ""
            ctx.issue("nan", name, int(bad.sum()) - pre, float(t[first]),
                      f"{name}: {int(bad.sum()) - pre} sample(s) NaN, inf or empty ({int(inf.sum())} inf; first at "
                      f"t={_g(t[first])} s){extra}", "kept as NaN, excluded from fits")

    _unwrap_position(ctx, t, ch, segments)
    # unit checks that need only the channel itself, then limits and spikes for everything but the
    # torques; torque units are judged against the (by then clean) current; then the torques
    _unit_suspects_self(ctx, t, ch)
    first = sorted((c for c in ch if c not in TORQUES), key=lambda c: c != "bus_voltage")  # bus first: it sets limits
    _limits_and_spikes(ctx, t, ch, segments, first)
    t, clock_check = _clock(ctx, t, ch, segments)
    sampling["clock"] = clock_check.to_dict()
    _unit_suspects_torque(ctx, t, ch)
    _position_velocity(ctx, t, ch, segments)
    _signs(ctx, t, ch)
    _limits_and_spikes(ctx, t, ch, segments, [c for c in ch if c in TORQUES])

    _supply_voltage(ctx, t, ch)
    _current_vs_command(ctx, t, ch)

    # constant / stuck / clipped
    clipped: dict[str, dict] = {}
    rate = 1.0 / sampling["dt_median"] if sampling.get("dt_median") else float("nan")
    for name in list(ch):
        x = ch[name]
        fin_idx = np.flatnonzero(np.isfinite(x))
        if len(fin_idx) < 10:
            continue
        fin = x[fin_idx]
        if np.all(fin == fin[0]):
            what = ("no excitation from the command (a hold / step-free test)" if name in COMMAND_CHANNELS
                    else "the channel carries no information about dynamics")
            ctx.issue("constant", name, len(fin), float(t[fin_idx[0]]),
                      f"{name}: all {len(fin)} finite samples equal {_g(fin[0])} {CANONICAL[name][0]}",
                      f"none; {what}")
            continue
        if name in COMMAND_CHANNELS:
            continue
        d = np.diff(fin)
        need = max(int(ctx.lim["stuck_samples"]), int(ctx.lim["stuck_seconds"] * rate) if np.isfinite(rate) else 0)
        change = np.flatnonzero(d != 0)
        starts = np.concatenate([[0], change + 1])
        ends = np.concatenate([change + 1, [len(fin)]])
        lens = ends - starts
        # runs the position explains (the actuator at rest, a speed held exactly) are no stuck sensor, and they do
        # not make a channel that changes every sample while it moves look like a slow one
        moving = np.ones(len(fin), bool)
        explained = np.zeros(len(starts), bool)
        if name != "position":
            for k in np.flatnonzero(lens >= need):
                if _run_explained_by_position(t, ch, name, fin_idx[starts[k]], fin_idx[ends[k] - 1], fin[starts[k]]):
                    explained[k] = True
                    moving[starts[k]:ends[k]] = False
        d_moving = np.diff(fin[moving]) if moving.sum() > 1 else d
        if name != "position" and len(d_moving) and np.median(np.abs(d_moving)) > 0:
            long = np.flatnonzero((lens >= need) & ~explained)
            if len(long):
                total = int(lens[long].sum())
                L = int(long[np.argmax(lens[long])])
                ctx.issue("constant", name, total, float(t[fin_idx[starts[long[0]]]]),
                          f"{name}: stuck at one value for {len(long)} run(s) of >= {need} samples ({total} samples; "
                          f"longest {int(lens[L])} samples = {_g(t[fin_idx[ends[L] - 1]] - t[fin_idx[starts[L]]])} s "
                          f"at {_g(fin[starts[L]])} {CANONICAL[name][0]})", "none (flagged)")
        # a current or torque held at a limit most of the time has median |step| 0: checked too (a supply voltage
        # resting on its set-point is not clipping)
        if name != "position" and (np.median(np.abs(d)) > 0 or name in CURRENTS + TORQUES):
            big = float(np.max(np.abs(fin)))
            uniq, counts = np.unique(fin, return_counts=True)
            typical = float(np.median(counts))
            for side, val in (("max", fin.max()), ("min", fin.min())):
                if name == "position" or abs(val) < 0.05 * big or len(uniq) < 20:
                    continue                        # a rest value (0 A, 0 rad/s, a parked angle) or a coarse
                at = fin == val                     # sensor with few levels is no clipping
                # a limit is reached: the run the recording starts in is its initial state (a temperature at
                # ambient until the heating shows), not a limiter, and is not counted; coming back to it later is
                at[: int(np.argmin(at)) if at[0] else 0] = False
                cnt = int(at.sum())
                if cnt >= max(10, int(0.01 * len(fin)), 10 * typical):
                    ctx.issue("clipped", name, cnt, float(t[fin_idx[np.flatnonzero(at)[0]]]),
                              f"{name}: {cnt} samples ({_g(100 * cnt / len(fin))} %) sit exactly at the {side} "
                              f"{_g(val)} {CANONICAL[name][0]}: saturated sensor or limiter?", "none (flagged)")
                    rec = clipped.setdefault(name, {"levels": [], "count": 0, "finite": int(len(fin))})
                    rec["levels"].append(float(val))
                    rec["count"] += cnt
    for name, rec in clipped.items():
        rec["fraction"] = rec["count"] / max(rec["finite"], 1)
        if name == "current":
            ctx.notes.append(f"current sits at {', '.join(_g(v) for v in rec['levels'])} A in "
                             f"{_g(100 * rec['fraction'])} % of the samples (a drive's current limit): those samples "
                             f"are left out of current-proportional fits")

    # accounting and meta
    meta = dict(raw.meta)
    aux = {}
    for key, val in raw.meta.get("aux", {}).items():
        aux[key] = val[idx] if isinstance(val, np.ndarray) and val.shape[:1] == (n_in,) else val
    meta["aux"] = aux
    if isinstance(raw.meta.get("line_numbers"), np.ndarray) and len(raw.meta["line_numbers"]) == n_in:
        meta["line_numbers"] = raw.meta["line_numbers"][idx]
    masked_counts = {k: len(v["index"]) for k, v in ctx.masked.items()}
    meta["accounting"] = {"rows_in": n_in, "rows_out": len(t), "dropped": dropped, "masked": masked_counts}
    assert n_in == len(t) + sum(dropped.values()), "row accounting does not balance"
    meta["masked"] = {k: {"index": np.asarray(v["index"]), "value": np.asarray(v["value"]), "reason": v["reason"]}
                      for k, v in ctx.masked.items()}
    meta["sampling"] = sampling
    if clock_check.follows == "uniform":
        meta["recorded_time"] = raw.time[idx].astype(float) * raw_meta_time_scale
    meta["rate_hz"] = sampling.get("rate_hz", float("nan"))
    meta["notes"] = ctx.notes
    meta["cleaned"] = True
    if raw_meta_time_scale != 1.0:
        meta["time_scale"] = raw_meta_time_scale
    meta["clipped"] = clipped
    meta["unit_suspects"] = sorted(ctx.exempt)
    _profile_fix_hints(ctx.issues, raw.meta)
    return Signals(t, ch, raw.source, ctx.issues, segments, meta)


_FIX_CHANNEL = re.compile(r"--map (\w+)=")


def _profile_fix_hints(issues: list[DataIssue], meta: dict) -> None:
    """A recording read through an input profile is fixed in the profile, not with --map: say which field."""
    name = meta.get("profile")
    if not name:
        return
    where = meta.get("profile_path") or name
    for i in issues:
        if i.kind not in ("unit_suspect", "sign_convention") or "--map" not in i.action:
            continue
        m = _FIX_CHANNEL.search(i.action)
        ch = m.group(1) if m else i.channel
        i.action += (f"; this file was read by input profile {name}: fix its columns.{ch} / units.{ch} / "
                     f"side.{ch} ({where}) or pass --map {ch}=... to override")
