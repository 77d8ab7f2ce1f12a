"""How the drive shares the voltage circle between d and q.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Param, Route, WriteBack

EFFECT = Effect(
    name="voltage_limit_mode", rank=180,
    description="the drive shares the voltage circle between d and q differently from the model (proportional "
                "scaling, d or q priority, field weakening): only visible where the voltage demand reaches the "
                "circle",
    equations=("tracking",), needs=("current", "current_command|torque_command", "velocity|position"),
    simulated=True, route=Route.DRIVE_MODE,
    confusable={"voltage_saturation": "run at the top speed with the d current recorded: the modes differ in "
                "i_d, a lower limit does not"},
    params=(Param("voltage_limit_mode", "", "drive.voltage_limit_mode"),),
    writeback=WriteBack.SETTING,
)
