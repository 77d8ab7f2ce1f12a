"""Locate a mismatch: WHEN (time windows, change points) and WHERE (operating regime, rotor angle).

All functions take the decimated equation-error residual of one equation (see :mod:`.equation_error`)
and the operating signals at the same instants. Results are plain dicts (JSON-ready).

* :func:`binned` — residual mean / RMS / z-score per bin of a signal (velocity sign and magnitude with a
  near-zero bin, |current|, temperature, voltage headroom |v|/v_max).
* :func:`rolling_rms` and :func:`change_points` — binary segmentation of the block-wise residual level
  (mean and log mean square) with a BIC-like penalty (ruptures is not a dependency).
* :func:`order_spectrum` — residual resampled on rotor angle (bin means over one mechanical revolution)
  and Fourier-transformed: amplitude per mechanical order, with pole_pairs, 2p, 6p and cogging orders marked.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .equation_error import integrated_autocorrelation_time


def _stats(r: np.ndarray, tau: float) -> dict[str, float]:
    n = len(r)
    if n == 0:
        return {"count": 0, "mean": float("nan"), "rms": float("nan"), "z": 0.0}
    mean = float(np.mean(r))
    sd = float(np.std(r)) if n > 1 else 0.0
    n_eff = max(1.0, n / tau)
    z = mean / (sd / math.sqrt(n_eff)) if sd > 0 else 0.0
    return {"count": int(n), "mean": mean, "rms": float(np.sqrt(np.mean(r ** 2))), "z": float(z)}


def binned(r: np.ndarray, x: np.ndarray, edges: list[float], labels: list[str] | None = None,
           tau: float | None = None) -> list[dict[str, Any]]:
    """Residual statistics in bins ``edges[k] <= x < edges[k+1]``; ``z`` = mean / its standard error
    (effective sample count from the residual's correlation time)."""
    ok = np.isfinite(r) & np.isfinite(x)
    r, x = r[ok], x[ok]
    if tau is None:
        tau = integrated_autocorrelation_time(r) if len(r) > 8 else 1.0
    out = []
    for k in range(len(edges) - 1):
        sel = (x >= edges[k]) & (x < edges[k + 1])
        s = _stats(r[sel], tau)
        s["lo"], s["hi"] = float(edges[k]), float(edges[k + 1])
        s["label"] = labels[k] if labels else f"[{edges[k]:.4g}, {edges[k + 1]:.4g})"
        out.append(s)
    return out


def velocity_edges(omega: np.ndarray, near_zero: float, n_side: int = 3) -> tuple[list[float], list[str]]:
    """Bins: negative speeds (quantiles), a near-zero bin ``|ω| < near_zero``, positive speeds."""
    w = omega[np.isfinite(omega)]
    neg = np.sort(w[w <= -near_zero])
    pos = np.sort(w[w >= near_zero])
    edges: list[float] = []
    labels: list[str] = []
    if len(neg) > 10:
        qs = np.quantile(neg, np.linspace(0, 1, n_side + 1))
        qs[0] = -np.inf
        edges += list(qs[:-1])
        labels += [f"ω<0 ({'slow' if k == n_side - 1 else 'fast' if k == 0 else 'mid'})" for k in range(n_side)]
    edges.append(-near_zero)
    labels.append("|ω|≈0")
    edges.append(near_zero)
    if len(pos) > 10:
        qs = np.quantile(pos, np.linspace(0, 1, n_side + 1))
        edges += list(qs[1:-1]) + [np.inf]
        labels += [f"ω>0 ({'slow' if k == 0 else 'fast' if k == n_side - 1 else 'mid'})" for k in range(n_side)]
    else:
        edges.append(np.inf)
        labels.append("ω>0")
    if len(neg) <= 10:
        edges = [-np.inf] + edges
        labels = ["ω<0"] + labels
    # drop empty/degenerate bins
    e2, l2 = [edges[0]], []
    for k in range(len(labels)):
        if edges[k + 1] > e2[-1]:
            e2.append(edges[k + 1])
            l2.append(labels[k])
    return e2, l2


def quantile_edges(x: np.ndarray, n: int) -> list[float]:
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return [0.0, 1.0]
    qs = np.unique(np.quantile(x, np.linspace(0, 1, n + 1)))
    if len(qs) < 2:
        qs = np.array([qs[0], qs[0] + 1e-9])
    qs[-1] = np.nextafter(qs[-1], np.inf)
    return list(qs)


# -- time -----------------------------------------------------------------------------------------

def rolling_rms(t: np.ndarray, r: np.ndarray, window: float) -> tuple[np.ndarray, np.ndarray]:
    """Residual RMS in consecutive windows of ``window`` seconds: (window centre times, rms)."""
    ok = np.isfinite(r)
    t, r = t[ok], r[ok]
    if len(t) == 0:
        return np.zeros(0), np.zeros(0)
    k = np.floor((t - t[0]) / window).astype(int)
    cnt = np.bincount(k)
    s2 = np.bincount(k, weights=r * r)
    st = np.bincount(k, weights=t)
    good = cnt > 0
    return st[good] / cnt[good], np.sqrt(s2[good] / cnt[good])


def _segment_cost(S1, S2, C, a, b):
    """Gaussian mean-change cost of x[a:b] from prefix sums: Σ(x - mean)²."""
    n = b - a
    s = S1[b] - S1[a]
    return (S2[b] - S2[a]) - s * s / n


def binary_segmentation(x: np.ndarray, penalty: float, min_size: int = 3, max_cp: int = 8) -> list[int]:
    """Change points of the mean of a (multi-column) series ``x`` (n, d), each column scaled to unit noise:
    split where the cost drop exceeds ``penalty``; recurse. Returns sorted split indices."""
    x = np.atleast_2d(np.asarray(x, float).T).T
    n = len(x)
    S1 = np.vstack([np.zeros(x.shape[1]), np.cumsum(x, axis=0)])
    S2 = np.concatenate([[0.0], np.cumsum((x * x).sum(axis=1))])

    def cost(a, b):
        s = S1[b] - S1[a]
        return (S2[b] - S2[a]) - float((s * s).sum()) / (b - a)

    cps: list[int] = []
    stack = [(0, n)]
    while stack and len(cps) < max_cp:
        a, b = stack.pop()
        if b - a < 2 * min_size:
            continue
        total = cost(a, b)
        best, best_k = 0.0, None
        for k in range(a + min_size, b - min_size + 1):
            gain = total - cost(a, k) - cost(k, b)
            if gain > best:
                best, best_k = gain, k
        if best_k is not None and best > penalty:
            cps.append(best_k)
            stack += [(a, best_k), (best_k, b)]
    return sorted(cps)


def change_points(t: np.ndarray, r: np.ndarray, *, n_blocks: int = 200) -> dict[str, Any]:
    """Change points of the residual level: block means and log mean squares over ~``n_blocks`` blocks,
    each standardised by its noise (MAD of block-to-block differences), binary segmentation with
    penalty ``4 ln n`` per split. Returns the segments with their mean/RMS and the split times."""
    ok = np.isfinite(r)
    t, r = t[ok], r[ok]
    if len(t) < 40:
        return {"times": [], "segments": []}
    nb = int(min(n_blocks, max(8, len(t) // 10)))
    edges = np.linspace(0, len(t), nb + 1).astype(int)
    mean = np.array([r[a:b].mean() for a, b in zip(edges[:-1], edges[1:])])
    lms = np.array([math.log(max(np.mean(r[a:b] ** 2), 1e-300)) for a, b in zip(edges[:-1], edges[1:])])
    feats = []
    for f in (mean, lms):
        d = np.diff(f)
        s = 1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2) if len(d) > 2 else 1.0
        feats.append(f / (s if s > 0 else (np.std(f) or 1.0)))
    X = np.column_stack(feats)
    cps = binary_segmentation(X, penalty=4.0 * math.log(nb) * 2, min_size=max(2, nb // 50))
    seg_edges = [0] + cps + [nb]
    segs = []
    for a, b in zip(seg_edges[:-1], seg_edges[1:]):
        ia, ib = edges[a], edges[b]
        rr = r[ia:ib]
        segs.append({"start": float(t[ia]), "stop": float(t[ib - 1]), "mean": float(rr.mean()),
                     "rms": float(np.sqrt(np.mean(rr ** 2)))})
    return {"times": [float(t[edges[c]]) for c in cps], "segments": segs}


def located_windows(cp: dict[str, Any], r: np.ndarray, equation: str, unit: str,
                    ratio_threshold: float = 1.5) -> list[dict[str, Any]]:
    """Segments between change points whose residual RMS is ``ratio_threshold`` times the quietest
    segment's (or whose mean is offset by more than its quiet RMS): where/when the model breaks."""
    segs = cp.get("segments", [])
    if len(segs) < 2:
        return []
    base = min(s["rms"] for s in segs)
    out = []
    for s in segs:
        ratio = s["rms"] / base if base > 0 else float("inf")
        if ratio >= ratio_threshold or abs(s["mean"]) > base:
            out.append({"equation": equation, "start": s["start"], "stop": s["stop"], "rms": s["rms"],
                        "mean": s["mean"], "ratio_to_quietest": ratio, "unit": unit, "kind": "change_point"})
    return out


# -- angle ----------------------------------------------------------------------------------------

def order_spectrum(theta: np.ndarray, r: np.ndarray, *, max_order: int = 512, pole_pairs: int = 1,
                   cogging_order: int = 0, omega: np.ndarray | None = None, fc: float | None = None,
                   min_samples: int = 100) -> dict[str, Any]:
    """Amplitude of the residual per mechanical order k (cycles per rotor revolution), k = 1..max_order.

    The residual is taken as a function of rotor angle and projected on ``exp(-i k θ)`` (a least-squares
    periodogram over angle: the FFT of the angle-resampled residual when the angle is covered uniformly,
    and still unbiased in phase when it is not). Orders in each octave use only samples slow enough that
    the order passes the residual's low-pass (``k |ω| / 2π < fc/2``), when ``omega``/``fc`` are given.
    Orders p, 2p, 6p and the cogging order are marked; ``peaks`` lists orders standing out of the local
    median by a factor >= 4.
    """
    ok = np.isfinite(theta) & np.isfinite(r)
    if omega is not None:
        ok &= np.isfinite(omega)
    theta, r = theta[ok], r[ok]
    w = np.abs(np.asarray(omega)[ok]) if omega is not None else None
    info: dict[str, Any] = {"orders": [], "amplitude": [], "peaks": [], "marks": {}, "method": "angle periodogram"}
    if len(theta) < 50:
        info["note"] = "too few samples"
        return info
    amp = np.full(max_order + 1, np.nan)
    used = np.zeros(max_order + 1, int)
    lo = 1
    while lo <= max_order:
        hi = min(max(lo, int(lo * 1.4)), max_order)
        if w is not None and fc:
            # weight: 1 while order `hi` sits below fc/2, falling to 0 at fc (as the regressors do)
            x = np.clip((w * hi / (2 * math.pi) - 0.5 * fc) / (0.5 * fc), 0.0, 1.0)
            wt = 0.5 * (1.0 + np.cos(math.pi * x))
        else:
            wt = np.ones(len(theta))
        sel = wt > 0
        n_eff = float(wt.sum())
        if n_eff >= min_samples:
            th, ww = theta[sel], wt[sel]
            rr = r[sel] - np.sum(ww * r[sel]) / ww.sum()
            wr = ww * rr
            z1 = np.exp(-1j * th)
            zk = z1 ** lo
            for k in range(lo, hi + 1):     # real dot products: a float @ complex product is 20x slower
                amp[k] = 2.0 * math.hypot(wr @ zk.real, wr @ zk.imag) / n_eff
                used[k] = int(n_eff)
                zk *= z1
        lo = hi + 1
    good = np.isfinite(amp[1:])
    info["orders"] = [int(k) for k in np.arange(1, max_order + 1)[good]]
    info["amplitude"] = [float(a) for a in amp[1:][good]]
    info["samples"] = [int(u) for u in used[1:][good]]
    marks = {"pole_pairs": pole_pairs, "2p": 2 * pole_pairs, "6p": 6 * pole_pairs}
    if cogging_order:
        marks["cogging"] = cogging_order
    info["marks"] = {k: v for k, v in marks.items() if 0 < v <= max_order}
    if not good.any():
        info["note"] = "no slow motion to resolve angle orders"
        return info
    a = np.array(info["amplitude"])
    ords = np.array(info["orders"])
    # local median (orders within a factor 2) as the noise floor
    peaks = []
    for idx in np.argsort(a)[::-1][:12]:
        k = ords[idx]
        near = a[(ords >= k / 2) & (ords <= 2 * k)]
        med = float(np.median(near)) if len(near) > 4 else float(np.median(a))
        if med > 0 and a[idx] >= 4.0 * med:
            peaks.append({"order": int(k), "amplitude": float(a[idx]), "ratio_to_median": float(a[idx] / med)})
    info["peaks"] = peaks[:8]
    info["median"] = float(np.median(a))
    return info


def angle_synchronous(theta: np.ndarray, r: np.ndarray, period_order: int, n_bins: int = 32) -> dict[str, Any]:
    """Residual averaged over the phase within one period of order ``period_order`` (2π/N): the
    angle-synchronous part. Returns bin centres, bin means and their RMS (the periodic error level)."""
    ok = np.isfinite(theta) & np.isfinite(r)
    if ok.sum() < n_bins * 3 or period_order <= 0:
        return {"rms": float("nan"), "phase": [], "mean": []}
    ph = (theta[ok] * period_order) % (2 * math.pi)
    b = np.minimum((ph / (2 * math.pi) * n_bins).astype(int), n_bins - 1)
    cnt = np.bincount(b, minlength=n_bins)
    s = np.bincount(b, weights=r[ok], minlength=n_bins)
    m = np.where(cnt > 0, s / np.maximum(cnt, 1), np.nan)
    m = m - np.nanmean(m)
    return {"rms": float(np.sqrt(np.nanmean(m ** 2))), "phase": ((np.arange(n_bins) + 0.5) * 2 * math.pi / n_bins).tolist(),
            "mean": m.tolist()}


# -- everything for one equation ------------------------------------------------------------------

def locate_equation(ctx, eq: str, resid_dec: np.ndarray) -> dict[str, Any]:
    """All locate views of one equation's decimated residual."""
    S = ctx.sig
    t = ctx.t_dec
    r = resid_dec
    ok = np.isfinite(r)
    tau = integrated_autocorrelation_time(r[ok]) if ok.sum() > 8 else 1.0
    out: dict[str, Any] = {"equation": eq, "unit": ctx.blocks[eq].unit, "rms": float(np.sqrt(np.nanmean(r ** 2))),
                           "mean": float(np.nanmean(r)), "tau_int": tau, "bins": {}}
    if "omega" in S:
        w = ctx.dsig("omega_s")
        near = max(2.0 * ctx.omega_eps, 0.02 * float(np.nanpercentile(np.abs(w), 95)))
        e, lab = velocity_edges(w[ok], near)
        out["bins"]["velocity"] = binned(r, w, e, lab, tau)
        out["near_zero_velocity"] = near
    if "i_q" in S:
        ia = np.abs(ctx.dsig("i_q"))
        out["bins"]["current"] = binned(r, ia, quantile_edges(ia[ok], 4), None, tau)
    if any(c in ctx.have for c in ("winding_temperature", "housing_temperature")):
        T = ctx.dsig("T_w")
        if np.nanmax(T) - np.nanmin(T) > 1.0:
            out["bins"]["temperature"] = binned(r, T, quantile_edges(T[ok], 4), None, tau)
    if "headroom" in S:
        h = ctx.dsig("headroom")
        out["bins"]["headroom"] = binned(r, h, [0.0, 0.5, 0.8, 0.95, np.inf],
                                         ["<0.5", "0.5-0.8", "0.8-0.95", ">=0.95 (at the limit)"], tau)
    dur = float(t[-1] - t[0]) if len(t) else 0.0
    win = max(0.1, dur / 100.0)
    tc, rms = rolling_rms(t, r, win)
    out["rolling_rms"] = {"window": win, "t": tc.tolist(), "rms": rms.tolist()}
    cp = change_points(t, r)
    out["change_points"] = cp
    out["windows"] = located_windows(cp, r, eq, out["unit"])
    if "theta" in S and float(S["theta_known"]) > 0:
        p = ctx.params.motor.pole_pairs
        nc = ctx.params.effects.cogging_order
        max_order = int(min(2048, 2 ** math.ceil(math.log2(max(12 * p, 2 * nc, 64)))))
        out["order_spectrum"] = order_spectrum(ctx.dsig("theta"), r, max_order=max_order, pole_pairs=p,
                                               cogging_order=nc, omega=ctx.dsig("omega_s"), fc=ctx.dec.fc)
    return out
