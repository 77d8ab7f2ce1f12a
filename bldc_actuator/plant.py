"""The plant protocol: what :class:`bldc_actuator.scheduler.Scheduler` (and so ``actuator_node``) steps.

A plant is a set of named joints, each an actuator with its q-axis current loop, stepped together in
simulation time. The node never touches the physics directly; it commands, steps and reads a plant. The
default plant, :class:`ActuatorPlant`, is one :class:`bldc_actuator.model.Actuator` per joint; another
implementation (e.g. actuators under MuJoCo bodies) drives the node unchanged if it offers these members.

Required (keep these names)
    ``joints -> list[str]``                        joint names, in the order of every batched call
    ``t_ns -> int``                                simulation time [ns], the same for every joint
    ``set_current_command(joint, i_q_ref)``        q-axis current command [A] (the drive limits it)
    ``set_torque_command(joint, tau_out)``         output torque command [N*m] (-> i_q_ref = tau / (K_t_q N))
    ``set_load_torque(joint, tau_out)``            extra external load at the output [N*m]
    ``step_ns(dt_ns)``                             advance every joint by ``dt_ns`` nanoseconds
    ``outputs(joint) -> dict``                     the keys of :meth:`bldc_actuator.model.Actuator.outputs`:
                                                   ``position_out`` [rad], ``velocity_out`` [rad/s],
                                                   ``effort_out`` [N*m] at the output; ``i_q``, ``i_d``,
                                                   ``i_q_ref`` [A], ``i_phase_a/b/c`` [A], ``v_q``, ``v_d``,
                                                   ``v_limit_q``, ``v_magnitude_q``, ``bus_voltage`` [V],
                                                   ``omega`` [rad/s], ``torque_em`` [N*m] (motor side),
                                                   ``T_winding``, ``T_housing`` [degC],
                                                   ``current_limit_effective`` [A], ``joule_power`` [W],
                                                   ``resistance_phase`` [ohm], ``voltage_saturated``,
                                                   ``tripped`` (bool), ...
Also used by the scheduler (the default plant has them; another plant should too)
    ``all_outputs() -> list[dict]``                ``outputs(j)`` for every joint in ``joints`` order, in
                                                   one call (the scheduler reads it once per period: a
                                                   plant that can batch this should)
    ``params(joint) -> ActuatorParams``            the joint's current model parameters
    ``update_params(joint, params)``               runtime-safe parameter change (bus voltage, limits,
                                                   load, ambient...); the state carries on
    ``reset_fault(joint) -> bool``                 clear a latched over-temperature trip; returns whether
                                                   one was latched
Optional
    ``joint_states() -> list[tuple]``              ``(position_out, velocity_out, effort_out,
                                                   voltage_saturated)`` of every joint in ``joints`` order:
                                                   all the scheduler needs on a period without diagnostics or
                                                   wanted detail topics. Offer it only if it is cheaper than
                                                   ``all_outputs()`` (the default plant's is
                                                   :meth:`bldc_actuator.model.Actuator.joint_state`, the same
                                                   numbers as ``outputs()`` for a fraction of the cost)

Units are SI at this boundary (A, N*m, rad, s, ns for time); commands are finite floats (the scheduler
rejects anything else before it reaches the plant).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from .model import Actuator
from .params import ActuatorParams


@runtime_checkable
class Plant(Protocol):
    """See the module docstring for the meaning and units of each member."""

    @property
    def joints(self) -> list[str]: ...

    @property
    def t_ns(self) -> int: ...

    def set_current_command(self, joint: str, i_q_ref: float) -> None: ...

    def set_torque_command(self, joint: str, tau_out: float) -> None: ...

    def set_load_torque(self, joint: str, tau_out: float) -> None: ...

    def step_ns(self, dt_ns: int) -> None: ...

    def outputs(self, joint: str) -> dict: ...

    def all_outputs(self) -> list[dict]: ...

    def params(self, joint: str) -> ActuatorParams: ...

    def update_params(self, joint: str, params: ActuatorParams) -> None: ...

    def reset_fault(self, joint: str) -> bool: ...


class ActuatorPlant:
    """The default plant: one independent :class:`~bldc_actuator.model.Actuator` per joint (each its own
    motor, drive, gear, thermal and friction parameters), stepped one after another over the same interval.

    >>> plant = ActuatorPlant({"knee": ActuatorParams()})
    >>> plant.set_current_command("knee", 2.0)
    >>> plant.step_ns(1_000_000)
    >>> plant.outputs("knee")["i_q_ref"]
    2.0
    """

    def __init__(self, params: dict[str, ActuatorParams], *, warn: bool = True):
        """``warn``: each joint's Actuator warns where its motor can outrun a complex-vector current loop; False
        where the caller says it (the node logs it per joint)."""
        if not params:
            raise ValueError("ActuatorPlant needs at least one joint")
        self._names = list(params)
        self._acts = {name: Actuator(p, warn=warn) for name, p in params.items()}
        self._list = list(self._acts.values())
        self._steps = [a.step_ns for a in self._list]
        self._outs = [a.outputs for a in self._list]
        self._states = [a.joint_state for a in self._list]
        # simulation time kept here (every joint steps the same interval through step_ns): reading it from
        # the kernel's state array every period cost more than the arithmetic
        self._t_ns = self._list[0].t_ns

    @property
    def joints(self) -> list[str]:
        return list(self._names)

    @property
    def t_ns(self) -> int:
        return self._t_ns

    def actuator(self, joint: str) -> Actuator:
        """The joint's :class:`~bldc_actuator.model.Actuator` (state, energy ledger, ...). Step it only through
        :meth:`step_ns` (the plant keeps the joints, and its clock, together)."""
        return self._acts[joint]

    def set_current_command(self, joint: str, i_q_ref: float) -> None:
        self._acts[joint].set_current_command(i_q_ref)

    def set_torque_command(self, joint: str, tau_out: float) -> None:
        self._acts[joint].set_torque_command(tau_out)

    def set_load_torque(self, joint: str, tau_out: float) -> None:
        self._acts[joint].set_load_torque(tau_out)

    def step_ns(self, dt_ns: int) -> None:
        for step in self._steps:
            step(dt_ns)
        self._t_ns += int(dt_ns)

    def outputs(self, joint: str) -> dict:
        return self._acts[joint].outputs()

    def all_outputs(self) -> list[dict]:
        return [out() for out in self._outs]

    def joint_states(self) -> list[tuple[float, float, float, bool]]:
        return [state() for state in self._states]

    def params(self, joint: str) -> ActuatorParams:
        return self._acts[joint].params

    def update_params(self, joint: str, params: ActuatorParams) -> None:
        self._acts[joint].update_params(params)

    def reset_fault(self, joint: str) -> bool:
        act = self._acts[joint]
        was = bool(act.outputs()["tripped"])
        act.reset_fault()
        return was
