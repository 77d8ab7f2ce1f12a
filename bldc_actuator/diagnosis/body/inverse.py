"""The body's torque on each joint: ``mujoco.mj_inverse`` over recorded positions, velocities, accelerations.

The MJCF's mass properties are the nominal. The recorded joints' armature, damping and dry friction
(``frictionloss``) are set to zero here: in the coupled simulator they ARE the actuators' rotor inertia, drag and
friction (:mod:`bldc_actuator.mujoco.coupling`), which each joint's own diagnosis already carries in its
mechanical equation. Constraints (contacts, joint limits, friction loss) are disabled: a fixed-base arm moving
freely. Joint springs and the other joints' passive forces stay the body's.

Inverse dynamics is linear in each body's mass when its rotational inertia is scaled with it (the body's
spatial inertia scales), so :meth:`BodyModel.mass_column` is exact: the change of every joint's torque per kg.
"""

from __future__ import annotations

import copy
import logging
from dataclasses import dataclass

import mujoco
import numpy as np

from ...mujoco.coupling import load_model
from .joints import AXIAL, JointMap, match

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BodyMass:
    """A body whose mass a recorded joint carries: a candidate for a mass error."""

    name: str
    body_id: int
    mass: float             #: nominal [kg]
    joints: tuple[str, ...]  #: the recorded joints it hangs from (their torques move with its mass)


