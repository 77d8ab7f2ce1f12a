"""Magnetic saturation: torque per amp falling at high current, as a monotone power law in |i_q|.

The simulator's term (:func:`bldc_actuator.effects.saturation_factor`) is K(i) = K (1 - k_sat s_n(i)) with the shape
s_n(i) = |i| (|i| / 1 A)^(n - 1) (:func:`bldc_actuator.effects.saturation_shape`), in torque AND back-EMF alike:
``effects.kt_saturation`` k_sat [1/A] (the fractional drop per ampere at 1 A) and ``effects.kt_saturation_exponent``
n (1 = the linear law K (1 - k_sat |i|)). The drop at a current I is k_sat s_n(I); it is reported at the recording's
peak current, the readable figure.

Its regressor form is one column in both equations the term enters, one coefficient k_sat:

    mechanical (current units)   r_m = k_sat i s_n(i)          (the torque lost, / K)
    electrical (where v_q is logged)   r_e = -k_sat K ω s_n(i)  (the back-EMF lost: the logged q voltage pins it)

The exponent is a continuous hyper-parameter: forms on a grid of n are offered to the selection (the best on
training data is kept), and the final fit refines n within its grid neighbours (``Variant.nonlinear``, as the
Stribeck velocity), with its uncertainty from the joint covariance. Both k_sat and n are written back.
"""

from __future__ import annotations

import numpy as np

from ... import effects as terms
from .forms import Forms, Variant, sd
from .record import Effect, Param, Story

EFFECT = Effect(
    name="magnetic_saturation", rank=160,
    description="magnetic saturation: torque per amp (and back-EMF per speed) falls at high current, "
                "K (1 - k_sat |i| (|i|/1 A)^(n-1))",
    equations=("mechanical", "electrical"), needs=("current", "velocity|position"), simulated=True,
    confusable={"torque_constant_error": "steps to several current levels: saturation only bends the top"},
    params=(Param("kt_saturation", "1/A", "effects.kt_saturation"),
            Param("kt_saturation_exponent", "1", "effects.kt_saturation_exponent"),
            Param("saturation_drop_at_peak", "1"),
            Param("peak_current", "A")),
    story=Story.CURRENT_TREND,
)

#: the exponents offered to the selection (the final fit refines between neighbours). Saturation sets in at a knee:
#: far below it the iron is linear and K hardly moves, so the drop's slope with |i| is finite at i = 0 and n >= 1
#: (the linear law is the steepest start the form allows). An n < 1 law falls fastest at the smallest currents:
#: not saturation but what a dead band or a friction near zero current does to a torque-per-amp fit.
EXPONENT_GRID = (1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0)
#: how far the refinement may leave the grid's ends (n = 1 is also the lower bound: see above)
EXPONENT_BOUNDS = (1.0, 5.0)
#: the exponent's name: the hyper-parameter, the refined nonlinear parameter and the reported parameter
EXPONENT = "kt_saturation_exponent"
#: the current the drop is reported at: this percentile of |i_q|
PEAK_PERCENTILE = 99.5


def column(n: float):
    """The column builder of the law with exponent ``n``: {mechanical: K i s_n(i), electrical: -K ω s_n(i)}
    (the mechanical part is divided by K into current units by the frame)."""
    def build(ctx):
        S = ctx.sig
        shape = terms.saturation_shape(S["i_col"], n)
        out = {"mechanical": S["K"] * S["i_col"] * shape}
        if "v_q" in S:
            out["electrical"] = -S["K"] * S["omega"] * shape
        return out
    return build


def key(n: float) -> str:
    return f"sat@n={n:.6g}"


def variants(ctx, loc):
    out = []
    grid = EXPONENT_GRID
    for j, n in enumerate(grid):
        lo = grid[j - 1] if j else EXPONENT_BOUNDS[0]
        hi = grid[j + 1] if j + 1 < len(grid) else EXPONENT_BOUNDS[1]
        k = key(n)
        out.append(Variant(EFFECT.name, f"K (1 - k |i|^{n:g})" + (" (linear)" if n == 1.0 else ""),
                           {k: column(n)}, hyper={EXPONENT: n},
                           nonlinear={EXPONENT: (n, lo, hi, lambda c, v, k=k: {k: column(v)})}))
    return out


def excited(ctx):
    i = np.abs(ctx.dsig("i_q"))
    lim = ctx.params.drive.current_limit
    top = float(np.percentile(i, PEAK_PERCENTILE))
    return None if top >= 0.4 * lim else (f"needs high current (99.5th percentile |i_q| = {top:.3g} A, "
                                          f"limit {lim:.3g} A)")


def to_params(coef, cov, keys, variant, ctx):
    """k_sat (the coefficient: a negative value, torque rising with current, has no simulator term), the exponent
    (its sd is the final fit's), and the drop they give at the recording's peak current. The drop's sd is
    shape x sd(k_sat) with k_sat's marginal sd (which carries its correlation with n): an upper bound, the drop at
    the peak being the better-determined combination of the two."""
    k = float(coef[0])
    n = float(variant.hyper.get(EXPONENT, 1.0))
    ok = k > 0
    i_pk = float(np.percentile(np.abs(ctx.dsig("i_q")), PEAK_PERCENTILE))
    shape = float(terms.saturation_shape(i_pk, n))
    return {"kt_saturation": {"value": k, "sd": sd(cov, 0), "unit": "1/A",
                              "field": "effects.kt_saturation" if ok else None, "delta": k},
            EXPONENT: {"value": n, "sd": float("nan"), "unit": "1",
                       "field": "effects.kt_saturation_exponent" if ok else None},
            "saturation_drop_at_peak": {"value": k * shape, "sd": sd(cov, 0) * shape, "unit": "1", "field": None},
            "peak_current": {"value": i_pk, "sd": 0.0, "unit": "A", "field": None}}


def implausible(pars, ctx):
    """The drop at the recording's peak current between -5 % and 60 % (its bound depends on the recorded current)."""
    drop, peak = pars.get("saturation_drop_at_peak"), pars.get("peak_current")
    if drop is None or drop.get("value") is None:
        return None
    v = drop["value"]
    return None if -0.05 <= v <= 0.6 else f"saturation {100 * v:.3g}% at {peak['value']:.3g} A"


FORMS = Forms(variants=variants, excited=excited, to_params=to_params, implausible=implausible)
