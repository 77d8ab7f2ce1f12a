"""Viscous damping.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

import numpy as np

from ... import effects as terms
from .forms import Forms, Single, flat, params_generic
from .record import Bounds, Effect, Param, Story

EFFECT = Effect(
    name="viscous_friction", rank=40,
    description="viscous damping: friction torque growing in proportion to speed",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"iron_loss": "iron loss also heats the stator: record temperatures at high speed, low current"},
    params=(Param("viscous_damping", "N*m*s/rad", "motor.viscous_damping", (Bounds(lo=0.0, lo_sd=3.0),)),),
    story=Story.VELOCITY,
)


def col_viscous(ctx):
    return {"mechanical": terms.viscous_basis(ctx.sig["omega"])[:, 0]}


def excite_viscous(ctx):
    w = np.abs(ctx.dsig("omega_s"))
    return None if np.percentile(w, 95) > 20 * ctx.omega_eps else "needs a range of speeds"


FORMS = Forms(Single({"visc": col_viscous}), excite_viscous,
              params_generic({"visc": ("viscous_damping", "N*m*s/rad", "motor.viscous_damping",
                                       flat("motor.viscous_damping"))}))
