"""Backlash: a dead zone in the transmission behind its spring.

The catalogue record and its regressor forms (``FORMS``: from the rotor alone the compliance's own forms, an exact
alias; none with a load encoder, where the dead zone is a form of transmission_compliance)."""

from __future__ import annotations

from .forms import Forms, Variant
from .record import Effect
from .transmission_compliance import v_compliance

#: the experiment that separates backlash from a compliant transmission
BACKLASH_EXPERIMENT = ("record the load's angle behind the transmission (a load-side encoder, column load_position: "
                       "the dead zone shows on the measured deflection), or reverse the load at low torque (a slow "
                       "reversal of the transmission torque: inside the dead zone the rotor runs free of the load, "
                       "behind a spring it does not)")

EFFECT = Effect(
    name="backlash", rank=110,
    description="backlash: a dead zone in the transmission (gear play) behind its spring; identified with a load "
                "encoder (a form of transmission_compliance), an alias of the compliance from the rotor alone",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"transmission_compliance": BACKLASH_EXPERIMENT},
    hides_behind=("transmission_compliance",),
)


def excite_backlash(ctx):
    """Never fitted on its own. With a load encoder the backlash is a form of transmission_compliance (the dead zone
    on the measured deflection); from the rotor's angle alone a dead zone behind a stiffer spring moves the rotor
    like a softer spring (the load follows through the spring's mean stiffness), so it is not checkable and is
    reported as the compliance finding's alias (:func:`v_backlash`)."""
    if "theta_load" in ctx.sig:
        return ("with the load encoder (load_position) it is identified as a form of transmission_compliance "
                "(the dead zone on the measured deflection)")
    return ("needs the load's angle (a load-side encoder, load_position) or a load reversal at low torque: from the "
            "rotor's angle alone a dead zone behind a spring moves the rotor like a softer spring")


def v_backlash(ctx, loc):
    """The forms a backlash takes seen from the rotor alone: the compliance forms themselves (the load follows a
    dead zone behind a stiffer spring through its mean stiffness: the same column at the softer spring's
    anti-resonance), so the alias with an accepted compliance is exact; none with a load encoder (there the dead
    zone is fitted on the measured deflection, a form of transmission_compliance)."""
    if "theta_load" in ctx.sig:
        return []
    return [Variant(EFFECT.name, f"a dead zone behind a stiffer spring, seen from the rotor alone ({v.label})",
                    v.columns, hyper=dict(v.hyper, kind="rotor"))
            for v in v_compliance(ctx, loc)]


def params_backlash(coef, cov, keys, variant, ctx):
    """Not identifiable from the rotor alone (the dead zone's width trades against the spring's stiffness): no
    values, the alias says which experiment separates them."""
    return {}


FORMS = Forms(v_backlash, excite_backlash, params_backlash)
