"""Every recorded joint's motion at the output, and the body's torque handed to each joint as a known input.

The motion comes from the diagnosis's own derivation (:func:`..frame.equation_error.prepare`: the speed from
central differences of the angle where the velocity channel agrees with it, else the velocity channel; the
acceleration by the same differentiator the mechanical equation uses for ω'), so the body's torque and the
joint's ``J ω'`` see the same acceleration, and both are low-passed alike by the equation error's parallel filter.

The body's torque enters each joint's mechanical equation as the ``load_torque`` channel (a known external load
at the output, :data:`..signals.CANONICAL`): ``P = J ω' + b ω + τ_f + τ_cog + τ_ext / N``. Where a joint logs a
torque sensor, its equation uses the sensor instead (the torque after the gear: ``τ_ext`` = the sensor reading),
and the body's torque is not needed there; the sensor then checks the body's model directly (:mod:`.mass`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ...params import ActuatorParams
from ..frame import equation_error as ee
from ..signals import Signals


@dataclass(frozen=True)
class JointMotion:
    """The recorded joints' motion at the output on one time base (columns in ``joints`` order)."""

    joints: tuple[str, ...]
    time: np.ndarray        #: [s] from the recording's first sample
    q: np.ndarray           #: (n, k) position [rad or m]
    qd: np.ndarray          #: (n, k) velocity
    qdd: np.ndarray         #: (n, k) acceleration


def joint_motion(signals: Mapping[str, Signals], params: Mapping[str, ActuatorParams], joints,
                 *, fc: float | None = None) -> JointMotion:
    """The output-side motion of ``joints`` (names in ``signals`` and ``params``), each derived as its own
    diagnosis derives it. Every joint must share one time base (one multi-joint log)."""
    joints = tuple(joints)
    cols, t0 = {"q": [], "qd": [], "qdd": []}, None
    for name in joints:
        sig = signals[name]
        if not (sig.has("position") or sig.has("velocity")):
            raise ValueError(f"joint {name!r}: no position or velocity channel: the body's torque needs the motion")
        ctx = ee.prepare([(sig, False)], params[name], fc=fc)
        n_out = params[name].gear.gear_ratio
        if t0 is None:
            t0 = ctx.t
        elif len(ctx.t) != len(t0) or not np.allclose(ctx.t, t0, rtol=0.0, atol=1e-6):
            raise ValueError(f"joint {name!r}: its samples are not on the time base of joint {joints[0]!r} "
                             f"({len(ctx.t)} vs {len(t0)} samples): a robot diagnosis needs one multi-joint log")
        S = ctx.sig
        cols["q"].append(S["theta"] / n_out)
        cols["qd"].append(S["omega"] / n_out)
        cols["qdd"].append(S["omega_dot"] / n_out)
    return JointMotion(joints, np.asarray(t0), *(np.column_stack(cols[k]) for k in ("q", "qd", "qdd")))


def with_load(sig: Signals, tau_out: np.ndarray, why: str) -> Signals:
    """``sig`` with ``tau_out`` [N·m at the output] added to its known external load (``load_torque``)."""
    tau_out = np.asarray(tau_out, dtype=float)
    if tau_out.shape != sig.time.shape:
        raise ValueError(f"body torque: {tau_out.shape} samples for a recording of {sig.time.shape}")
    chans = dict(sig.channels)
    chans["load_torque"] = chans["load_torque"] + tau_out if "load_torque" in chans else tau_out
    meta = dict(sig.meta)
    meta["notes"] = list(meta.get("notes", [])) + [why]
    meta["semantics"] = dict(meta.get("semantics", {}), load_torque=why)
    return dataclasses.replace(sig, channels=chans, meta=meta)


def has_torque_sensor(sig: Signals) -> bool:
    return sig.has("torque")
