"""Stribeck friction (the low-speed rise).

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="stribeck_friction", rank=30,
    description="Stribeck friction: extra friction at low speed that fades above the Stribeck velocity",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"coulomb_friction": "slow constant-speed sweeps (0.1-10x the Stribeck velocity)"},
    params=(Param("stribeck_friction", "N*m", "effects.stribeck_friction"),
            Param("stribeck_velocity", "rad/s", "effects.stribeck_velocity")),
    story=Story.VELOCITY,
)
