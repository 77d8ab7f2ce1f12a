"""An MJCF model's bodies driven by this project's actuators, stepped in lock-step.

Split of the physics (one implementation of each equation, nothing copied):

* MuJoCo integrates the mechanics of the whole multibody. Each coupled joint gets the actuator's rotor inertia
  reflected through the gear as its armature (``J N²``), its viscous and eddy-current drag as damping
  (``(b + c_e) N²``) and its symmetric Coulomb and hysteresis drag as the joint's dry friction
  (``frictionloss = (τ_c + τ_h) N``, a MuJoCo constraint: it sticks and breaks away). The rest of the friction
  law (:func:`bldc_actuator.effects.friction_magnitude`: asymmetry, Stribeck) is applied explicitly with the
  sign of the joint's speed, as an applied force.
* The kernel (:mod:`bldc_actuator.kernel`, prescribed-motion mode) advances the drive (PI current loop at its
  own rate, voltage circle, limits, derating), the currents and the thermal network over each body step with
  the joint's speed as its rotor speed: ``ω(t) = N (q̇_k + a_k t)``, ``a_k = (q̇_k - q̇_{k-1})/h`` (the body's last
  acceleration, so the speed ramp is extrapolated, not held). The step's mean electromagnetic torque
  ``N ∫K i_q dt / h`` is then applied to the joint (``qfrc_applied``) for the SAME body step: no one-step lag
  (the torque the body receives over [t_k, t_k+h] is the one the drive produced over that interval).

Energy: the kernel's ledger closes on the electrical side (electrical in = Joule + Δ magnetic energy + magnetic
work ∫K ω i_q dt); the body receives ``Σ τ̄ Δq``. Their difference (``CoupledLedger.coupling``) is the price of the
predicted speed ramp, reported, never hidden; test/test_mujoco.py shows it small.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import mujoco
import numpy as np

from .. import effects
from ..model import BatchActuator, warn_current_loop
from ..params import ActuatorParams, load_preset

log = logging.getLogger(__name__)

_JOINT_TYPES = {int(mujoco.mjtJoint.mjJNT_HINGE): "hinge", int(mujoco.mjtJoint.mjJNT_SLIDE): "slide"}


@dataclass(frozen=True)
class JointState:
    """One coupled joint at the present time: the body's state and every actuator output."""

    position: float     #: joint position [rad or m] (the body's)
    velocity: float     #: joint velocity [rad/s or m/s]
    effort: float       #: mean actuator torque applied to the joint over the last body step [N·m or N]
    outputs: dict       #: the actuator's outputs (:meth:`CoupledSim.outputs`)


@dataclass(frozen=True)
class CoupledLedger:
    """Energies since the start [J], summed over the coupled joints and the whole body."""

    electrical_in: float    #: ∫ v·i dt from the inverters
    joule: float            #: ∫ R |i|² dt
    magnetic: float         #: Δ ½ L |i|² (now minus at the start)
    magnetic_work: float    #: ∫ K ω i_q dt at the speed the kernel saw (the body's ramp)
    body_work: float        #: Σ τ̄ Δq: work of the actuator torques on the joints
    load_work: float        #: Σ τ_load Δq: work done against the external load torques
    passive_work: float     #: Σ (damping + dry friction + constraint forces) · Δq (negative: dissipated)
    kinetic: float          #: Δ kinetic energy of the multibody (armature included)
    potential: float        #: Δ potential energy (gravity, springs)

    @property
    def electrical_residual(self) -> float:
        """Electrical in minus Joule, magnetic energy and magnetic work (round-off)."""
        return self.electrical_in - self.joule - self.magnetic - self.magnetic_work

    @property
    def coupling(self) -> float:
        """Magnetic work the kernel converted minus the work the body received (the coupling's error)."""
        return self.magnetic_work - self.body_work

    @property
    def body_residual(self) -> float:
        """Work on the body minus its change of energy (MuJoCo's integrator error)."""
        return self.body_work - self.load_work + self.passive_work - self.kinetic - self.potential


def _as_params(value, joint: str, loaded: dict) -> ActuatorParams:
    if isinstance(value, ActuatorParams):
        return value
    if isinstance(value, (str, Path)):
        if str(value) not in loaded:                  # one parse per preset or file, however many joints
            loaded[str(value)] = load_preset(value)
        return loaded[str(value)]
    raise TypeError(f"actuators[{joint!r}]: expected ActuatorParams, a preset name or a parameter file path, "
                    f"got {type(value).__name__}")


