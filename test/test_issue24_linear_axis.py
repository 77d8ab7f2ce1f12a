"""Issue #24, symptom 5: a constant force on a linear axis was fitted as two cancelling sinusoid terms ("gravity
375 N·m" on a horizontal slide), and the forms a load takes are the ones the recording can identify.

A linear positioning axis: a 10 mm-lead screw (gear ratio 2π/0.01 rad of motor angle per metre), a stroke of
0.18 m (0.18 "rad" of output angle: a thirtieth of a period, where sin, cos and a constant are one column), moves
in both directions with rests between them, a constant force of -3.16 N on the slide plus Coulomb and viscous
friction at the motor. The diagnosis names Coulomb, viscous and the constant force within their uncertainties
and no gravity term, whether the parameter file says the axis is linear (``gear.output_motion: linear``: the
force is then reported in N) or says nothing. The force (3.16 N = 0.0050 N·m at the motor) exceeds the Coulomb
friction (0.003 N·m): friction with that asymmetry would be negative in one direction, so the data decide it is a
force. A hinge with a real gravity load over ±90° gets its gravity named.

Recordings from the project's simulator (:func:`test_issue14_judge_helpers.closed_loop_recording`: a PD position
loop around the truth actuator, 1 kHz log)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bldc_actuator.diagnosis import pipeline
from bldc_actuator.diagnosis.effects import position_dependent_load as pdl
from bldc_actuator.params import ActuatorParams

from test_issue14_judge_helpers import closed_loop_recording

LEAD = 0.01                                  # m of travel per motor revolution
N_SCREW = 2 * math.pi / LEAD                 # rad of motor angle per metre
FORCE = -3.16                                # N on the slide (load.load_torque of a linear axis)
COULOMB, VISCOUS = 0.003, 4e-5               # at the motor [N*m], [N*m*s/rad]
LOAD = pdl.EFFECT.name
EFFECTS = ["coulomb_friction", "viscous_friction", "asymmetric_friction", LOAD, "stribeck_friction",
           "inertia_error"]


def _stroke(ph: float):
    """Motor angle [rad]: 0.18 m strokes out and back (2 s each) with 2 s rests, a small dither while moving."""
    def ref(t):
        T = t % 8.0
        x = np.where(T < 2, 0.5 * (1 - np.cos(np.pi * T / 2)),
                     np.where(T < 4, 1.0, np.where(T < 6, 0.5 * (1 + np.cos(np.pi * (T - 4) / 2)), 0.0)))
        moving = (T < 2) | ((T >= 4) & (T < 6))
        return 0.18 * N_SCREW * (x - 0.5) + 3.0 * np.sin(2 * np.pi * 1.3 * t + ph) * moving
    return ref


def _nominal(motion: str) -> ActuatorParams:
    return ActuatorParams().replace(**{"gear.gear_ratio": N_SCREW, "gear.output_motion": motion,
                                       "effects.coulomb_friction": 0.0, "motor.rotor_inertia": 6e-5,
                                       "motor.viscous_damping": 1e-5})


@pytest.fixture(scope="module")
def axis_recordings():
    truth = _nominal("unspecified").replace(**{"effects.coulomb_friction": COULOMB, "motor.viscous_damping": VISCOUS,
                                               "load.load_torque": FORCE})
    nom = _nominal("unspecified")
    return (closed_loop_recording(truth, nom, _stroke(0.0), duration=24.0, seed=1),
            closed_loop_recording(truth, nom, _stroke(1.0), duration=16.0, seed=2))


def _named(rep) -> dict:
    return {f["effect"]: f for f in rep.findings}


@pytest.mark.parametrize("motion,unit", [("linear", "N"), ("unspecified", "N*m")])
def test_a_linear_axis_names_coulomb_viscous_and_a_constant_force_and_no_gravity(axis_recordings, motion, unit):
    tr, ho = axis_recordings
    rep = pipeline.diagnose(tr, _nominal(motion), options=pipeline.DiagnoseOptions(
        holdout_signals=ho, progress=False, effects=EFFECTS))
    named = _named(rep)
    assert set(named) == {"coulomb_friction", "viscous_friction", LOAD}, (named, rep.rejected)
    load = named[LOAD]
    assert set(load["parameters"]) == {"load_torque"}, load          # no gravity term, no spring
    assert "gravity" not in load["form"]
    assert load["units"]["load_torque"] == unit
    f, f_sd = load["parameters"]["load_torque"], load["uncertainty"]["load_torque"]
    assert abs(f - FORCE) <= 3 * f_sd and f_sd < 0.02 * abs(FORCE), load
    c = named["coulomb_friction"]
    assert abs(c["parameters"]["coulomb_friction"] - COULOMB) <= 3 * c["uncertainty"]["coulomb_friction"], c
    v = named["viscous_friction"]
    assert abs(v["parameters"]["viscous_damping"] - VISCOUS) <= 3 * v["uncertainty"]["viscous_damping"], v
    # the asymmetric friction is the same equation while moving; its fitted asymmetry exceeds the Coulomb part,
    # friction negative in one direction: refused as a force, not named
    (asym,) = [x for x in rep.rejected if x["effect"] == "asymmetric_friction"]
    assert "a constant force, not friction" in asym["reason"], asym


def test_gravity_is_offered_only_where_the_angle_separates_it_from_a_constant():
    """The forms follow the recording's output angles and the declared joint: 0.18 rad of travel does not
    separate a sinusoid from a constant (a thirtieth of a period), ±90° does; a declared slide never carries a
    gravity sinusoid, a declared hinge always may."""
    class Ctx:
        def __init__(self, th_out, motion, N=9.0):
            self.params = ActuatorParams().replace(**{"gear.gear_ratio": N, "gear.output_motion": motion})
            self._th = np.asarray(th_out) * N

        def dsig(self, name):
            return self._th

    stroke = np.linspace(-0.09, 0.09, 2000)
    hinge = np.linspace(-math.pi / 2, math.pi / 2, 2000)
    ok, rho = pdl.separable(Ctx(stroke, "unspecified"), ("sin", "cos", "const"))
    assert not ok and rho > 0.999
    ok, rho = pdl.separable(Ctx(hinge, "unspecified"), ("sin", "cos", "const"))
    assert ok and rho < 0.95
    assert not pdl.gravity_offered(Ctx(stroke, "unspecified"))[0]
    assert pdl.gravity_offered(Ctx(hinge, "unspecified"))[0]
    assert not pdl.gravity_offered(Ctx(hinge, "linear"))[0]
    assert pdl.gravity_offered(Ctx(stroke, "rotary"))[0]


def test_b_a_hinge_with_gravity_over_90_degrees_gets_its_gravity_named():
    N, TAU_G, PHI = 9.0, 0.3, 0.25                    # output side [N*m], [rad]
    nom = ActuatorParams().replace(**{"gear.gear_ratio": N, "effects.coulomb_friction": 0.01,
                                      "motor.rotor_inertia": 6e-5})
    truth = nom.replace(**{"load.gravity_torque": TAU_G, "load.gravity_phase": PHI})

    def swing(ph):
        return lambda t: N * (1.45 * np.sin(2 * np.pi * 0.2 * t + ph) + 0.1 * np.sin(2 * np.pi * 1.7 * t + ph))

    tr = closed_loop_recording(truth, nom, swing(0.0), duration=20.0, seed=3)
    ho = closed_loop_recording(truth, nom, swing(1.3), duration=12.0, seed=4)
    rep = pipeline.diagnose(tr, nom, options=pipeline.DiagnoseOptions(holdout_signals=ho, progress=False,
                                                                       effects=EFFECTS))
    named = _named(rep)
    assert LOAD in named, (rep.findings, rep.rejected)
    load = named[LOAD]
    assert "gravity" in load["form"], load
    p, u = load["parameters"], load["uncertainty"]
    assert abs(p["gravity_torque"] - TAU_G) <= max(3 * u["gravity_torque"], 0.02 * TAU_G), load
    assert abs(p["gravity_phase"] - PHI) <= max(3 * u["gravity_phase"], 0.02), load
    assert load["units"]["gravity_torque"] == "N*m"


def test_a_force_below_the_dry_friction_and_a_friction_asymmetry_are_reported_as_aliases():
    """The same axis with a Coulomb friction (0.012 N*m) above the force (0.005 N*m at the motor): while moving a
    constant force and a friction asymmetry are one column (|sign ω| = 1), and standing still both hold the same
    band; the data cannot separate them, and the report says so and which experiment does."""
    nom = _nominal("linear")
    truth = nom.replace(**{"effects.coulomb_friction": 0.012, "motor.viscous_damping": VISCOUS,
                           "load.load_torque": FORCE})
    tr = closed_loop_recording(truth, nom, _stroke(0.0), duration=24.0, seed=1)
    ho = closed_loop_recording(truth, nom, _stroke(1.0), duration=16.0, seed=2)
    rep = pipeline.diagnose(tr, nom, options=pipeline.DiagnoseOptions(holdout_signals=ho, progress=False,
                                                                      effects=EFFECTS))
    named = _named(rep)
    assert "viscous_friction" in named
    al = [a for a in rep.aliases if set(a["effects"]) == {"asymmetric_friction", LOAD}]
    assert al, (rep.aliases, list(named))
    assert "same equation" in al[0]["message"] and "holding current at standstill" in al[0]["experiment"]
    # whichever form was kept, the constant torque while moving is the force: the asymmetry, or the load
    if "asymmetric_friction" in named:
        a = named["asymmetric_friction"]
        got, sd = a["parameters"]["friction_asymmetry"], a["uncertainty"]["friction_asymmetry"]
        assert abs(got - FORCE / N_SCREW) <= 3 * sd + 0.02 * abs(FORCE / N_SCREW), a
