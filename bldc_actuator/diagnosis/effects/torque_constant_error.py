"""The torque / back-EMF constant is off.

The catalogue record and its regressor forms (``FORMS``: columns, parameter mapping, the frame factor a ratio
matches)."""

from __future__ import annotations

from ... import frames
from .forms import Forms, Variant, sd
from .record import Bounds, Effect, Param, Story

EFFECT = Effect(
    name="torque_constant_error", rank=80,
    description="the torque / back-EMF constant is off (often a frame convention: sqrt(3/2), sqrt(2), sqrt(3)...)",
    equations=("mechanical", "electrical"), needs=("current", "velocity|position"), simulated=True,
    confusable={"inertia_error": "with a torque sensor, a known load, or voltage_q (back-EMF) the two "
                "separate; from current and motion alone only K_t/J is known"},
    params=(Param("torque_constant_q", "N*m/A", "motor.torque_constant_q"), Param("ratio_to_nominal", "", bounds=(Bounds(0.2, 5.0, label="torque constant ratio"),)),
            Param("frame_factor", "")),
    nominal=(("torque_constant_q", "motor.torque_constant_q"),),
    story=Story.CURRENT_TREND, torque_scale=True,
)


#: frame factors a torque-constant error is compared with (fitted K / nominal K): every ratio a K_t read in one
#: frame and entered as another produces, drives on delta motors included (:func:`frames.torque_constant_frame_factors`)
FRAME_FACTORS = {name: value for name, (value, _) in frames.torque_constant_frame_factors().items()}


def match_frame_factor(ratio: float, sigma: float) -> str:
    """Name of the frame factor within max(2 %, 2σ) of ``ratio``, else ``"none"``."""
    best, best_err = "none", float("inf")
    for name, f in FRAME_FACTORS.items():
        err = abs(ratio - f)
        if err <= max(0.02 * f, 2.0 * sigma) and err < best_err:
            best, best_err = name, err
    return best


def col_kt(equations, kappa: float = 1.0):
    """Torque-constant scale κ = K_true/K (coefficient κ - 1). Mechanical (current units): i = P/(κK), so
    the column is -P/(κ̂K) at the current estimate κ̂ (iterated to a fixed point); electrical: K ω."""
    def build(ctx):
        S = ctx.sig
        out = {}
        if "mechanical" in equations:
            out["mechanical"] = -S["P"] / kappa       # divided by K with every mechanical column
        if "electrical" in equations and "v_q" in S:
            out["electrical"] = S["K"] * S["omega"]
        return out
    return build


def _kt_iterate(key, equations):
    return lambda ctx, coef: {key: col_kt(equations, max(0.05, 1.0 + coef))}


def v_kt(ctx, loc):
    """One K for torque and back-EMF (the model has one): both equations when both exist."""
    if "electrical" in ctx.blocks and "mechanical" in ctx.blocks:
        eqs, label = ("mechanical", "electrical"), "same factor on torque and back-EMF"
    elif "mechanical" in ctx.blocks:
        eqs, label = ("mechanical",), "from the torque balance (no voltage)"
    else:
        eqs, label = ("electrical",), "from the back-EMF (no motion equation)"
    key = "kt_" + "_".join(e[:4] for e in eqs)
    return [Variant(EFFECT.name, label, {key: col_kt(eqs)}, hyper={"equations": eqs},
                    iterate=_kt_iterate(key, eqs))]


def params_kt(coef, cov, keys, variant, ctx):
    K0 = ctx.params.motor.torque_constant_q
    ratio = 1.0 + float(coef[0])
    s = sd(cov, 0)
    return {"torque_constant_q": {"value": K0 * ratio, "sd": K0 * s, "unit": "N*m/A", "field": "motor.torque_constant_q"},
            "ratio_to_nominal": {"value": ratio, "sd": s, "unit": "", "field": None},
            "frame_factor": {"value": match_frame_factor(ratio, s), "sd": 0.0, "unit": "", "field": None}}


FORMS = Forms(v_kt, None, params_kt)
