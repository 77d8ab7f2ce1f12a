"""Two fitted parameters the data cannot separate, and the one combination of them it does pin (issue #24,
symptoms 5 and 6): the one implementation behind the voltage equation's core check (:mod:`..fit.base_model`:
R and K_t under a viscous brake, ω ∝ i) and the linear selection's final fit (:mod:`.writeback`: a constant
load and a gravity term over a short stroke, any two accepted columns).

Where the fitted estimates of ``x_p`` and ``x_q`` correlate beyond :data:`COLLINEAR`, their columns are (nearly)
proportional over the recording, ``X_q ≈ a X_p`` with ``a = <X_q, X_p> / <X_p, X_p>``: the data pin
``x_p + a x_q`` (the coefficient of ``X_p`` once ``X_q`` is folded into it) to ``sd = sqrt(w' Σ w)``,
``w = (1, a)``, and say next to nothing about ``x_p - x_q / a``. The defensible write-back holds the second at
its nominal value and gives the first the whole combination (``x_p = c - a x_q,nominal``): the model then
simulates the recording as the fit does, and no value the data did not determine is changed."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: |correlation| of two fitted estimates beyond which they are reported as their identifiable combination
COLLINEAR = 0.99


@dataclass(frozen=True)
class Combination:
    """``parameters[0] + a * parameters[1]`` = ``value`` ± ``sd``; ``value`` in the first parameter's units (the
    fitted values, nominal parts included, of whatever the two names are); ``correlation``: of the two
    estimates."""

    parameters: tuple[str, str]
    correlation: float
    a: float
    value: float
    sd: float

    def text(self, symbols: dict[str, str] | None = None, unit: str = "") -> str:
        sp, sq = ((symbols or {}).get(p, p) for p in self.parameters)
        return (f"{sp} and {sq} not separable with this data (their fitted estimates correlate "
                f"{self.correlation:+.4f}): the data pin {sp} + {self.a:.4g}·{sq} = {self.value:.4g} ± "
                f"{self.sd:.2g}{' ' + unit if unit else ''}")


def correlation(cov: np.ndarray, i: int, j: int) -> float:
    d = cov[i, i] * cov[j, j]
    return float(cov[i, j] / math.sqrt(d)) if d > 0 and math.isfinite(d) else float("nan")


def collinear(names: list[str], values, cov: np.ndarray, columns, *, limit: float = COLLINEAR,
              among: list[str] | None = None) -> list[Combination]:
    """The pairs of ``among`` (default all ``names``) whose estimates correlate beyond ``limit``, strongest
    first, each parameter in one pair at most. ``values``: the fitted values (any offset: the combination is
    ``values[p] + a values[q]``), ``cov`` their covariance (in the columns' order ``names``), ``columns``: name ->
    the regressor column (or a 2-D array whose columns are in ``names`` order) that defines ``a``."""
    idx = {k: i for i, k in enumerate(names)}
    cand = [k for k in (among if among is not None else names) if k in idx]
    col = (lambda k: np.asarray(columns[:, idx[k]], float)) if isinstance(columns, np.ndarray) else \
        (lambda k: np.asarray(columns[k], float))
    pairs = []
    for ii, p in enumerate(cand):
        for q in cand[ii + 1:]:
            rho = correlation(cov, idx[p], idx[q])
            if abs(rho) > limit:
                pairs.append((abs(rho), rho, p, q))
    pairs.sort(key=lambda x: -x[0])
    used, out = set(), []
    for _, rho, p, q in pairs:
        if p in used or q in used:
            continue
        xp, xq = col(p), col(q)
        ok = np.isfinite(xp) & np.isfinite(xq)
        a = float(xq[ok] @ xp[ok] / max(float(xp[ok] @ xp[ok]), 1e-300))      # X_q ~ a X_p over the recording
        w = np.array([1.0, a])
        sub = cov[np.ix_([idx[p], idx[q]], [idx[p], idx[q]])]
        out.append(Combination((p, q), rho, a, float(values[idx[p]] + a * values[idx[q]]),
                               float(math.sqrt(max(float(w @ sub @ w), 0.0)))))
        used |= {p, q}
    return out


def same_equation(ctx, cols, keys_x: list[str], keys_y: list[str]) -> float | None:
    """Whether every column of ``keys_y`` (those not in ``keys_x``) lies in the span of the columns ``keys_x`` on
    the training rows the fit uses: the smallest uncentred R² when each is beyond :data:`COLLINEAR` squared, else
    None. A constant load while moving and a friction asymmetry (``|sign ω|``) are one column wherever the rotor
    is not stuck (stuck samples leave the equation: friction is anything up to breakaway there). ``ctx``: the
    equation-error context (its ``blocks`` and ``holdout_dec``); ``cols``: key -> {equation: decimated column}."""
    extra = [k for k in keys_y if k not in keys_x]
    if not extra or not keys_x:
        return None
    ho = ctx.holdout_dec
    Xs, Ys = [], []
    for eq, B in ctx.blocks.items():
        rows = B.rows(ho, "train")
        n = int(rows.sum())
        if not n:
            continue

        def take(k):
            c = cols[k].get(eq)
            return c[rows] if c is not None else np.zeros(n)

        Xs.append(np.column_stack([take(k) for k in keys_x]))
        Ys.append(np.column_stack([take(k) for k in extra]))
    if not Xs:
        return None
    X, Y = np.vstack(Xs), np.vstack(Ys)
    good = np.all(np.isfinite(X), axis=1) & np.all(np.isfinite(Y), axis=1)
    X, Y = X[good], Y[good]
    if len(X) < 10:
        return None
    r2 = []
    for j in range(Y.shape[1]):
        y = Y[:, j]
        yy = float(y @ y)
        if yy <= 0:
            continue
        beta, *_ = np.linalg.lstsq(X, y, rcond=None)
        e = y - X @ beta
        r2.append(1.0 - float(e @ e) / yy)
    if not r2 or min(r2) <= COLLINEAR ** 2:
        return None
    return float(min(r2))
