"""The angle's quantization error (an encoder's counts) in the derivatives the equations take from the angle.

An angle on a grid of step ``q`` holds an error ``e`` (a sawtooth in the motion, ~ ``q^2/12`` in power) that the
speed and acceleration taken from it by central differences carry through ``D`` and ``D^2``: the acceleration's
noise ``u = D^2 e`` rises as ``f^2`` up to the log rate, and the zero-phase low-pass keeps its band. The mechanical
equation's target holds the same noise times the nominal inertia (``-J u / K`` in current units), so every column
made of the acceleration shares it: its expected cross product with the target is ``-J E[c_u' u]``. A rotor that
carries a large reflected load (a robot joint's body inertia moved onto its rotor, ~70 x the rotor's own) makes
that share large against the motion's, and the compliance search read it as a load that decouples above an
"anti-resonance" at the top of its band (a rigid joint with a 14-bit encoder and 71 x the rotor inertia: 30.8 Hz,
damping ratio 1, "not decidable" against its backlash alias).

:func:`angle_error` re-makes the error by quantizing the angle, low-passed at :data:`QUANTIZATION_MOTION_CUTOFF` x
the cut-off, on the recorded grid (:func:`angle_step`): its spectrum is the recorded error's, its phase need not
be. :func:`decimated_cross` is its share of a search column's cross product with the target, as
:func:`.clock_noise.decimated_cross` is the scattered instants'; :mod:`..report.residual_structure` takes its
paths into the residual's noise reference from the same error."""

from __future__ import annotations

import math

import numpy as np

QUANTIZED_MIN = 0.99     #: fraction of angle samples on one grid for the angle to count as quantized


def angle_step(theta: np.ndarray) -> tuple[float, float] | None:
    """(step [rad], grid offset [rad]) of an angle channel that sits on a grid (an encoder's counts), or None.
    The step is the smallest spacing of the recorded values that more than :data:`QUANTIZED_MIN` of the samples sit
    on (within 1 % of it)."""
    th = theta[np.isfinite(theta)]
    if len(th) < 64:
        return None
    u = np.unique(th)
    d = np.diff(u)
    d = d[d > 1e-12 * max(1.0, float(np.max(np.abs(u))))]
    if len(d) < 2:
        return None
    step = float(np.percentile(d, 5))
    if not step > 0 or float(np.ptp(th)) / step > 1e9:
        return None
    # the step refined over the whole range (counts fitted to the values): a spacing read from a log printed to a
    # few digits is off by its last digit, which drifts the grid by steps over many counts (a joint encoder's 2^16
    # counts times the gear ratio printed to 7 digits: up to 1e-3 of a step per count, steps over 7800 counts)
    # counts of steps from the lowest value, over a span doubled while the refined step keeps them whole
    span = 64.0
    while True:
        near = u <= u[0] + span * step
        counts = np.round((u[near] - u[0]) / step)
        if np.ptp(counts) > 0 and np.max(np.abs((u[near] - u[0]) / step - counts)) < 0.25:
            step = float(np.polyfit(counts, u[near], 1)[0])
        if near.all():
            break
        span *= 2.0
    frac = th / step - np.round(th / step)
    off = float(np.angle(np.mean(np.exp(2j * math.pi * frac)))) / (2 * math.pi)
    dev = np.abs((frac - off + 0.5) % 1.0 - 0.5)
    if np.mean(dev < 0.01) < QUANTIZED_MIN:
        return None
    return step, off * step


def segment_gradient(x: np.ndarray, t: np.ndarray, segments) -> np.ndarray:
    """Central differences of ``x`` over ``t`` per segment (as the equations take the speed from the angle)."""
    out = np.zeros_like(x)
    for a, b in segments:
        if b - a >= 3:
            out[a:b] = np.gradient(x[a:b], t[a:b])
    return out


#: the re-made motion a quantization error is re-made on: the angle low-passed at this fraction of the cut-off (the
#: recorded error's own lines below the cut-off, e.g. a 2086 Hz sawtooth sampled at 1 kHz sits at 86 Hz, must not be
#: in it: quantizing an angle that holds them again cancels them)
QUANTIZATION_MOTION_CUTOFF = 0.25


def angle_error(ctx) -> tuple[np.ndarray, np.ndarray] | None:
    """``(d1, d2)``: the re-made quantization error of the angle through one and two central differences at the raw
    rate (the speed's and the acceleration's share), or None when the angle is not quantized or the speed is not
    taken from it (module docstring). Once per context."""
    memo = getattr(ctx, "memo", None)
    return _angle_error(ctx) if memo is None else memo(("quantization_angle_error",), lambda: _angle_error(ctx))


def _angle_error(ctx):
    raw = getattr(ctx, "raw", {}) or {}
    dec, S = ctx.dec, ctx.sig
    if "position" not in raw or "theta" not in S or "omega" not in S or getattr(dec, "steady", False) \
            or getattr(dec, "sos", None) is None:
        return None
    theta = np.asarray(S["theta"], float)
    grid = angle_step(np.asarray(raw["position"], float))
    if grid is None or not np.isfinite(theta).all():
        return None
    d1_rec = segment_gradient(theta, ctx.t, ctx.segments)
    if not np.allclose(S["omega"], d1_rec, rtol=1e-9, atol=1e-12):
        return None               # the speed is the velocity channel's
    step, off = grid
    smooth = dec.lowpass(theta, QUANTIZATION_MOTION_CUTOFF * dec.fc)
    err = step * np.round((smooth - off) / step) + off - smooth
    d1 = segment_gradient(err, ctx.t, ctx.segments)
    return d1, segment_gradient(d1, ctx.t, ctx.segments)


def decimated_cross(ctx, column_of, target_of) -> float:
    """``sum over the mechanical training rows of column_of(u) target_of(u)``, ``u`` the quantization error's share
    of the inertia column ``omega'/K`` (decimated): for a column a search builds from the decimated acceleration
    with its own filters (``column_of``) against the target as it filters it (``target_of``); per unit of the
    inertia that scales the target's share (``-J u``); 0 without a quantized angle."""
    err = angle_error(ctx)
    if err is None or "mechanical" not in ctx.blocks or ctx.steady:
        return 0.0
    memo = getattr(ctx, "memo", None)
    share = lambda: ctx.dec.apply(err[1] / ctx.sig["K"])    # noqa: E731 - the same array on every call (memo)
    u = share() if memo is None else memo(("quantization_decimated_share",), share)
    rows = ctx.train_rows("mechanical")
    return float(column_of(u)[rows] @ target_of(u)[rows])
