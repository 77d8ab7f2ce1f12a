"""A load depending on the output angle (gravity, spring) plus a constant.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="position_dependent_load", rank=70,
    description="a load that depends on the output angle (gravity, spring) plus a constant load",
    equations=("mechanical",), needs=("current", "position"), simulated=True,
    confusable={"asymmetric_friction": "hold still at several angles, or move in both directions over the "
                "same angles"},
    params=(Param("gravity_torque", "N*m", "load.gravity_torque"), Param("gravity_phase", "rad", "load.gravity_phase"),
            Param("spring_stiffness", "N*m/rad", "load.spring_stiffness"),
            Param("load_torque", "N*m", "load.load_torque")),
    story=Story.VELOCITY, external_load=True,
)
