"""The recorded voltage leads the current by a delay.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="current_loop_delay", rank=200,
    description="the recorded voltage leads the current by a delay (PWM / computation delay)",
    equations=("electrical",), needs=("voltage_q", "current", "velocity|position"), simulated=True,
    confusable={"inductance_error": "current steps recorded at a higher rate than the current loop"},
    params=(Param("delay", "s", "drive.current_loop_delay"),),
    story=Story.ELECTRICAL_CURRENT_TREND, within_loop_period=True,
)
