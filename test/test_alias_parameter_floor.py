"""The simulator deciding between aliased forms (judge/simulated.py arbitrate_aliases) compares FORMS, not the
values one training fit happened to give them.

Builtin benchmark seed 5, case `asymmetric` (a friction asymmetry: a constant offset torque while moving): the
equation error chose asymmetric_friction, the held-out replay preferred position_dependent_load by +0.0196 rad/s
over a window floor of 0.015 and named the load. The load form was not better: the asymmetric form had refitted
the Coulomb friction 2.2 standard deviations low (0.009875 +- 0.000057 for a true and nominal 0.01), the load form
has no Coulomb column and kept the nominal (true) value; the replay of a constant torque resolves 1e-4 N*m. With
the Coulomb friction held at the truth both forms replay alike (0.1895 vs 0.1886 rad/s). An estimate's error moves
every window's error alike, so the paired spread over windows does not see it: the noise floor now adds each
form's replay-error spread over its own fitted uncertainty (delta method, :func:`parameter_spread`).

Recordings from the project's simulator (a PD position loop around the truth actuator, 1 kHz log). The first
case reproduces the seed-5 mechanism deterministically: the training recording's Coulomb friction is 1.5 % below
the held-out one's (the nominal), so the asymmetric form's refitted Coulomb friction is off for the held-out data
by several of its standard deviations. The second: a real constant + gravity load, where the angle terms are
physics and the load form must still replace the friction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bldc_actuator import effects
from bldc_actuator.diagnosis.frame import writeback
from bldc_actuator.diagnosis.frame.selection import forward_select
from bldc_actuator.diagnosis.judge import simulated as judge
from bldc_actuator.diagnosis.pipeline import DiagnoseOptions
from bldc_actuator.diagnosis.search import stage as search
from bldc_actuator.params import ActuatorParams

from test_issue14_judge_helpers import closed_loop_recording

NOMINAL = ActuatorParams().replace(**{"gear.gear_ratio": 9.0, "effects.coulomb_friction": 0.01,
                                      "motor.rotor_inertia": 6e-5, "gear.output_motion": "rotary"})
FRICTION, LOAD = "asymmetric_friction", "position_dependent_load"


def _reference(ph: float):
    """Motor-side angle [rad]: both directions, output angle within about +-0.5 rad (where sin/cos of the output
    angle and a constant are nearly collinear: the two forms alias)."""
    return lambda t: (3 * np.sin(2 * np.pi * 0.23 * t + ph) + 1.0 * np.sin(2 * np.pi * 1.1 * t + 2 * ph)
                      + 0.5 * np.sin(2 * np.pi * 3.7 * t) + 0.2 * np.sin(2 * np.pi * 8.3 * t + ph))


def _arbitrate(train_truth: ActuatorParams, heldout_truth: ActuatorParams):
    """Search on a 20 s training and a 10 s held-out recording with the two aliased candidates, the friction
    form chosen and the load form its alias (as the equation error chose on seed 5); the simulator decides."""
    tr = closed_loop_recording(train_truth, NOMINAL, _reference(0.3), duration=20.0, seed=1)
    ho = closed_loop_recording(heldout_truth, NOMINAL, _reference(1.9), duration=10.0, seed=2)
    opts = DiagnoseOptions(holdout_signals=ho, progress=False, effects=[FRICTION, LOAD])
    s = search.run(tr, NOMINAL, opts, lambda m: None)
    names = [FRICTION, LOAD]
    sel = forward_select(s.ctx, s.located, s.lib, [FRICTION], opts.gate)
    assert [a.effect for a in sel.accepted] == [FRICTION]
    sel.aliases = [{"effects": [FRICTION, LOAD], "chosen": FRICTION, "correlation": 0.99}]
    new, records = judge.arbitrate_aliases(
        s.ctx, sel, lambda out: forward_select(s.ctx, s.located, s.lib, [n for n in names if n not in out], opts.gate),
        s.lib, s.starts_holdout, opts.window_s)
    (rec,) = records
    return s, sel, new, rec


def test_a_friction_whose_coulomb_part_is_fitted_off_is_not_replaced_by_a_load():
    truth_ho = NOMINAL.replace(**{"effects.friction_asymmetry": 0.005})
    truth_tr = truth_ho.replace(**{"effects.coulomb_friction": 0.01 - 1.5e-4})
    s, sel, new, rec = _arbitrate(truth_tr, truth_ho)
    assert rec["kept"] == FRICTION, rec
    assert [a.effect for a in new.accepted] == [FRICTION]
    # the mechanism: the friction form's Coulomb friction, fitted on the training recording, is off the held-out
    # truth by several of its standard deviations; the load form keeps the nominal (held-out) value
    ff = writeback.final_fit(s.ctx, sel)
    c = writeback.effect_parameters(s.ctx, sel, ff, s.lib)[FRICTION]["coulomb_friction"]
    assert (0.01 - c["value"]) > 2.0 * c["sd"], c
    err = rec["error"]
    gain = err[FRICTION] - err[LOAD]
    # ... so the load replays the held-out speed better beyond the windows' paired spread alone (the old floor,
    # which named the load) ...
    assert gain > rec["window_floor"], rec
    # ... but not beyond the spread the two forms' own fitted uncertainties give the replay error
    assert rec["parameter_spread"][FRICTION] > 0.0 and rec["parameter_spread"][LOAD] > 0.0
    assert rec["noise_floor"] == pytest.approx(math.hypot(rec["window_floor"], rec["parameter_floor"]), rel=1e-9)
    # ... and the load's constant form is the same equation as the friction asymmetry wherever the rotor moves
    # (stuck samples leave the equation): a replay difference is one of fitted values, never of forms
    assert "same equation" in rec["reason"], rec


def test_a_real_constant_plus_gravity_load_still_replaces_the_friction():
    truth = NOMINAL.replace(**{"load.load_torque": 0.04, "load.gravity_torque": 0.03, "load.gravity_phase": 0.6})
    s, sel, new, rec = _arbitrate(truth, truth)
    err = rec["error"]
    assert err[FRICTION] - err[LOAD] > rec["noise_floor"], rec
    assert err[LOAD] < 0.5 * err[FRICTION]
    assert rec["kept"] == LOAD, rec
    assert [a.effect for a in new.accepted] == [LOAD]
    p = writeback.effect_parameters(s.ctx, new, writeback.final_fit(s.ctx, new), s.lib)[LOAD]
    # over +-0.4 rad of output angle a sinusoid is a constant plus a spring to 1e-3 of its amplitude: the form
    # the fit picks (gravity, or spring + constant) reproduces the true load over the angles it saw
    th = np.linspace(-0.4, 0.4, 41)
    v = {k: x["value"] for k, x in p.items()}
    fitted = effects.position_load_torque_out(th, v.get("load_torque", 0.0), v.get("gravity_torque", 0.0),
                                              v.get("gravity_phase", 0.0), v.get("spring_stiffness", 0.0),
                                              NOMINAL.load.spring_zero)
    true = effects.position_load_torque_out(th, 0.04, 0.03, 0.6, 0.0, 0.0)
    assert np.max(np.abs(fitted - true)) < 0.1 * 0.03, (p, fitted - true)


@pytest.mark.parametrize("a,b", [(0.3, 0.0), (0.0, 0.4), (-0.2, 0.5)])
def test_parameter_spread_is_the_delta_method_sd_of_a_quadratic_error(a, b):
    """e(x) = e0 + a x + b x^2 / 2 with x ~ N(0, 1) (a whitened parameter error): the spread from the errors at
    x = +-1 equals the sd of e(x), checked against a large sample."""
    e0 = 1.0
    e = lambda x: e0 + a * x + 0.5 * b * x * x                                       # noqa: E731
    x = np.random.default_rng(3).standard_normal(400_000)
    assert judge.parameter_spread(e0, [e(1.0)], [e(-1.0)]) == pytest.approx(float(np.std(e(x))), rel=0.01)
    # independent directions add in variance
    two = judge.parameter_spread(e0, [e(1.0), e(1.0)], [e(-1.0), e(-1.0)])
    assert two == pytest.approx(math.sqrt(2) * judge.parameter_spread(e0, [e(1.0)], [e(-1.0)]), rel=1e-12)
