"""Direction-dependent friction.

The catalogue record and its regressor forms (``FORMS``: columns, excitation test, parameter mapping)."""

from __future__ import annotations

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


FORMS = Forms(Single({"fric_sign": col_fric_sign, "fric_abs": col_fric_abs}), excite_friction, params_friction)
