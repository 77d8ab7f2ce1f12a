"""Viscous damping.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="viscous_friction", rank=40,
    description="viscous damping: friction torque growing in proportion to speed",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"iron_loss": "iron loss also heats the stator: record temperatures at high speed, low current"},
    params=(Param("viscous_damping", "N*m*s/rad", "motor.viscous_damping"),),
    story=Story.VELOCITY,
)
