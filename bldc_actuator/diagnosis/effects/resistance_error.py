"""The winding resistance is off.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="resistance_error", rank=120,
    description="the winding resistance is off (at the reference temperature)",
    equations=("electrical",), needs=("voltage_q", "current", "velocity|position"), simulated=True,
    confusable={"resistance_temperature": "hold a current while the winding warms, with winding temperature "
                "recorded"},
    params=(Param("phase_resistance", "ohm", "motor.phase_resistance"),),
    nominal=(("phase_resistance", "motor.phase_resistance"),),
    story=Story.ELECTRICAL_CURRENT_TREND,
)
