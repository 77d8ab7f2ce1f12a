"""A compliant transmission: the load a second mass behind a spring.

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Bounds, Effect, Param

EFFECT = Effect(
    name="transmission_compliance", rank=100,
    description="a compliant transmission (shaft, belt, harmonic drive, series-elastic spring): the load is a second "
                "mass on a spring, a two-mass resonance in the rotor's motion",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"inertia_error": "excite near the resonance (a chirp or steps): a rigid inertia error scales the "
                "acceleration at every frequency, a compliance only above the anti-resonance",
                "current_loop_delay": "a load encoder (joint side) measures the deflection directly"},
    params=(Param("load_inertia_reflected", "kg*m^2", bounds=(
                Bounds(lo=0.0, lo_sd=-3.0, label="reflected load inertia"),     # a load, clear of zero by 3 sd
                Bounds(hi=0.95, nominal="motor.rotor_inertia", label="reflected load inertia"))),   # a rotor left Param("load_inertia", "kg*m^2", "gear.load_inertia"),
            Param("transmission_stiffness", "N*m/rad", "gear.transmission_stiffness"),
            Param("transmission_damping", "N*m*s/rad", "gear.transmission_damping"),
            Param("backlash", "rad", "gear.backlash"),
            Param("rotor_inertia_motor_side", "kg*m^2"), Param("antiresonance_frequency", "Hz"),
            Param("resonance_frequency", "Hz"), Param("damping_ratio", "")),
    takes_from_rotor_inertia="load_inertia_reflected",
)
