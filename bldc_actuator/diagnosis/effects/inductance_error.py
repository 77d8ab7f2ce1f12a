"""The q-axis inductance is off.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

from .forms import Forms, Single, flat, params_generic
from .record import Bounds, Effect, Param, Story

EFFECT = Effect(
    name="inductance_error", rank=130,
    description="the q-axis inductance is off",
    equations=("electrical",), needs=("voltage_q", "current", "velocity|position"), simulated=True,
    confusable={"current_loop_delay": "current steps recorded at a higher rate than the current loop"},
    params=(Param("q_inductance", "H", "motor.q_inductance", (Bounds(0.2, 5.0, nominal="motor.q_inductance"),)),),
    nominal=(("q_inductance", "motor.q_inductance"),),
    story=Story.ELECTRICAL_CURRENT_TREND, within_loop_period=True,
)


def col_l_err(ctx):
    return {"electrical": ctx.sig["di_dt"]}


FORMS = Forms(Single({"l_err": col_l_err}), None,
              params_generic({"l_err": ("q_inductance", "H", "motor.q_inductance", flat("motor.q_inductance"))}))