def _checked(p: ActuatorParams, joint: str) -> ActuatorParams:
    for field in ("gravity_torque", "spring_stiffness"):
        if getattr(p.load, field) != 0.0:
            raise ValueError(f"actuators[{joint!r}]: load.{field} must be 0 when a body is coupled "
                             f"(the MJCF model carries gravity and springs), got {getattr(p.load, field)}")
    return p


def load_model(mjcf) -> mujoco.MjModel:
    """An ``MjModel`` from a path to an MJCF file, an MJCF string or a model (returned as is)."""
    if isinstance(mjcf, mujoco.MjModel):
        return mjcf
    text = str(mjcf)
    if isinstance(mjcf, Path) or not text.lstrip().startswith("<"):
        path = Path(text)
        if not path.exists():
            raise FileNotFoundError(f"mujoco.model: no MJCF file {text!r}")
        return mujoco.MjModel.from_xml_path(str(path))
    return mujoco.MjModel.from_xml_string(text)


class CoupledSim:
    """An MJCF model with an actuator on each named hinge/slide joint, stepped in lock-step.

    >>> sim = CoupledSim("config/two_link_leg.xml", {"hip": "ak80_9", "knee": "ak80_9"})
    >>> sim.set_torque_command("knee", 5.0)
    >>> sim.step(0.1)
    >>> sim.joint_state("knee").position

    Also the plant protocol the node's scheduler steps: :attr:`joints`, :meth:`set_current_command`,
    :meth:`set_torque_command`, :meth:`set_load_torque`, :meth:`step_ns`, :attr:`t_ns`, :meth:`outputs`.
    """

    def __init__(self, mjcf, actuators: Mapping[str, Any], *, timestep: float | None = None, warn: bool = True):
        """``warn``: the ``ParameterWarning`` of a complex-vector current loop the motor can outrun
        (:func:`..model.warn_current_loop`) for the joints given as :class:`ActuatorParams` (a preset or file was
        warned about where it was read, with its name); False where the caller says it (the node logs it per
        joint)."""
        if not actuators:
            raise ValueError("actuators: expected at least one joint name -> parameters")
        self.model = load_model(mjcf)
        m = self.model
        if timestep is not None:
            if not (timestep > 0.0 and math.isfinite(timestep)):
                raise ValueError(f"timestep: expected a body step > 0 s, got {timestep!r}")
            m.opt.timestep = timestep
        self._h_ns = int(round(m.opt.timestep * 1e9))
        if self._h_ns <= 0:
            raise ValueError(f"option.timestep: expected at least 1 ns, got {m.opt.timestep!r} s")
        m.opt.timestep = self._h_ns * 1e-9
        self._h = self._h_ns * 1e-9
        self.data = mujoco.MjData(m)
        self._joints: list[str] = list(actuators)
        self._params: list[ActuatorParams] = []
        dofs, qadrs, loaded = [], [], {}
        for name in self._joints:
            jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
            if jid < 0:
                have = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)]
                raise ValueError(f"actuators: no joint named {name!r} in the MJCF model (have: {have})")
            if int(m.jnt_type[jid]) not in _JOINT_TYPES:
                raise ValueError(f"actuators[{name!r}]: expected a hinge or slide joint, got joint type "
                                 f"{int(m.jnt_type[jid])} (free and ball joints have no single axis)")
            p = _checked(_as_params(actuators[name], name, loaded), name)
            self._params.append(p)
            dofs.append(int(m.jnt_dofadr[jid]))
            qadrs.append(int(m.jnt_qposadr[jid]))
        self._dof = np.array(dofs)
        self._qadr = np.array(qadrs)
        self._index = {name: k for k, name in enumerate(self._joints)}
        for k, dof in enumerate(dofs):
            had = (float(m.dof_armature[dof]), float(m.dof_damping[dof]), float(m.dof_frictionloss[dof]))
            if any(had):
                log.warning("joint %s: the MJCF armature/damping/frictionloss %s are replaced by the actuator's "
                            "(rotor inertia, drag and friction through the gear)", self._joints[k], had)
        self._apply_params()
        self._load = np.zeros(len(self._joints))
        if warn:
            warn_current_loop([p for j, p in zip(self._joints, self._params)
                               if isinstance(actuators[j], ActuatorParams)])
        self.actuators = BatchActuator(self._params, warn=False)
        self._cmd_q = np.zeros(len(self._joints))
        self._cmd_dirty = False
        mujoco.mj_forward(m, self.data)
        self._v_prev = self.data.qvel[self._dof].copy()
        self._effort = np.zeros(len(self._joints))
        self._t_ns = 0
        self._out_cache: tuple[int, dict] | None = None
        self._restart_ledger()

    def _restart_ledger(self) -> None:
        self._e0 = self._body_energy()
        self._w_body = self._w_load = self._w_passive = 0.0
        self._mag0 = self._magnetic()
        self._e_act0 = (float(np.sum(self.actuators.energy.electrical_in)), float(np.sum(self.actuators.energy.joule)),
                        float(np.sum(self.actuators.magnetic_work)))

    @property
    def joints(self) -> list[str]:
        """The coupled joints, in the order of every batched call."""
        return list(self._joints)

    def set_pose(self, positions: Mapping[str, float]) -> None:
        """Place joints (any of the model's hinge/slide joints, by name) at rest at the given positions [rad or m],
        before or between runs; the energy ledger restarts from this state."""
        m, d = self.model, self.data
        for name, value in positions.items():
            jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
            if jid < 0 or int(m.jnt_type[jid]) not in _JOINT_TYPES:
                raise ValueError(f"set_pose: no hinge or slide joint named {name!r}")
            if not math.isfinite(value):
                raise ValueError(f"set_pose[{name!r}]: expected a finite position, got {value!r}")
            d.qpos[m.jnt_qposadr[jid]] = value
            d.qvel[m.jnt_dofadr[jid]] = 0.0
        mujoco.mj_forward(m, d)
        self._v_prev = d.qvel[self._dof].copy()
        self._out_cache = None
        self._restart_ledger()

    def _apply_params(self) -> None:
        """The parameters' mechanics into the body (reflected rotor inertia, drag, symmetric dry friction) and
        the per-joint constants of the coupling."""
        m, ps = self.model, self._params
        for name, p in zip(self._joints, ps):
            if p.gear.transmission_stiffness > 0.0:   # the body integrates the joint: its gear must be rigid
                raise ValueError(f"{name}: gear.transmission_stiffness {p.gear.transmission_stiffness:g} N*m/rad: the "
                                 f"MuJoCo coupling needs a rigid transmission (0); model the compliance in the MJCF "
                                 f"(a joint spring between two bodies) instead")
        self._N = np.array([p.gear.gear_ratio for p in ps])
        self._Kt_N = np.array([p.motor.torque_constant_q * p.gear.gear_ratio for p in ps])   # torque -> current
        for p, dof, N in zip(ps, self._dof, self._N):
            m.dof_armature[dof] = p.motor.rotor_inertia * N * N
            m.dof_damping[dof] = (p.motor.viscous_damping + p.effects.iron_loss_eddy) * N * N
            m.dof_frictionloss[dof] = (p.effects.coulomb_friction + p.effects.iron_loss_hysteresis) * N
        mujoco.mj_setConst(m, mujoco.MjData(m))   # the constants derived from them (dof_M0, invweight, ...)
        self._fric = np.array([[p.effects.coulomb_friction, p.effects.friction_asymmetry,
                                p.effects.stribeck_friction, p.effects.stribeck_velocity] for p in ps])
        self._explicit_friction = bool(np.any(self._fric[:, 1]) or np.any(self._fric[:, 2]))
        self._load0 = np.array([p.load.load_torque for p in ps])
        self._load_total = self._load0 + getattr(self, "_load", 0.0)

    def params(self, joint: str) -> ActuatorParams:
        """The joint's actuator parameters."""
        return self._params[self._k(joint)]

    def update_params(self, joint: str, params: ActuatorParams) -> None:
        """Replace the joint's actuator parameters at run time (bus voltage, limits, friction, ambient...); the
        state carries on, the body takes the new inertia, drag and friction."""
        k = self._k(joint)
        self._params[k] = _checked(params, joint)
        self.actuators.update_params(self._params)
        self._apply_params()
        self._out_cache = None

    def reset_fault(self, joint: str) -> bool:
        """Clear the joint's latched over-temperature trip; returns whether one was latched."""
        self._out_cache = None
        return bool(self.actuators.reset_fault(self._k(joint))[self._k(joint)])

    # -- commands --------------------------------------------------------------------------------------------

    def _k(self, joint: str) -> int:
        k = self._index.get(joint)
        if k is None:
            raise ValueError(f"joint: no coupled joint {joint!r} (have: {', '.join(self._joints)})")
        return k

    def set_current_command(self, joint: str, i_q_ref: float) -> None:
        """q-axis current command [A] of the joint's actuator (limited by its drive)."""
        if not math.isfinite(i_q_ref):
            raise ValueError(f"current command {joint}: expected a finite q-axis current [A], got {i_q_ref!r}")
        self._cmd_q[self._k(joint)] = i_q_ref
        self._cmd_dirty = True                 # handed to the drives at the next body step, all joints at once

    def set_torque_command(self, joint: str, tau_out: float) -> None:
        """Output torque command [N·m] → ``i_q_ref = τ/(K_t_q N)`` with the nominal constant."""
        if not math.isfinite(tau_out):
            raise ValueError(f"torque command {joint}: expected a finite output torque [N*m], got {tau_out!r}")
        k = self._k(joint)
        self._cmd_q[k] = tau_out / self._Kt_N[k]
        self._cmd_dirty = True

    def set_torque_commands(self, tau_out) -> None:
        """Output torque commands [N·m] of every joint at once, in :attr:`joints` order."""
        tau = np.asarray(tau_out, dtype=float)
        if tau.shape != (len(self._joints),) or not np.all(np.isfinite(tau)):
            raise ValueError(f"torque commands: expected {len(self._joints)} finite output torques [N*m] in "
                             f"joints order, got {tau_out!r}")
        self._cmd_q[:] = tau / self._Kt_N
        self._cmd_dirty = True

    def set_load_torque(self, joint: str, tau_out: float) -> None:
        """Extra external load torque at the joint [N·m] (opposes positive motion), on top of the body's own."""
        if not math.isfinite(tau_out):
            raise ValueError(f"load torque {joint}: expected a finite output torque [N*m], got {tau_out!r}")
        self._load[self._k(joint)] = tau_out
        self._load_total = self._load0 + self._load

    # -- stepping --------------------------------------------------------------------------------------------

    @property
    def t_ns(self) -> int:
        return self._t_ns

    @property
    def t(self) -> float:
        return self._t_ns * 1e-9

    @property
    def timestep(self) -> float:
        """The body step [s] (MJCF ``option/timestep``); the drive's ticks run inside it."""
        return self._h

    def step(self, dt: float) -> None:
        """Advance ``dt`` seconds: a whole number of body steps."""
        if not (dt >= 0.0 and math.isfinite(dt)):
            raise ValueError(f"dt: expected a finite duration >= 0 s, got {dt!r}")
        self.step_ns(int(round(dt * 1e9)))

    def step_ns(self, dt_ns: int) -> None:
        """Advance ``dt_ns`` nanoseconds: a whole number of body steps (``option/timestep``)."""
        n, rest = divmod(int(dt_ns), self._h_ns)
        if rest:
            raise ValueError(f"dt: expected a multiple of the body step {self._h_ns} ns, got {dt_ns} ns")
        for _ in range(n):
            self._body_step()

    def _body_step(self) -> None:
        m, d, act, h, N = self.model, self.data, self.actuators, self._h, self._N
        q = d.qpos[self._qadr]
        v = d.qvel[self._dof]
        a = (v - self._v_prev) / h
        if self._cmd_dirty:
            act.set_current_command(self._cmd_q)
            self._cmd_dirty = False
        act.prescribe_motion(N * v, N * a, N * q)
        imp0 = act.impulse_em
        act.step_ns(self._h_ns)
        tau = N * (act.impulse_em - imp0) / h
        load = self._load_total
        frc = tau - load
        fric = None
        if self._explicit_friction:   # the friction law beyond the symmetric Coulomb part the joint carries
            f = self._fric
            sgn = np.sign(v)
            excess = effects.friction_magnitude(sgn, np.abs(N * v), f[:, 0], f[:, 1], f[:, 2], f[:, 3]) - f[:, 0]
            fric = np.where(sgn != 0.0, -sgn * excess * N, 0.0)
            frc = frc + fric
        d.qfrc_applied[self._dof] = frc
        mujoco.mj_step(m, d)
        dq = d.qpos[self._qadr] - q
        self._w_body += float(tau @ dq)
        self._w_load += float(load @ dq)
        # every dof (a free base too): passive (springs are potential energy) and constraint forces, the damping
        # at the new speed (MuJoCo's Euler integrates it implicitly), and the coupled joints' explicit friction
        qvel = d.qvel
        self._w_passive += float((d.qfrc_passive - d.qfrc_spring - d.qfrc_damper + d.qfrc_constraint
                                  - m.dof_damping * qvel) @ qvel) * h + (float(fric @ dq) if fric is not None else 0.0)
        self._v_prev = v
        self._effort = tau
        self._t_ns += self._h_ns

    # -- state -----------------------------------------------------------------------------------------------

    def outputs(self, joint: str) -> dict[str, Any]:
        """Every output :meth:`Actuator.outputs` has, for the joint's actuator, with the body's position and
        velocity at the output (``position_out``, ``velocity_out``) and ``effort_applied`` (the mean torque the
        joint received over the last body step [N·m])."""
        k = self._k(joint)
        if self._out_cache is None or self._out_cache[0] != self._t_ns:
            self._out_cache = (self._t_ns, self.actuators.outputs())
        out = {key: (val[k].item() if isinstance(val, np.ndarray) and val.ndim else val)
               for key, val in self._out_cache[1].items()}
        d = self.data
        out["position_out"] = float(d.qpos[self._qadr[k]])
        out["velocity_out"] = float(d.qvel[self._dof[k]])
        out["effort_applied"] = float(self._effort[k])
        return out

    def all_outputs(self) -> list[dict[str, Any]]:
        """:meth:`outputs` of every joint, in :attr:`joints` order."""
        return [self.outputs(j) for j in self._joints]

    def joint_state(self, joint: str) -> JointState:
        """Position, velocity and applied effort at the output, and every actuator output."""
        out = self.outputs(joint)
        return JointState(position=out["position_out"], velocity=out["velocity_out"],
                          effort=out["effort_applied"], outputs=out)

    def body_state_labels(self) -> tuple[str, ...]:
        """Names of :meth:`body_state`'s entries: every ``qpos`` then every ``qvel`` entry of the whole model
        (``qpos.<joint>`` for a hinge/slide, ``qpos.<joint>.x``...``.qz`` for a free joint, ...)."""
        m = self.model
        pos_suffix = {0: (".x", ".y", ".z", ".qw", ".qx", ".qy", ".qz"), 1: (".qw", ".qx", ".qy", ".qz")}
        vel_suffix = {0: (".vx", ".vy", ".vz", ".wx", ".wy", ".wz"), 1: (".wx", ".wy", ".wz")}
        qpos, qvel = [], []
        for j in range(m.njnt):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
            t = int(m.jnt_type[j])
            qpos += [f"qpos.{name}{s}" for s in pos_suffix.get(t, ("",))]
            qvel += [f"qvel.{name}{s}" for s in vel_suffix.get(t, ("",))]
        return tuple(qpos + qvel)

    def body_state(self) -> np.ndarray:
        """The whole multibody's state now: ``qpos`` then ``qvel`` (see :meth:`body_state_labels`), SI."""
        return np.concatenate((self.data.qpos, self.data.qvel))

    def _body_energy(self) -> tuple[float, float]:
        m, d = self.model, self.data
        mujoco.mj_fwdPosition(m, d)
        mujoco.mj_energyPos(m, d)
        mujoco.mj_energyVel(m, d)
        return float(d.energy[0]), float(d.energy[1])

    def _magnetic(self) -> float:
        i = self.actuators.field("i")
        L = np.array([p.motor.q_inductance for p in self._params])
        return float(np.sum(0.5 * L * np.abs(i) ** 2))

    @property
    def energy(self) -> CoupledLedger:
        """The energy ledger since the start (see :class:`CoupledLedger`)."""
        led = self.actuators.energy
        pot, kin = self._body_energy()
        e_in0, joule0, work0 = self._e_act0
        return CoupledLedger(
            electrical_in=float(np.sum(led.electrical_in)) - e_in0, joule=float(np.sum(led.joule)) - joule0,
            magnetic=self._magnetic() - self._mag0,
            magnetic_work=float(np.sum(self.actuators.magnetic_work)) - work0,
            body_work=self._w_body, load_work=self._w_load, passive_work=self._w_passive,
            kinetic=kin - self._e0[1], potential=pot - self._e0[0])