class BodyModel:
    """An MJCF model prepared for inverse dynamics over a multi-joint recording.

    ``mjcf``: a path, an MJCF string or an ``MjModel`` (copied, never changed); ``rename``: recorded joint name ->
    MJCF joint name; ``recording_joints``: the recorded joints, in the order of every array's columns."""

    def __init__(self, mjcf, recording_joints, rename=None):
        m = copy.deepcopy(load_model(mjcf))
        self.joint_map: JointMap = match(recording_joints, m, rename)
        for j in range(m.njnt):
            if int(m.jnt_type[j]) not in AXIAL:
                name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
                raise ValueError(f"--mujoco-model: joint {name!r} is a free or ball joint: a floating base needs "
                                 "its pose and twist, which a joint log does not hold (fixed-base robots only)")
        self.notes: list[str] = []
        self._dof = np.array([jm.dof for jm in self.joint_map.joints])
        self._qadr = np.array([jm.qpos for jm in self.joint_map.joints])
        had = [(jm.model, float(m.dof_armature[jm.dof]), float(m.dof_damping[jm.dof]), float(m.dof_frictionloss[jm.dof]))
               for jm in self.joint_map.joints]
        had = [h for h in had if any(h[1:])]
        if had:
            self.notes.append("the MJCF's armature/damping/frictionloss on " + ", ".join(h[0] for h in had)
                              + " are left out of the body's torque: the actuators' rotor inertia, drag and friction "
                              "are those of their parameter files")
        m.dof_armature[self._dof] = 0.0
        m.dof_damping[self._dof] = 0.0
        m.dof_frictionloss[self._dof] = 0.0
        m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
        self.model = m
        self._data = mujoco.MjData(m)
        if self.joint_map.unrecorded:
            self.notes.append("model joints no recording drives, held at the MJCF's reference pose: "
                              + ", ".join(self.joint_map.unrecorded))

    @property
    def joints(self) -> list[str]:
        """The recorded joints, in the order of every array's columns."""
        return self.joint_map.recording_names

    def torques(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """(n, k) generalized force the body needs on each recorded joint [N·m or N] at the output, for (n, k)
        positions [rad or m], velocities and accelerations of the recorded joints (columns in :attr:`joints`
        order)."""
        q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
        k = len(self._dof)
        if not (q.shape == qd.shape == qdd.shape and q.shape[1] == k):
            raise ValueError(f"body torques: expected (n, {k}) positions, velocities and accelerations, got "
                             f"{q.shape}, {qd.shape}, {qdd.shape}")
        m, d = self.model, self._data
        d.qpos[:] = m.qpos0
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        out = np.empty_like(q)
        qadr, dof = self._qadr, self._dof
        for i in range(len(q)):
            d.qpos[qadr] = q[i]
            d.qvel[dof] = qd[i]
            d.qacc[dof] = qdd[i]
            mujoco.mj_inverse(m, d)
            out[i] = d.qfrc_inverse[dof]
        return out

    def joint_inertia(self, q: np.ndarray, every: int = 10) -> np.ndarray:
        """(k,) each recorded joint's own inertia in the body (the mass matrix's diagonal, armature left out)
        [kg·m² or kg], averaged over the poses ``q`` (n, k) (every ``every``-th): the torque a unit acceleration
        of that joint alone needs, less the torque of none (inverse dynamics is linear in the accelerations)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))[:: max(1, int(every))]
        z = np.zeros_like(q)
        base = self.torques(q, z, z)
        out = np.empty(q.shape[1])
        for k in range(q.shape[1]):
            a = z.copy()
            a[:, k] = 1.0
            out[k] = float(np.mean(self.torques(q, z, a)[:, k] - base[:, k]))
        return out

    def candidates(self) -> list[BodyMass]:
        """Bodies with mass that hang from at least one recorded joint."""
        m = self.model
        jbody = {jm.recording: int(m.jnt_bodyid[jm.joint_id]) for jm in self.joint_map.joints}
        out = []
        for b in range(1, m.nbody):
            if not m.body_mass[b] > 0.0:
                continue
            chain, x = set(), b
            while x > 0:
                chain.add(x)
                x = int(m.body_parentid[x])
            carried = tuple(j for j, jb in jbody.items() if jb in chain)
            if carried:
                name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
                out.append(BodyMass(name, b, float(m.body_mass[b]), carried))
        return out

    def body(self, name: str) -> BodyMass:
        for c in self.candidates():
            if c.name == name:
                return c
        raise ValueError(f"body {name!r}: no body with mass hanging from a recorded joint (have: "
                         f"{', '.join(c.name for c in self.candidates())})")

    def mass_column(self, body: BodyMass, q, qd, qdd, base: np.ndarray | None = None) -> np.ndarray:
        """(n, k) change of each recorded joint's body torque per kg of ``body``'s mass (its rotational inertia
        scaled with it) [N·m/kg]: exact, inverse dynamics being linear in a body's spatial inertia. ``base``: this
        model's :meth:`torques` of the same motion where the caller has it (one inverse-dynamics pass per body
        instead of two)."""
        base = self.torques(q, qd, qdd) if base is None else np.asarray(base, dtype=float)
        with self._scaled(body.body_id, 2.0):
            double = self.torques(q, qd, qdd)
        return (double - base) / body.mass

    def with_mass(self, changes: dict[str, float]) -> "BodyModel":
        """A copy with ``{body name: Δm [kg]}`` added (each body's inertia scaled with its mass)."""
        new = copy.copy(self)
        new.model = copy.deepcopy(self.model)
        new._data = mujoco.MjData(new.model)
        new.notes = list(self.notes)
        for name, dm in changes.items():
            b = self.body(name)
            f = (b.mass + dm) / b.mass
            if not f > 0.0:
                raise ValueError(f"body {name!r}: a mass change of {dm:g} kg leaves {b.mass + dm:g} kg (must stay > 0)")
            new.model.body_mass[b.body_id] *= f
            new.model.body_inertia[b.body_id] *= f
        return new

    class _Scale:
        def __init__(self, model, b, f):
            self.m, self.b, self.f = model, b, f

        def __enter__(self):
            self.mass, self.inertia = float(self.m.body_mass[self.b]), self.m.body_inertia[self.b].copy()
            self.m.body_mass[self.b] *= self.f
            self.m.body_inertia[self.b] *= self.f

        def __exit__(self, *exc):
            self.m.body_mass[self.b] = self.mass
            self.m.body_inertia[self.b] = self.inertia

    def _scaled(self, b: int, f: float):
        return BodyModel._Scale(self.model, b, f)
