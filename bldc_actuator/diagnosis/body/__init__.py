"""Diagnose a robot, not a joint (issue #26): the body's dynamics from its MJCF.

One job per module:

* :mod:`.joints` — the recording's joints matched to the MJCF's hinge/slide joints by name (a rename map).
* :mod:`.inverse` — :class:`.inverse.BodyModel`: ``mujoco.mj_inverse`` over recorded positions, velocities and
  accelerations (the body without the actuators' armature, damping and dry friction, which stay the
  actuators'), and the exact per-kg column of a body's mass.
* :mod:`.motion` — every joint's recorded motion at the output, from the diagnosis's own derivation of the
  speed and acceleration (:func:`..frame.equation_error.prepare`), and the body's torque handed to each joint as
  the known ``load_torque`` input of its mechanical equation.
* :mod:`.mass` — body effects as candidates: a body's mass error fitted jointly over all joints, against the
  per-joint gravity loads it would otherwise be taken for.
* :mod:`.robot` — :func:`.robot.diagnose_robot`: the body's findings, then each joint's diagnosis with the
  corrected body as its known load; one :class:`.robot.RobotReport`.
"""

from __future__ import annotations
