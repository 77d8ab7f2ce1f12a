"""Direction-dependent friction.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="asymmetric_friction", rank=20,
    description="direction-dependent friction: different dry friction for positive and negative motion",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"position_dependent_load": "hold still at several angles, or move in both directions over "
                "the same angles: a load depends on angle, friction on direction",
                "coulomb_friction": "move at the same speeds in both directions"},
    params=(Param("coulomb_friction", "N*m", "effects.coulomb_friction"),
            Param("friction_asymmetry", "N*m", "effects.friction_asymmetry")),
    story=Story.VELOCITY,
)
