"""Noise in the derivatives from samples taken at scattered instants (a logger's odd clock, :mod:`..io.clock`).

A channel ``x`` sampled at ``t_k + e_k`` but placed at ``t_k`` holds ``x(t_k) + x'(t_k) e_k``: the angle carries
``omega e_k``, and its second central difference -- the acceleration the inertia column is made of -- carries that
white noise through ``D^2`` (``1/T^2`` per sample), far above the motion's own acceleration at speed. The zero-phase
low-pass keeps a share of it. The equation's target holds the same noise times the nominal inertia (``P = J omega' +
...`` on the right), so least squares reads it as an inertia too small by ``E[u'u] / E[x'x]`` (errors in variables:
1.4 x nominal fitted as 1.34 with 20 % of a 500 Hz period of scatter, 7 standard deviations off).

The expected cross product of the column with the residual, for bias-compensated least squares: at the column's true
coefficient ``beta`` the residual holds ``-(J + beta) u``, so ``E[x'e] = -(J + beta) sum_r E[u_r^2]`` with
``E[u_r^2] = sigma^2 sum_k g(r - k)^2 (s_k / K_k)^2``, ``g`` the impulse response of the column's chain (central
differences on the log's grid, the zero-phase low-pass) and ``s`` the smoothed slope the scatter multiplies (the
speed for an angle-derived speed, the acceleration for a logged speed). Solved with its coefficient
(:func:`.loop_noise.compensated_solve`). Where the acceleration columns are instrumented (:mod:`.loop_noise`'s
loop-fed current noise), the instrument, lagged past the filter's spread, is independent of white timing noise:
the cross is 0 there."""

from __future__ import annotations

import numpy as np
from scipy import signal as sps


def _impulse_energy(ctx, derivatives: int) -> np.ndarray:
    """``g^2``: the squared impulse response of ``derivatives`` central differences then the zero-phase low-pass at
    the log's rate (a uniform grid of period 1/fs)."""
    half = int(20 * ctx.fs / ctx.dec.fc) + 20
    x = np.zeros(2 * half + 1)
    x[half] = 1.0
    for _ in range(derivatives):
        x = np.gradient(x, 1.0 / ctx.fs)
    y = sps.sosfiltfilt(ctx.dec.sos, x)
    return y ** 2


def acceleration_noise_energy(ctx) -> float:
    """Expected sum over the mechanical equation's training rows of the squared timing noise in ``omega'/K`` (its
    column in current units), 0 without a resolved scatter."""
    sigma = ctx.instant_scatter
    if sigma is None or not np.any(sigma > 0) or ctx.steady or "omega_dot" not in ctx.sig:
        return 0.0
    S = ctx.sig
    from_angle = float(S.get("omega_from_position", 0.0)) > 0
    slope = S["omega_s"] if from_angle else ctx.dec.lowpass(S["omega_dot"])
    g2 = _impulse_energy(ctx, 2 if from_angle else 1)
    w = (sigma * slope / S["K"]) ** 2
    var = np.zeros_like(w)
    for lo, hi in ctx.segments:
        if hi - lo > 1:
            var[lo:hi] = np.convolve(w[lo:hi], g2, mode="same")
    rows = ctx.train_rows("mechanical")
    return float(var[ctx.dec.idx][rows].sum())


def inertia_cross(ctx) -> dict[str, float]:
    """``{"mechanical": E[x'e]}`` for the inertia column ``x = omega'``, at the coefficient of its own compensated
    fit beside the always-fitted nuisance columns (module docstring); 0 without scatter or where the acceleration
    columns are instrumented."""
    if "mechanical" not in ctx.blocks or "a_inst" in ctx.sig:
        return {"mechanical": 0.0}
    energy = acceleration_noise_energy(ctx)
    if not energy > 0.0:
        return {"mechanical": 0.0}
    from .loop_noise import compensated_solve

    J = ctx.params.motor.rotor_inertia

    def cross_of(beta: float) -> float:
        return -(J + beta) * energy

    rows = ctx.train_rows("mechanical")
    col = ctx.dec.apply(np.nan_to_num(ctx.sig["omega_dot"] / ctx.sig["K"]))[rows]
    nuis = [ctx.column(k, b).get("mechanical") for k, b in ctx.nuisance.items()]
    X = np.column_stack([col] + [c[rows] for c in nuis if c is not None])
    y = ctx.blocks["mechanical"].target[rows]
    try:
        _, bias = compensated_solve(X.T @ X, X.T @ y, 0, cross_of)
    except np.linalg.LinAlgError:
        bias = cross_of(0.0)
    return {"mechanical": bias}
