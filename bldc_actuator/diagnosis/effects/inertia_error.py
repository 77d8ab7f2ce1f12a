"""The rotor + load inertia is off.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

import numpy as np

from .forms import Forms, Single, flat, params_generic
from .record import Bounds, Effect, Param

EFFECT = Effect(
    name="inertia_error", rank=90,
    description="the rotor + load inertia is off",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"torque_constant_error": "record voltage_q (back-EMF gives K directly) or a known load / torque "
                "sensor"},
    params=(Param("rotor_inertia", "kg*m^2", "motor.rotor_inertia",
                  (Bounds(0.1, 20.0, nominal="motor.rotor_inertia"),)),),
    nominal=(("rotor_inertia", "motor.rotor_inertia"),),
)


def col_inertia(ctx):
    return {"mechanical": ctx.sig["omega_dot"]}


col_inertia.inertia = True   # its coefficient adds to the inertia the residual's timing noise scales with (clock_noise)


def excite_inertia(ctx):
    a = ctx.dsig("omega_dot")
    return None if np.std(a) > 0 else "needs acceleration"


FORMS = Forms(Single({"inertia": col_inertia}), excite_inertia,
              params_generic({"inertia": ("rotor_inertia", "kg*m^2", "motor.rotor_inertia",
                                          flat("motor.rotor_inertia"))}))
