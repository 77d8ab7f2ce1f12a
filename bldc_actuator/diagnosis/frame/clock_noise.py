"""Noise in the derivatives from samples taken at scattered instants (a logger's odd clock, :mod:`..io.clock`).

A channel ``x`` sampled at ``t_k + e_k`` but placed at ``t_k`` holds ``x(t_k) + x'(t_k) e_k``: the angle carries
``omega e_k``, and its second central difference -- the acceleration the inertia column is made of -- carries that
white noise through ``D^2`` (``1/T^2`` per sample), far above the motion's own acceleration at speed. The zero-phase
low-pass keeps a share of it. The equation's target holds the same noise times the nominal inertia (``P = J omega' +
...`` on the right), so least squares reads it as an inertia too small by ``E[u'u] / E[x'x]`` (errors in variables:
1.4 x nominal fitted as 1.34 with 20 % of a 500 Hz period of scatter, 7 standard deviations off).

Taken out wherever the acceleration is fitted: at the columns' true coefficients the residual holds
``-(J + beta_J) u`` (``u`` the noise of the inertia column ``omega'/K``, ``beta_J`` that column's coefficient), so a
column's expected cross product with it is ``-(J + beta_J) E[c_u' u]``, ``c_u`` the noise the column holds:
:func:`column_cross` builds it through the column's own builder from :data:`DRAWS` realizations of ``u`` (the
smoothed slope the scatter multiplies -- the speed for an angle-derived speed, the acceleration for a logged speed --
times white noise of the measured scatter, through the same central differences), and
:func:`.equation_error.fit_columns` moves the ``beta_J`` share to the left of its normal equations. The compliance
search's own fit (:func:`decimated_cross`) and the current alignment's (:func:`acceleration_noise_variance`: the
expected ``E[u_r^2] = sigma^2 sum_k g(r - k)^2 (s_k / K_k)^2``, ``g`` the chain's impulse response) do the same. A
column instrumented by the lagged acceleration (:mod:`.loop_noise`'s loop-fed current noise) does not share white
timing noise: no cross there."""

from __future__ import annotations

import numpy as np
from scipy import signal as sps

from ... import zero_phase


def _impulse_energy(ctx, derivatives: int) -> np.ndarray:
    """``g^2``: the squared impulse response of ``derivatives`` central differences then the zero-phase low-pass at
    the log's rate (a uniform grid of period 1/fs)."""
    half = int(20 * ctx.fs / ctx.dec.fc) + 20
    x = np.zeros(2 * half + 1)
    x[half] = 1.0
    for _ in range(derivatives):
        x = np.gradient(x, 1.0 / ctx.fs)
    y = zero_phase.sosfiltfilt(ctx.dec.sos, x)
    return y ** 2


def acceleration_noise_energy(ctx, rows: np.ndarray | None = None) -> float:
    """Expected sum over the mechanical equation's training rows (or the decimated ``rows``) of the squared timing
    noise in ``omega'/K`` (its column in current units), 0 without a resolved scatter."""
    var = acceleration_noise_variance(ctx)
    if var is None:
        return 0.0
    rows = ctx.train_rows("mechanical") if rows is None else rows
    return float(var[rows].sum())


def acceleration_noise_variance(ctx) -> np.ndarray | None:
    """Expected variance of the timing noise in ``omega'/K`` per decimated sample (module docstring); None without
    a resolved scatter."""
    sigma = ctx.instant_scatter
    if sigma is None or not np.any(sigma > 0) or ctx.steady or "omega_dot" not in ctx.sig:
        return None
    return ctx.memo(("clock_noise_variance",), lambda: _variance(ctx))


