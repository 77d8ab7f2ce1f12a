"""The rotor + load inertia is off.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param

EFFECT = Effect(
    name="inertia_error", rank=90,
    description="the rotor + load inertia is off",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"torque_constant_error": "record voltage_q (back-EMF gives K directly) or a known load / torque "
                "sensor"},
    params=(Param("rotor_inertia", "kg*m^2", "motor.rotor_inertia"),),
    nominal=(("rotor_inertia", "motor.rotor_inertia"),),
)
