"""Coulomb (dry) friction.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

import numpy as np

from .forms import Forms, Single, frac, friction_columns, sd
from .record import Bounds, Effect, Param, Story

#: a friction torque is not negative (within 3 sd)
NON_NEGATIVE = (Bounds(lo=0.0, lo_sd=3.0),)

EFFECT = Effect(
    name="coulomb_friction", rank=10,
    description="Coulomb (dry) friction: a constant torque opposing the motion, a step at zero speed",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"dead_time": "dead time acts on the voltage equation (needs voltage_q); friction on torque",
                "asymmetric_friction": "move at the same speeds in both directions"},
    params=(Param("coulomb_friction", "N*m", "effects.coulomb_friction", NON_NEGATIVE),),
    story=Story.VELOCITY,
)


def col_fric_sign(ctx):
    return {"mechanical": friction_columns(ctx, 1.0)[:, 0]}


def col_fric_abs(ctx):
    return {"mechanical": friction_columns(ctx, 1.0)[:, 1]}


def excite_friction(ctx):
    """Friction shows as a step at zero speed: motion in both directions (shared by the friction effects)."""
    w = ctx.dsig("omega_s")
    m = np.abs(w) > 2 * ctx.omega_eps
    pos, neg = frac((w > 0) & m), frac((w < 0) & m)
    if min(pos, neg) < 0.03:
        return (f"needs motion in both directions (moving ω>0 {100 * pos:.0f}%, ω<0 {100 * neg:.0f}% of samples)")
    return None


def params_friction(coef, cov, keys, variant, ctx):
    """The friction columns' coefficients (by key: ``fric_sign``, ``fric_abs``, ``stribeck@...``) onto the
    nominal friction parameters (shared by the friction effects)."""
    out = {}
    e = ctx.params.effects
    for i, k in enumerate(keys):
        if k == "fric_sign":
            out["coulomb_friction"] = {"value": e.coulomb_friction + coef[i], "sd": sd(cov, i),
                                       "unit": "N*m", "field": "effects.coulomb_friction", "delta": float(coef[i])}
        elif k == "fric_abs":
            out["friction_asymmetry"] = {"value": e.friction_asymmetry + coef[i], "sd": sd(cov, i),
                                         "unit": "N*m", "field": "effects.friction_asymmetry", "delta": float(coef[i])}
        elif k.startswith("stribeck"):
            out["stribeck_friction"] = {"value": e.stribeck_friction + coef[i], "sd": sd(cov, i),
                                        "unit": "N*m", "field": "effects.stribeck_friction", "delta": float(coef[i])}
    return out


FORMS = Forms(Single({"fric_sign": col_fric_sign}), excite_friction, params_friction)
