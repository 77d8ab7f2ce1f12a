"""The thermal network is off.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Route

EFFECT = Effect(
    name="thermal_parameters", rank=210,
    description="the thermal network (R_wh, R_ha, C_w, C_h) is off",
    equations=("thermal",), needs=("current", "winding_temperature|housing_temperature"), simulated=True,
    route=Route.THERMAL,
    confusable={"iron_loss": "hold current at standstill (no iron loss) and spin at high speed with no current"},
    params=(Param("winding_to_housing_resistance", "K/W", "thermal.winding_to_housing_resistance"),
            Param("housing_to_ambient_resistance", "K/W", "thermal.housing_to_ambient_resistance"),
            Param("winding_heat_capacity", "J/K", "thermal.winding_heat_capacity"),
            Param("housing_heat_capacity", "J/K", "thermal.housing_heat_capacity")),
    nominal=tuple((f, "thermal." + f) for f in ("winding_to_housing_resistance", "housing_to_ambient_resistance",
                                                "winding_heat_capacity", "housing_heat_capacity")),
    bounded_log_fit=True, level_windows=True,
)
