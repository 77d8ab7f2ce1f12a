"""Which clock a recording's samples follow: its time column, or a uniform clock its stamps scatter around.

A logger's clock is often not the sampler's. The stamps may be exact for samples taken at scattered instants (a
logger that stamps each sample when it takes it), or scatter around samples taken on a uniform clock (a logger that
stamps a sample when it RECEIVES it), or be a uniform count k T for samples whose instants scatter (a logger that
counts samples). The derivatives the diagnosis takes (speed, acceleration) need the instants the samples were taken
at: a stamp scatter of 20 % of the period turns the angle's second difference into noise proportional to the speed
(an inertia error of 1.4 x at 500 Hz hidden behind a false resistance and a structured residual).

The motion tells. The angle (a smooth channel) sampled at instants ``s_k`` and placed on an axis
``a_k`` misses the cubic through its four neighbours (k-2, k-1, k+1, k+2, Lagrange on the axis) by
``x'(t_k) (s_k - a_k - <the stencil's mix of the neighbours' offsets>)`` plus the curve's own 4th-order term and the
sensor's noise: its square grows with ``x'^2`` by ``G sigma^2`` (``G`` = 1 + 34/36, the stencil's gain for white
offsets of s.d. ``sigma``). The regression of the squared residual on the squared derivative measures ``sigma``, the
scatter of the instants around that axis (its white part; a clock that wanders slowly is invisible and harmless).
:func:`check` measures it on the stamps and on the uniform clock fitted through them (their moving average),
and the samples follow the axis around which they scatter least."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: a stamp scatter (s.d. around the fitted uniform clock, share of the period) below this is a regular clock
STAMP_SCATTER_MIN = 0.02
#: the instants' scatter around the chosen axis is reported from this share of the period on ...
INSTANT_SCATTER_MIN = 0.02
#: ... when its squared-residual slope stands this many standard errors above zero (a real angle's residual is
#: heavy-tailed: quantization patterns, an encoder's lag that moves with the speed; the project's real logs with
#: uniform stamps reach z = 4-8, generated 10 s logs with 5 % of a period of white scatter z = 19)
SIGNIFICANCE_Z = 10.0
#: the samples follow the uniform clock when their scatter around it is below this share of their scatter around
#: the stamps (and that scatter is significant)
PREFER_RATIO = 0.5
#: gain of the 4-point Lagrange stencil for white instant offsets: 1 + (1 + 16 + 16 + 1) / 36
STENCIL_GAIN = 1.0 + 34.0 / 36.0


@dataclass(frozen=True)
class Scatter:
    """The instants' scatter around one axis: ``sigma_s`` [s] (0 when not resolved), its standard error, and the
    z value of the squared residual's slope on the squared derivative."""

    sigma_s: float
    sd_s: float
    z: float
    samples: int

    @property
    def significant(self) -> bool:
        return self.z > SIGNIFICANCE_Z


@dataclass(frozen=True)
class ClockCheck:
    """What :func:`check` found. ``follows``: "stamps" (the time column is kept), "uniform" (the samples follow the
    uniform clock fitted through the stamps: ``time`` is that clock) or "undecided" (the motion cannot tell: the
    stamps are kept). ``stamp_scatter_s``: s.d. of the stamps around that uniform clock; ``on_stamps`` and
    ``on_uniform``: the instants' scatter around each axis (None where not measured); ``instant_scatter``: around
    the axis kept; ``channel``: the channel the motion was read from (None: no motion channel)."""

    period_s: float
    stamp_scatter_s: float
    follows: str
    channel: str | None
    on_stamps: Scatter | None
    on_uniform: Scatter | None
    time: np.ndarray

    @property
    def irregular_stamps(self) -> bool:
        return self.stamp_scatter_s > STAMP_SCATTER_MIN * self.period_s

    @property
    def instant_scatter(self) -> Scatter | None:
        return self.on_uniform if self.follows == "uniform" else self.on_stamps

    @property
    def instant_scatter_s(self) -> float:
        """[s] the instants' scatter around the time axis kept, where it is resolved and reported (else 0)."""
        s = self.instant_scatter
        return s.sigma_s if s is not None and s.significant and s.sigma_s > INSTANT_SCATTER_MIN * self.period_s \
            else 0.0

    def to_dict(self) -> dict:
        def sc(s):
            return None if s is None else {"sigma_s": s.sigma_s, "sd_s": s.sd_s, "z": s.z, "samples": s.samples}
        return {"period_s": self.period_s, "stamp_scatter_s": self.stamp_scatter_s, "follows": self.follows,
                "channel": self.channel, "on_stamps": sc(self.on_stamps), "on_uniform": sc(self.on_uniform),
                "instant_scatter_s": self.instant_scatter_s}


#: [samples] the moving average that makes the uniform clock from the stamps: it follows a logger whose rate drifts
#: or pauses, and averages a white scatter down by its square root
CLOCK_WINDOW = 25


