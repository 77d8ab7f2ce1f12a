"""The torque / back-EMF constant is off.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Story

EFFECT = Effect(
    name="torque_constant_error", rank=80,
    description="the torque / back-EMF constant is off (often a frame convention: sqrt(3/2), sqrt(2), sqrt(3)...)",
    equations=("mechanical", "electrical"), needs=("current", "velocity|position"), simulated=True,
    confusable={"inertia_error": "with a torque sensor, a known load, or voltage_q (back-EMF) the two "
                "separate; from current and motion alone only K_t/J is known"},
    params=(Param("torque_constant_q", "N*m/A", "motor.torque_constant_q"), Param("ratio_to_nominal", ""),
            Param("frame_factor", "")),
    nominal=(("torque_constant_q", "motor.torque_constant_q"),),
    story=Story.CURRENT_TREND, torque_scale=True,
)
