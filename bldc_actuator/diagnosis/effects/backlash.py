"""Backlash: a dead zone in the transmission behind its spring.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect

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