def uniform_clock(t: np.ndarray, segments) -> np.ndarray:
    """[s] the clock the stamps scatter around: per segment, their moving average over :data:`CLOCK_WINDOW` samples
    (odd reflection at the ends keeps the local rate; a straight line on segments too short for it)."""
    out = np.array(t, dtype=float)
    h = CLOCK_WINDOW // 2
    for a, b in segments:
        if b - a > 2 * h + 1:
            x = t[a:b]
            pad = np.concatenate([2 * x[0] - x[h:0:-1], x, 2 * x[-1] - x[-2:-h - 2:-1]])
            out[a:b] = np.convolve(pad, np.ones(2 * h + 1) / (2 * h + 1), mode="valid")
        elif b - a >= 3:
            k = np.arange(b - a, dtype=float)
            slope, icpt = np.polyfit(k, t[a:b], 1)
            out[a:b] = icpt + slope * k
    return out


def _four_point_residual(x: np.ndarray, ax: np.ndarray) -> np.ndarray:
    """x_k minus the cubic through x_{k-2}, x_{k-1}, x_{k+1}, x_{k+2} on the axis, at ax_k (NaN at the ends)."""
    r = np.full(len(x), np.nan)
    if len(x) < 5:
        return r
    at = ax[2:-2]
    nodes = [(ax[:-4], x[:-4]), (ax[1:-3], x[1:-3]), (ax[3:-1], x[3:-1]), (ax[4:], x[4:])]
    pred = np.zeros(len(at))
    with np.errstate(divide="ignore", invalid="ignore"):
        for i, (ti, yi) in enumerate(nodes):
            w = np.ones(len(at))
            for j, (tj, _) in enumerate(nodes):
                if j != i:
                    w = w * (at - tj) / (ti - tj)
            pred = pred + w * yi
    r[2:-2] = x[2:-2] - pred
    return r


def scatter(x: np.ndarray, ax: np.ndarray, segments) -> Scatter:
    """The instants' scatter around the axis ``ax`` from the channel ``x`` (NaN-free runs of each segment)."""
    rr, dd = [], []
    for a, b in segments:
        if b - a < 8:
            continue
        xs, ts = x[a:b], ax[a:b]
        r = _four_point_residual(xs, ts)
        with np.errstate(invalid="ignore", divide="ignore"):   # the slope over +-3 samples: little of the
            d = np.full(len(xs), np.nan)                        # sensor noise the residual holds
            d[3:-3] = (xs[6:] - xs[:-6]) / (ts[6:] - ts[:-6])
        ok = np.isfinite(r) & np.isfinite(d)
        rr.append(r[ok])
        dd.append(d[ok])
    if not rr or sum(len(r) for r in rr) < 50:
        return Scatter(0.0, math.inf, 0.0, 0)
    r2, d2 = np.concatenate(rr) ** 2, np.concatenate(dd) ** 2
    X = np.column_stack([np.ones_like(d2), d2])
    try:
        XtX_inv = np.linalg.inv(X.T @ X)
    except np.linalg.LinAlgError:
        return Scatter(0.0, math.inf, 0.0, len(r2))
    c = XtX_inv @ (X.T @ r2)
    res = r2 - X @ c
    cov = XtX_inv @ ((X.T * res ** 2) @ X) @ XtX_inv   # heteroscedasticity-consistent
    se = math.sqrt(max(float(cov[1, 1]), 0.0))
    z = float(c[1]) / se if se > 0 else 0.0
    sigma = math.sqrt(max(float(c[1]), 0.0) / STENCIL_GAIN)
    sd = se / (2.0 * STENCIL_GAIN * sigma) if sigma > 0 else math.sqrt(se / STENCIL_GAIN)
    return Scatter(sigma, sd, z, len(r2))


def check(t: np.ndarray, channels: dict[str, np.ndarray], segments) -> ClockCheck:
    """Measure the stamps' scatter and decide which clock the samples follow (module docstring). ``channels``:
    canonical name -> samples (the angle unwrapped); the angle is read (without it the clock is undecided)."""
    t = np.asarray(t, dtype=float)
    segs = [(int(a), int(b)) for a, b in segments if b - a >= 3]
    dts = np.concatenate([np.diff(t[a:b]) for a, b in segs]) if segs else np.array([1.0])
    period = float(np.median(dts)) if len(dts) else 1.0
    lin = uniform_clock(t, segs)
    # the stamps' white scatter from their periods (robust: a pause or a drift of the rate does not count)
    stamp_scatter = 1.4826 * float(np.median(np.abs(dts - period))) / math.sqrt(2.0) if len(dts) else 0.0
    # the angle (a speed channel's own noise reaches its slope and its residual alike: no measure of the instants)
    name = "position" if "position" in channels and np.isfinite(np.asarray(channels["position"], float)).sum() >= 50 \
        else None
    if name is None:
        return ClockCheck(period, stamp_scatter, "undecided" if stamp_scatter > STAMP_SCATTER_MIN * period
                          else "stamps", None, None, None, t)
    x = np.asarray(channels[name], dtype=float)
    on_st = scatter(x, t, segs)
    if not stamp_scatter > STAMP_SCATTER_MIN * period:
        return ClockCheck(period, stamp_scatter, "stamps", name, on_st, None, t)
    on_un = scatter(x, lin, segs)
    if on_st.significant and on_un.sigma_s < PREFER_RATIO * on_st.sigma_s:
        return ClockCheck(period, stamp_scatter, "uniform", name, on_st, on_un, lin)
    if on_un.significant and on_st.sigma_s < PREFER_RATIO * on_un.sigma_s:
        return ClockCheck(period, stamp_scatter, "stamps", name, on_st, on_un, t)
    return ClockCheck(period, stamp_scatter, "undecided", name, on_st, on_un, t)