def _variance(ctx) -> np.ndarray:
    sigma = ctx.instant_scatter
    S = ctx.sig
    from_angle = float(S.get("omega_from_position", 0.0)) > 0
    slope = S["omega_s"] if from_angle else ctx.dec.lowpass(S["omega_dot"])
    g2 = _impulse_energy(ctx, 2 if from_angle else 1)
    w = (sigma * slope / S["K"]) ** 2
    var = np.zeros_like(w)
    for lo, hi in ctx.segments:
        if hi - lo > 1:
            var[lo:hi] = np.convolve(w[lo:hi], g2, mode="same")
    return var[ctx.dec.idx]


#: noise realizations the cross products of the columns are averaged over (a fixed seed: the same context gives the
#: same fit)
DRAWS = 4
SEED = 24


def _realizations(ctx) -> list[tuple[np.ndarray, np.ndarray]]:
    """``[(u, u_column)]``: realizations of the scattered instants' noise in ``omega'`` at the raw rate and in the
    inertia column (``u/K`` low-passed and decimated); empty without a resolved scatter."""
    sigma = ctx.instant_scatter
    S = ctx.sig
    if sigma is None or not np.any(sigma > 0) or ctx.steady or "omega_dot" not in S:
        return []
    from_angle = float(S.get("omega_from_position", 0.0)) > 0
    slope = S["omega_s"] if from_angle else ctx.dec.lowpass(S["omega_dot"])
    rng = np.random.default_rng(SEED)
    out = []
    for _ in range(DRAWS):
        n = sigma * slope * rng.standard_normal(len(slope))   # the angle's (or the speed's) displacement
        u = np.zeros_like(n)
        for lo, hi in ctx.segments:
            if hi - lo >= 3:
                x = n[lo:hi]
                for _ in range(2 if from_angle else 1):
                    x = np.gradient(x, ctx.t[lo:hi])
                u[lo:hi] = x
        out.append((u, ctx.dec.apply(u / S["K"])))
    return out


def realizations(ctx) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`_realizations`, once per context."""
    return ctx.memo(("clock_noise_realizations",), lambda: _realizations(ctx))


def column_cross(ctx, rebuild, column: dict[str, np.ndarray]) -> dict[str, float]:
    """``{"mechanical": E[sum over training rows of c_u u]}``: the timing noise ``c_u`` the mechanical column
    ``column`` (``rebuild()``: the same column built again from the context's signals as they are then) holds, against the inertia column's own
    ``u``; per unit of the inertia that multiplies the residual's share (``e = -(J + beta_J) u``). ``c_u`` is the
    column built with the noise added to the acceleration (and to the nominal motion torque ``P = J omega' + ...``)
    minus the column, averaged over :data:`DRAWS` realizations. Empty without a resolved scatter."""
    reals = realizations(ctx)
    if not reals or "mechanical" not in column or "mechanical" not in ctx.blocks:
        return {}
    S = ctx.sig
    J = ctx.params.motor.rotor_inertia
    rows = ctx.train_rows("mechanical")
    kept = {k: S[k] for k in ("omega_dot", "P") if k in S}
    total = 0.0
    try:
        for u, u_col in reals:
            S["omega_dot"] = kept["omega_dot"] + u
            if "P" in kept:
                S["P"] = kept["P"] + J * u
            c = rebuild().get("mechanical")
            if c is None:
                return {}
            total += float((c - column["mechanical"])[rows] @ u_col[rows])
    finally:
        S.update(kept)
    return {"mechanical": total / len(reals)}


def decimated_cross(ctx, column_of, target_of) -> float:
    """``E[sum over the mechanical training rows of column_of(u) target_of(u)]`` over the realizations of the inertia
    column's timing noise ``u`` (decimated): for a column a search builds from the decimated acceleration with its
    own filters (``column_of``) against the target as it filters it (``target_of``); 0 without a resolved scatter."""
    reals = realizations(ctx)
    if not reals or "mechanical" not in ctx.blocks:
        return 0.0
    rows = ctx.train_rows("mechanical")
    return float(np.mean([column_of(u_col)[rows] @ target_of(u_col)[rows] for _, u_col in reals]))
