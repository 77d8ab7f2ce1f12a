"""Coulomb (dry) friction.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="coulomb_friction", rank=10,
    description="Coulomb (dry) friction: a constant torque opposing the motion, a step at zero speed",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"dead_time": "dead time acts on the voltage equation (needs voltage_q); friction on torque",
                "asymmetric_friction": "move at the same speeds in both directions"},
    params=(Param("coulomb_friction", "N*m", "effects.coulomb_friction"),),
    story=Story.VELOCITY,
)
