"""The q-axis inductance is off.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="inductance_error", rank=130,
    description="the q-axis inductance is off",
    equations=("electrical",), needs=("voltage_q", "current", "velocity|position"), simulated=True,
    confusable={"current_loop_delay": "current steps recorded at a higher rate than the current loop"},
    params=(Param("q_inductance", "H", "motor.q_inductance"),),
    nominal=(("q_inductance", "motor.q_inductance"),),
    story=Story.ELECTRICAL_CURRENT_TREND, within_loop_period=True,
)
