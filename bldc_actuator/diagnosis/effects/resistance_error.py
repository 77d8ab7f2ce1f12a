"""The winding resistance is off.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

from .forms import Forms, Single, flat, params_generic
from .record import Bounds, Effect, Param, Story

EFFECT = Effect(
    name="resistance_error", rank=120,
    description="the winding resistance is off (at the reference temperature)",
    equations=("electrical",), needs=("voltage_q", "current", "velocity|position"), simulated=True,
    confusable={"resistance_temperature": "hold a current while the winding warms, with winding temperature "
                "recorded"},
    params=(Param("phase_resistance", "ohm", "motor.phase_resistance",
                  (Bounds(0.2, 5.0, nominal="motor.phase_resistance"),)),),
    nominal=(("phase_resistance", "motor.phase_resistance"),),
    story=Story.ELECTRICAL_CURRENT_TREND,
)


def col_r_err(ctx):
    m = ctx.params.motor
    S = ctx.sig
    return {"electrical": S["i_col"] * S["R"] / m.phase_resistance}


FORMS = Forms(Single({"r_err": col_r_err}), None,
              params_generic({"r_err": ("phase_resistance", "ohm", "motor.phase_resistance",
                                        flat("motor.phase_resistance"))}))
