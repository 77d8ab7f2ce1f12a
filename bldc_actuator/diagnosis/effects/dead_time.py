"""Inverter dead time.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Bounds, Effect, Param, Story

EFFECT = Effect(
    name="dead_time", rank=190,
    description="inverter dead time: the applied voltage falls short by a constant times the sign of the current",
    equations=("electrical",), needs=("voltage_q", "current", "velocity|position"), simulated=True,
    confusable={"coulomb_friction": "friction acts on torque: compare the voltage equation at standstill "
                "with current of both signs"},
    params=(Param("dead_time_voltage", "V", bounds=(Bounds(lo=0.0, lo_sd=3.0),)), Param("dead_time", "s", "drive.dead_time"),
            Param("dead_time_current_band", "A", "drive.dead_time_current_band")),
    story=Story.ELECTRICAL_CURRENT_TREND, replay_form=True,
)
