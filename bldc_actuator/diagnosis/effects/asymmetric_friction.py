"""Direction-dependent friction.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

import math

from .coulomb_friction import NON_NEGATIVE, col_fric_abs, col_fric_sign, excite_friction, params_friction
from .forms import Forms, Single
from .record import Effect, Param, Story

EFFECT = Effect(
    name="asymmetric_friction", rank=20,
    description="direction-dependent friction: different dry friction for positive and negative motion",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"position_dependent_load": "hold still at several angles, or move in both directions over "
                "the same angles: a load depends on angle, friction on direction",
                "coulomb_friction": "move at the same speeds in both directions"},
    params=(Param("coulomb_friction", "N*m", "effects.coulomb_friction", NON_NEGATIVE),
            Param("friction_asymmetry", "N*m", "effects.friction_asymmetry")),
    story=Story.VELOCITY,
)


def directional(pars, ctx):
    """Dry friction opposes motion in both directions: ``c + a`` (positive motion) and ``c - a`` (negative) are not
    negative. One that is, beyond 3 sd, is a constant force driving the axis (it needs a holding current at
    standstill; a constant load names it), not friction."""
    c, a = pars.get("coulomb_friction", {}), pars.get("friction_asymmetry", {})
    cv, av = c.get("value"), a.get("value")
    if not isinstance(cv, (int, float)) or not isinstance(av, (int, float)):
        return None
    sd = math.hypot(c.get("sd") or 0.0, a.get("sd") or 0.0)
    if cv - abs(av) + 3.0 * sd >= 0.0:
        return None
    return (f"dry friction {cv - abs(av):.3g} N*m < 0 in one direction (coulomb {cv:.3g}, asymmetry {av:.3g}): a "
            f"constant force, not friction")


FORMS = Forms(Single({"fric_sign": col_fric_sign, "fric_abs": col_fric_abs}), excite_friction, params_friction,
              implausible=directional)
