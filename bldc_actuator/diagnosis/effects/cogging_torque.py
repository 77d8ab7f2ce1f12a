"""Cogging torque, locked to the rotor angle.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story, WriteBack

EFFECT = Effect(
    name="cogging_torque", rank=50,
    description="cogging torque: torque ripple locked to the rotor angle (slots x magnets), present without current",
    equations=("mechanical",), needs=("current", "position"), simulated=True,
    confusable={"electrical_angle_ripple": "repeat at a different current: cogging does not scale with "
                "current; sensor-gain ripple does"},
    params=(Param("cogging_order", "", "effects.cogging_order"), Param("cogging_cos_1", "N*m", "effects.cogging_cos[0]"),
            Param("cogging_sin_1", "N*m", "effects.cogging_sin[0]"), Param("amplitude_1", "N*m")),
    story=Story.ANGLE_SPECTRUM, angle_locked=True, writeback=WriteBack.COGGING_SERIES,
    no_form_reason=("no multiple of 2 x pole_pairs stands out of the residual's angle-order spectrum (cogging "
                    "order = lcm(slots, 2p); give effects.cogging_order to test a known order)"),
)
