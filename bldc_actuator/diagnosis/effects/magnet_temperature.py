"""Magnet flux falling with temperature.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

from .forms import Forms, Single, excite_temperature, sd
from .record import Bounds, Effect, Param, Story

EFFECT = Effect(
    name="magnet_temperature", rank=150,
    description="magnet flux (torque and back-EMF constant) falling with temperature (NdFeB about -0.1 %/K)",
    equations=("mechanical", "electrical"),
    needs=("current", "velocity|position", "winding_temperature|housing_temperature"), simulated=True,
    confusable={"resistance_temperature": "spin unloaded when hot and when cold: only the flux changes the "
                "back-EMF"},
    params=(Param("magnet_temperature_coefficient", "1/K", "motor.magnet_temperature_coefficient",
                  (Bounds(-0.01, 0.002, label="magnet coefficient"),)),),
    story=Story.TEMPERATURE_TREND, level_windows=True, enables=("motor.magnet_temperature_enabled",),
)


def col_magnet(ctx):
    m = ctx.params.motor
    S = ctx.sig
    dT = S["T_h"] - m.reference_temperature
    out = {"mechanical": -dT * S["P"]}
    if "v_q" in S:
        out["electrical"] = m.torque_constant_q * dT * S["omega"]
    return out


def params_magnet(coef, cov, keys, variant, ctx):
    m = ctx.params.motor
    b0 = m.magnet_temperature_coefficient if m.magnet_temperature_enabled else 0.0
    return {"magnet_temperature_coefficient": {"value": b0 + coef[0], "sd": sd(cov, 0), "unit": "1/K",
                                               "field": "motor.magnet_temperature_coefficient"}}


FORMS = Forms(Single({"magnet": col_magnet}), excite_temperature, params_magnet)
