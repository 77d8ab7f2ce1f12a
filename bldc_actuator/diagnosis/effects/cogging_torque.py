"""Cogging torque, locked to the rotor angle.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

import math

from .forms import Forms, Variant, col_harmonic, excite_angle, sd
from .record import Effect, Param, Story, WriteBack

EFFECT = Effect(
    name="cogging_torque", rank=50,
    description="cogging torque: torque ripple locked to the rotor angle (slots x magnets), present without current",
    equations=("mechanical",), needs=("current", "position"), simulated=True,
    confusable={"electrical_angle_ripple": "repeat at a different current: cogging does not scale with "
                "current; sensor-gain ripple does"},
    params=(Param("cogging_order", "", "effects.cogging_order"), Param("cogging_cos_1", "N*m", "effects.cogging_cos[0]"),
            Param("cogging_sin_1", "N*m", "effects.cogging_sin[0]"), Param("amplitude_1", "N*m")),
    story=Story.ANGLE_SPECTRUM, angle_locked=True, writeback=WriteBack.COGGING_SERIES,
    no_form_reason=("no multiple of 2 x pole_pairs stands out of the residual's angle-order spectrum (cogging "
                    "order = lcm(slots, 2p); give effects.cogging_order to test a known order)"),
)


def cogging_orders(ctx, loc) -> list[int]:
    """The orders tried: the file's ``effects.cogging_order``, then the residual spectrum's peaks that are
    multiples of 2p."""
    p = ctx.params.motor.pole_pairs
    orders = []
    if ctx.params.effects.cogging_order:
        orders.append(int(ctx.params.effects.cogging_order))
    spec = (loc.get("mechanical") or {}).get("order_spectrum") or {}
    # N_c = lcm(slots, 2p) is always a multiple of 2p: other peaks (p, 3p...) are electrical, not cogging
    for pk in spec.get("peaks", [])[:6]:
        o = int(pk["order"])
        if o not in orders and o % (2 * p) == 0:
            orders.append(o)
    return orders


def v_cogging(ctx, loc):
    out = []
    for o in cogging_orders(ctx, loc):
        for nh in (1, 2):
            cols = {}
            for k in range(1, nh + 1):
                cols[f"cog{o}c{k}"] = col_harmonic(o, k, "cos")
                cols[f"cog{o}s{k}"] = col_harmonic(o, k, "sin")
            out.append(Variant(EFFECT.name, f"order {o}, {nh} harmonic{'s' if nh > 1 else ''}", cols,
                               hyper={"order": o, "harmonics": nh}))
    return out


def params_cogging(coef, cov, keys, variant, ctx):
    out = {"cogging_order": {"value": variant.hyper["order"], "sd": 0.0, "unit": "", "field": "effects.cogging_order"}}
    for i, k in enumerate(keys):
        kind = "cos" if "c" in k.split(str(variant.hyper["order"]), 1)[1][:1] else "sin"
        h = int(k[-1])
        out[f"cogging_{kind}_{h}"] = {"value": float(coef[i]), "sd": sd(cov, i), "unit": "N*m",
                                      "field": f"effects.cogging_{kind}[{h - 1}]", "delta": float(coef[i])}
    amp = math.hypot(*(coef[:2])) if len(coef) >= 2 else float("nan")
    out["amplitude_1"] = {"value": amp, "sd": float(max(sd(cov, 0), sd(cov, 1))) if len(coef) >= 2 else float("nan"),
                          "unit": "N*m", "field": None}
    return out


FORMS = Forms(v_cogging, excite_angle(lambda p: 2 * p.motor.pole_pairs), params_cogging)
