"""The recorded voltage leads the current by a delay.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

from .forms import Forms, Single, sd
from .record import Bounds, Effect, Param, Story

EFFECT = Effect(
    name="current_loop_delay", rank=200,
    description="the recorded voltage leads the current by a delay (PWM / computation delay)",
    equations=("electrical",), needs=("voltage_q", "current", "velocity|position"), simulated=True,
    confusable={"inductance_error": "current steps recorded at a higher rate than the current loop"},
    params=(Param("delay", "s", "drive.current_loop_delay", (Bounds(-2e-3, 2e-3),)),),
    story=Story.ELECTRICAL_CURRENT_TREND, within_loop_period=True,
)


def col_delay(ctx):
    """The voltage-rate column: ``v(t - d) = v - d dv/dt``; where the log's voltage/current pairing is known
    (:func:`..frame.equation_error.voltage_alignment`) the equation already holds the nominal delay and hold, and
    the coefficient is the departure from them."""
    return {"electrical": ctx.sig["dv_dt"]}


def _delay_cross(ctx):
    """the loop-fed current-sensor noise this column shares with the voltage equation's residual
    (:mod:`..frame.loop_noise`)"""
    return ctx.tools.voltage_rate_cross(ctx)


col_delay.cross = _delay_cross


def params_delay(coef, cov, keys, variant, ctx):
    """The dv/dt column's coefficient is the delay d [s] (v(t - d) = v - d dv/dt): drive.current_loop_delay,
    which the simulator takes up to one loop period."""
    delta = float(coef[0])
    drive = ctx.params.drive
    # aligned equation: the coefficient is the change of the nominal delay; else the whole lag of the logged voltage
    d = drive.current_loop_delay + delta if "voltage_alignment" in ctx.sig else delta
    period = 1.0 / drive.current_loop_rate
    fits = 0.0 <= d <= period
    return {"delay": {"value": d, "sd": sd(cov, 0), "unit": "s", "field": "drive.current_loop_delay" if fits else None,
                      "delta": delta}}


FORMS = Forms(Single({"delay": col_delay}), None, params_delay)
