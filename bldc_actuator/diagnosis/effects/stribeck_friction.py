"""Stribeck friction (the low-speed rise).

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

import numpy as np

from .coulomb_friction import NON_NEGATIVE, excite_friction, params_friction
from .forms import Forms, Variant, frac, friction_columns
from .record import Effect, Param, Story

EFFECT = Effect(
    name="stribeck_friction", rank=30,
    description="Stribeck friction: extra friction at low speed that fades above the Stribeck velocity",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"coulomb_friction": "slow constant-speed sweeps (0.1-10x the Stribeck velocity)"},
    params=(Param("stribeck_friction", "N*m", "effects.stribeck_friction", NON_NEGATIVE),
            Param("stribeck_velocity", "rad/s", "effects.stribeck_velocity")),
    story=Story.VELOCITY,
)


def col_stribeck(omega_s):
    return lambda ctx: {"mechanical": friction_columns(ctx, omega_s)[:, 2]}


def excite_stribeck(ctx):
    r = excite_friction(ctx)
    if r:
        return r
    w = np.abs(ctx.dsig("omega_s"))
    slow = (w > 2 * ctx.omega_eps) & (w < 0.1 * np.percentile(w, 95))
    return None if frac(slow) > 0.02 else "needs slow motion (few samples at low non-zero speed)"


def v_stribeck(ctx, loc):
    """Six Stribeck velocities log-spaced over the recorded slow motion, each refined in the final fit."""
    w = np.abs(ctx.dsig("omega_s"))
    moving = w[w > 2 * ctx.omega_eps]
    if len(moving) < 10:
        return []
    lo = max(2.0 * ctx.omega_eps, float(np.percentile(moving, 2)))
    hi = max(lo * 1.5, 0.5 * float(np.median(moving)))
    out = []
    for ws in np.geomspace(lo, hi, 6):
        ws = float(ws)
        out.append(Variant(EFFECT.name, f"omega_s={ws:.3g} rad/s", {f"stribeck@{ws:.6g}": col_stribeck(ws)},
                           hyper={"omega_s": ws},
                           nonlinear={"omega_s": (ws, lo / 2, hi * 2, lambda c, v: {f"stribeck@{ws:.6g}": col_stribeck(v)})}))
    return out


FORMS = Forms(v_stribeck, excite_stribeck, params_friction)
