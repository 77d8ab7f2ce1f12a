"""Winding resistance rising with temperature.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

from .forms import Forms, Single, excite_temperature, sd
from .record import Bounds, Effect, Param, Story

EFFECT = Effect(
    name="resistance_temperature", rank=140,
    description="winding resistance rising with temperature (copper, about +0.39 %/K)",
    equations=("electrical",),
    needs=("voltage_q", "current", "velocity|position", "winding_temperature|housing_temperature"), simulated=True,
    confusable={"magnet_temperature": "the magnet term also changes the torque and back-EMF; spin unloaded when "
                "hot and cold"},
    params=(Param("copper_temperature_coefficient", "1/K", "motor.copper_temperature_coefficient",
                  (Bounds(-0.001, 0.01, label="copper coefficient"),)),),
    story=Story.TEMPERATURE_TREND, level_windows=True, enables=("motor.resistance_temperature_enabled",),
)


def col_r_temp(ctx):
    m = ctx.params.motor
    S = ctx.sig
    return {"electrical": m.phase_resistance * (S["T_w"] - m.reference_temperature) * S["i_col"]}


def params_r_temp(coef, cov, keys, variant, ctx):
    m = ctx.params.motor
    a0 = m.copper_temperature_coefficient if m.resistance_temperature_enabled else 0.0
    return {"copper_temperature_coefficient": {"value": a0 + coef[0], "sd": sd(cov, 0), "unit": "1/K",
                                               "field": "motor.copper_temperature_coefficient"}}


FORMS = Forms(Single({"r_temp": col_r_temp}), excite_temperature, params_r_temp)
