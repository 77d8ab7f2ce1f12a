"""Magnetic saturation: torque per amp falling at high current.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="magnetic_saturation", rank=160,
    description="magnetic saturation: torque per amp falls at high current",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"torque_constant_error": "steps to several current levels: saturation only bends the top"},
    params=(Param("kt_saturation", "1/A", "effects.kt_saturation"),),
    story=Story.CURRENT_TREND,
)
