"""The drive's current controller and its feed-forward differ from the parameter file.

Identified by :mod:`..drive_feedforward` (the closed-loop replay of each drive form, before anything is judged and
again with the judged findings), not by the candidate library; its finding writes the whole form (``updated_fields``).
"""

from __future__ import annotations

from .record import Effect, Param, Route, WriteBack

EFFECT = Effect(
    name="drive_current_controller", rank=230,
    description="the drive's current controller (PI or complex-vector) or its back-EMF/cross-coupling feed-forward "
                "differs from the parameter file",
    equations=("tracking",), needs=("current", "current_command|torque_command", "velocity|position"),
    simulated=True, route=Route.DRIVE_FORM,
    params=(Param("drive_form", ""), Param("current_controller", "", "drive.current_controller"),
            Param("decoupling_enabled", "", "drive.decoupling_enabled")),
    writeback=WriteBack.SETTING,
)
