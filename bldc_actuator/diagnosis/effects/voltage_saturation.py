"""The inverter's voltage limit below the model's.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Route, Story

EFFECT = Effect(
    name="voltage_saturation", rank=170,
    description="the inverter cannot apply the voltage the model allows near the limit (bus sag, modulation "
                "limit): the current stops following its command early",
    equations=("tracking",), needs=("current", "current_command|torque_command", "velocity|position"),
    simulated=False, route=Route.VOLTAGE_LIMIT,
    confusable={"dead_time": "run at high speed with low current, and at low speed with high current"},
    params=(Param("voltage_limit_ratio", "", "drive.modulation_limit"),),
    story=Story.HEADROOM,
)
