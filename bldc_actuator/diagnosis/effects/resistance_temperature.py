"""Winding resistance rising with temperature.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="resistance_temperature", rank=140,
    description="winding resistance rising with temperature (copper, about +0.39 %/K)",
    equations=("electrical",),
    needs=("voltage_q", "current", "velocity|position", "winding_temperature|housing_temperature"), simulated=True,
    confusable={"magnet_temperature": "the magnet term also changes the torque and back-EMF; spin unloaded when "
                "hot and cold"},
    params=(Param("copper_temperature_coefficient", "1/K", "motor.copper_temperature_coefficient"),),
    story=Story.TEMPERATURE_TREND, level_windows=True, enables=("motor.resistance_temperature_enabled",),
)
