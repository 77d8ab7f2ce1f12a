"""Magnet flux falling with temperature.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="magnet_temperature", rank=150,
    description="magnet flux (torque and back-EMF constant) falling with temperature (NdFeB about -0.1 %/K)",
    equations=("mechanical", "electrical"),
    needs=("current", "velocity|position", "winding_temperature|housing_temperature"), simulated=True,
    confusable={"resistance_temperature": "spin unloaded when hot and when cold: only the flux changes the "
                "back-EMF"},
    params=(Param("magnet_temperature_coefficient", "1/K", "motor.magnet_temperature_coefficient"),),
    story=Story.TEMPERATURE_TREND, level_windows=True, enables=("motor.magnet_temperature_enabled",),
)
