"""Iron (core) loss.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Route

EFFECT = Effect(
    name="iron_loss", rank=220,
    description="iron (core) loss: heat growing with speed, with little current",
    equations=("thermal",), needs=("current", "velocity|position", "winding_temperature|housing_temperature"),
    simulated=False, route=Route.THERMAL,
    confusable={"thermal_parameters": "spin at high speed with no current: only iron loss heats then"},
    params=(Param("hysteresis_loss_coefficient", "W*s/rad", "effects.iron_loss_hysteresis"),
            Param("eddy_loss_coefficient", "W*s^2/rad^2", "effects.iron_loss_eddy")),
    level_windows=True, motion_heat=True,
)
