"""Torque ripple locked to the electrical angle (current sensors, flux harmonics).

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

import math

from ... import effects as terms
from .forms import Forms, Variant, excite_angle, resolvable, sd
from .record import Effect, Story, WriteBack

EFFECT = Effect(
    name="electrical_angle_ripple", rank=60,
    description="torque ripple locked to the ELECTRICAL angle (current-sensor offset at order p, gain mismatch at "
                "2p, flux harmonics / dead time at 6p)",
    equations=("mechanical", "electrical"), needs=("current", "position"), simulated=False,
    confusable={"cogging_torque": "repeat at a different current: cogging does not scale with current"},
    # parameters named by form and order: <form>_order_<k>_amplitude / _phase (form: sensor_offset,
    # sensor_gain_ripple, flux_harmonic, torque_ripple)
    story=Story.ANGLE_SPECTRUM, angle_locked=True, sensor_side=True, writeback=WriteBack.CURRENT_SENSORS,
)


def col_eripple(order, which, kind):
    """Electrical-angle ripple, coefficient in A (sensor) or per unit (flux), shared by both equations:

    offset  current-sensor offsets: i_meas = i_true + δ cos(pθ+φ) -> mechanical (current units) +δ·cos,
            voltage -R δ·cos (the loop regulates the measured current, so the true one carries -δ)
    gain    sensor gain mismatch: i_meas = i_true (1 + g cos(2pθ+φ)) -> +g i cos, voltage -R g i cos
    flux    flux harmonic: torque and back-EMF x (1 + h cos(6pθ+φ)) -> -h i cos, voltage +K ω h cos
    """
    def build(ctx):
        S = ctx.sig
        b = terms.angle_harmonic_basis(S["theta"], order, 1)[:, 0 if which == "cos" else 1]
        b = b * resolvable(ctx, order)
        out = {}
        if kind == "offset":
            out["mechanical"] = S["K"] * b                      # /K -> current units
            if "v_q" in S:
                out["electrical"] = -S["R"] * b
        elif kind == "gain":
            out["mechanical"] = S["K"] * S["i_col"] * b
            if "v_q" in S:
                out["electrical"] = -S["R"] * S["i_col"] * b
        elif kind == "flux":
            out["mechanical"] = -S["K"] * S["i_col"] * b
            if "v_q" in S:
                out["electrical"] = S["K"] * S["omega"] * b
        else:   # a torque ripple independent of current
            out["mechanical"] = b
        return out
    return build


def v_eripple(ctx, loc):
    p = ctx.params.motor.pole_pairs
    forms = [("current-sensor offset (order p)", p, "offset", "A"),
             ("current-sensor gain mismatch (order 2p, proportional to current)", 2 * p, "gain", ""),
             ("flux harmonic (order 6p, torque and back-EMF)", 6 * p, "flux", ""),
             ("torque ripple at order 6p (independent of current)", 6 * p, "torque", "N*m")]
    out = []
    for label, order, kind, unit in forms:
        cols = {f"er{order}{kind}cos": col_eripple(order, "cos", kind),
                f"er{order}{kind}sin": col_eripple(order, "sin", kind)}
        out.append(Variant(EFFECT.name, label, cols,
                           hyper={"order": order, "kind": kind, "unit": unit,
                                  "current_weighted": kind in ("gain", "flux")}, additive=True))
    return out


def params_eripple(coef, cov, keys, variant, ctx):
    o = variant.hyper["order"]
    kind = variant.hyper.get("kind", "torque")
    unit = variant.hyper.get("unit", "")
    name = {"offset": "sensor_offset", "gain": "sensor_gain_ripple", "flux": "flux_harmonic",
            "torque": "torque_ripple"}.get(kind, "ripple")
    amp = math.hypot(coef[0], coef[1])
    ph = math.atan2(-coef[1], coef[0])     # a cos + b sin = A cos(kθ + φ)
    return {f"{name}_order_{o}_amplitude": {"value": amp, "sd": max(sd(cov, 0), sd(cov, 1)), "unit": unit,
                                            "field": None},
            f"{name}_order_{o}_phase": {"value": ph, "sd": float("nan"), "unit": "rad", "field": None},
            # per form: several forms of this effect may be accepted together, and their parameters are merged
            # into one dict per effect (issue #14: the last form's coefficients were written for every form)
            f"_{kind}_cos": {"value": float(coef[0]), "sd": sd(cov, 0), "unit": unit, "field": None},
            f"_{kind}_sin": {"value": float(coef[1]), "sd": sd(cov, 1), "unit": unit, "field": None}}


FORMS = Forms(v_eripple, excite_angle(lambda p: p.motor.pole_pairs), params_eripple)
