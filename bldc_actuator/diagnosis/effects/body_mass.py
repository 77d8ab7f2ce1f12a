"""A body of the robot's multibody model (a link, a payload) heavier or lighter than the MJCF says.

Found by the robot route (:mod:`bldc_actuator.diagnosis.body`), never per joint: the MJCF's inverse dynamics is
linear in each body's mass with its inertia scaled alongside, so "body b is Δm heavier" is one column on every
joint's mechanical equation (the change of that joint's inverse-dynamics torque per kg), fitted jointly over
all joints: one parameter, many equations. Written back to the MJCF (``body_mass`` and ``body_inertia`` of that
body), not to an actuator's parameter file."""

from __future__ import annotations

from .record import Effect, Param, Route, WriteBack

EFFECT = Effect(
    name="body_mass", rank=300,
    description="a body of the multibody model (link or payload) whose mass differs from the MJCF's",
    equations=("body",), needs=("current", "position"), simulated=True, route=Route.BODY,
    confusable={"position_dependent_load": "move the other joints while this one holds: a body's mass moves "
                "the torque of every joint it hangs from with the whole arm's pose, a per-joint gravity load "
                "only with that joint's own angle"},
    params=(Param("delta_mass", "kg"), Param("mass", "kg")),
    external_load=True, writeback=WriteBack.NONE,
)
