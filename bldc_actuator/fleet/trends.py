"""The SHIFT test (one of the three alert kinds of :mod:`.alerts`): a tracked parameter whose recent values
left that actuator's own baseline, for series of >= 8 recordings.

Test, per (actuator, parameter) series of tracked values ordered by start time (status ``ok`` only):

* baseline = the first ``max(min_baseline, n/3)`` recordings, recent = the last ``max(min_recent, n/3)``
  (they do not overlap; series shorter than ``min_baseline + min_recent`` are not tested);
* scatter ``s = sqrt(s_d^2 + u_med^2)`` with ``s_d = 1.4826 * MAD(diff(values)) / sqrt(2)``: the actuator's
  own recording-to-recording scatter from the differences of consecutive values of the WHOLE series (a
  drift only shifts their median, a step spoils one of them; n - 1 differences estimate the scatter far
  better than a MAD of the few baseline points), and ``u_med`` the median per-recording fit uncertainty
  (so a series whose values happen to agree better than the fits can tell is not over-trusted);
* robust z-score of the shift of the median: ``z = (median(recent) - median(baseline)) /
  (s * sqrt(pi/2) * sqrt(1/n_b + 1/n_r))`` (sqrt(pi/2): efficiency of the median under Gaussian scatter);
* alert when ``|z| > z_crit(n, n_b, n_r, alpha)`` AND ``|relative change| >= min_change``. ``z_crit`` is
  calibrated by Monte Carlo of this very statistic on i.i.d. Gaussian series of the same lengths
  (:func:`critical_z`, 20 000 draws, fixed seed) so that the FALSE-ALARM RATE per series is ``alpha``
  (default 0.001) when the actuator is stable (the heavy tails of a scatter estimated from few points
  are thereby accounted for);
* each alert also gives the Theil-Sen slope over the whole series (per 30 days, with its 95 % interval,
  ``scipy.stats.theilslopes``) to tell a drift from a step.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any

import numpy as np

DEFAULT_ALPHA = 1e-3
MIN_BASELINE = 5
MIN_RECENT = 3


def _mad_sigma(x: np.ndarray) -> float:
    return 1.4826 * float(np.median(np.abs(x - np.median(x)))) if len(x) else float("nan")


def scatter(values: np.ndarray) -> float:
    """Recording-to-recording scatter from consecutive differences (robust to drifts and steps)."""
    d = np.diff(values)
    return _mad_sigma(d) / math.sqrt(2.0) if len(d) else float("nan")


def statistic(values: np.ndarray, n_base: int, n_recent: int, u_med: float = 0.0) -> float:
    """The robust z-score of the module docstring for time-ordered ``values``."""
    base, recent = values[:n_base], values[len(values) - n_recent:]
    s = math.hypot(scatter(values), u_med if math.isfinite(u_med) else 0.0)
    d = float(np.median(recent) - np.median(base))
    se = s * math.sqrt(math.pi / 2.0) * math.sqrt(1.0 / len(base) + 1.0 / len(recent))
    if se <= 0:
        return 0.0 if d == 0 else math.copysign(math.inf, d)
    return d / se


@lru_cache(maxsize=256)
def critical_z(n: int, n_base: int, n_recent: int, alpha: float = DEFAULT_ALPHA, draws: int = 20000) -> float:
    """|z| exceeded with probability ``alpha`` by a stable series (i.i.d. Gaussian) of these lengths."""
    rng = np.random.default_rng(12345)
    x = rng.normal(size=(draws, n))
    d = np.diff(x, axis=1)
    s = 1.4826 * np.median(np.abs(d - np.median(d, axis=1)[:, None]), axis=1) / math.sqrt(2.0)
    mb = np.median(x[:, :n_base], axis=1)
    mr = np.median(x[:, n - n_recent:], axis=1)
    z = (mr - mb) / (s * math.sqrt(math.pi / 2.0) * math.sqrt(1.0 / n_base + 1.0 / n_recent))
    return float(np.quantile(np.abs(z), 1.0 - alpha))


def split(n: int, min_baseline: int = MIN_BASELINE, min_recent: int = MIN_RECENT) -> tuple[int, int] | None:
    if n < min_baseline + min_recent:
        return None
    nb = max(min_baseline, n // 3)
    nr = max(min_recent, n // 3)
    if nb + nr > n:
        nr = n - nb
    return nb, nr


def shift_test(times: np.ndarray, values: np.ndarray, unc: np.ndarray, *, alpha: float = DEFAULT_ALPHA,
                min_change: float = 0.0) -> dict[str, Any]:
    """Test one series (times in days, any origin). Returns the statistics and ``alert`` (bool)."""
    order = np.argsort(times, kind="stable")
    t, v, u = times[order], values[order], unc[order]
    ok = np.isfinite(v)
    t, v, u = t[ok], v[ok], u[ok]
    parts = split(len(v))
    if parts is None:
        return {"tested": False, "alert": False, "n": int(len(v)),
                "reason": f"{len(v)} recordings; the test needs >= {MIN_BASELINE + MIN_RECENT}"}
    nb, nr = parts
    base, recent = v[:nb], v[-nr:]
    uu = u[np.isfinite(u)]
    u_med = float(np.median(uu)) if len(uu) else 0.0
    z = statistic(v, nb, nr, u_med)
    zc = critical_z(len(v), nb, nr, alpha)
    mb, mr = float(np.median(base)), float(np.median(recent))
    rel = (mr - mb) / abs(mb) if mb else float("nan")
    out = {"tested": True, "n": int(len(v)), "n_baseline": nb, "n_recent": nr, "baseline_median": mb,
           "recent_median": mr, "change": mr - mb, "relative_change": rel,
           "scatter": scatter(v), "median_uncertainty": u_med, "z": z, "z_critical": zc,
           "alpha": alpha}
    out["alert"] = bool(abs(z) > zc and (not min_change or (math.isfinite(rel) and abs(rel) >= min_change)))
    if len(v) >= 3 and np.ptp(t) > 0:
        from scipy.stats import theilslopes

        slope, _, lo, hi = theilslopes(v, t, alpha=0.95)
        out.update(slope_per_30d=30.0 * slope, slope_low_per_30d=30.0 * lo, slope_high_per_30d=30.0 * hi)
        # a step looks like a flat start and a flat end; a drift keeps moving within both
        if not out["alert"]:
            out["shape"] = "no alert"
        else:
            out["shape"] = "drift" if (lo > 0 or hi < 0) and _within_trend(t, v, nb, nr) else "step or shift"
    return out


def _within_trend(t, v, nb, nr) -> bool:
    """Both the baseline and the recent part keep moving in the same direction (a drift, not a step)."""
    from scipy.stats import theilslopes

    s_all = theilslopes(v, t)[0]
    s1 = theilslopes(v[:nb], t[:nb])[0] if np.ptp(t[:nb]) > 0 else 0.0
    s2 = theilslopes(v[-nr:], t[-nr:])[0] if np.ptp(t[-nr:]) > 0 else 0.0
    return s1 * s_all > 0 and s2 * s_all > 0 and min(abs(s1), abs(s2)) > 0.3 * abs(s_all)
