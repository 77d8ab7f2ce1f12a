"""The judge refuses a finding the simulated actuator has no place for (judge/simulated.py, ``simulate_findings``):
when leaving the finding out does not change the simulated parameters, the held-out replay cannot show it helps,
and the verdict is "not simulated" with the reason in plain words, never a replayed "not confirmed" from two
identical simulations. Two ways a finding has no place: its form has no term in the simulator (the electrical-angle
ripple's flux-harmonic form), or its fitted value lies outside what its parameter can hold (a negative
``effects.kt_saturation``: torque per amp rising with current).

Real inputs: a closed-loop recording of a joint with a true Coulomb friction, the diagnosis's own search stage (the
Context, the selection, the library), the real candidate variants and their ``to_params``; only the two extra
findings are put into the selection by hand (no recording here makes the search accept them)."""

from __future__ import annotations

import numpy as np
import pytest

from bldc_actuator.diagnosis.frame import writeback
from bldc_actuator.diagnosis.frame.selection import Accepted
from bldc_actuator.diagnosis.judge import simulated as judge
from bldc_actuator.diagnosis.pipeline import DiagnoseOptions
from bldc_actuator.diagnosis.search import stage as search
from bldc_actuator.params import ActuatorParams

from test_issue14_judge_helpers import closed_loop_recording, triangle_then_sines

NOMINAL = ActuatorParams().replace(**{"gear.gear_ratio": 9.0})
TRUTH = NOMINAL.replace(**{"effects.coulomb_friction": 0.02})


@pytest.fixture(scope="module")
def searched():
    rec = closed_loop_recording(TRUTH, NOMINAL, triangle_then_sines, duration=16.0, seed=5)
    found = search.run(rec, NOMINAL, DiagnoseOptions(), lambda m: None)
    assert [a.effect for a in found.selection.accepted] == ["coulomb_friction"]
    assert len(found.starts_holdout) >= 10
    return found


def _with(found, extra: dict[str, tuple[str | None, np.ndarray]]):
    """The search's selection and parameters with ``extra`` findings added: effect -> (variant kind or None for the
    candidate's only form, fitted coefficients), each through the candidate's own variants and ``to_params``."""
    ctx, lib, sel = found.ctx, found.lib, found.selection
    pars = writeback.effect_parameters(ctx, sel, writeback.final_fit(ctx, sel), lib)
    accepted = list(sel.accepted)
    for effect, (kind, coef) in extra.items():
        cand = lib[effect]
        variants = cand.variants(ctx, found.located)
        v = next(v for v in variants if kind is None or v.hyper.get("kind") == kind)
        keys = list(v.columns)
        accepted.append(Accepted(effect, v, keys, round=1, dbic=50.0, heldout={}))
        pars[effect] = cand.to_params(np.asarray(coef, float), np.eye(len(keys)) * 1e-8, keys, v, ctx)
    return type(sel)(**{**sel.__dict__, "accepted": accepted}), pars


def _judge(found, sel, pars):
    return judge.simulate_findings(found.ctx, sel, pars, found.lib, found.starts_holdout, 0.1)


def test_no_term_and_a_value_outside_its_field_are_refused_as_not_simulated(searched):
    sel, pars = _with(searched, {"electrical_angle_ripple": ("flux", [0.02, 0.01]),
                                 "magnetic_saturation": (None, [-0.01])})
    assert pars["magnetic_saturation"]["kt_saturation"]["field"] is None      # the candidate's own mapping refuses it
    out = _judge(searched, sel, pars)
    # the real finding is judged by the replay as usual, unaffected by the two that change nothing
    assert out["coulomb_friction"]["verdict"] == "confirmed"
    assert out["coulomb_friction"]["channel"] == "velocity"
    # no term for the flux-harmonic form
    r = out["electrical_angle_ripple"]
    assert r["verdict"] == "not simulated" and r["channel"] is None
    assert r["reason"] == "the simulated actuator has no term for this form: it cannot be shown to help in simulation"
    assert "without" not in r      # no replayed comparison of two identical simulations
    # a fitted value its parameter cannot hold: the reason names it with its value and unit
    s = out["magnetic_saturation"]
    assert s["verdict"] == "not simulated" and s["channel"] is None and "without" not in s
    assert s["reason"].startswith("the fitted kt_saturation = -0.01 1/A has no place in the simulated actuator "
                                  "(outside what its parameter can hold)")


def test_the_same_finding_inside_its_field_is_replayed(searched):
    """The control: a positive saturation coefficient has its parameter (effects.kt_saturation): the leave-one-out
    replay differs and gives a simulated verdict on the speed (whatever it is), not "not simulated"."""
    sel, pars = _with(searched, {"magnetic_saturation": (None, [0.01])})
    assert pars["magnetic_saturation"]["kt_saturation"]["field"] == "effects.kt_saturation"
    s = _judge(searched, sel, pars)["magnetic_saturation"]
    assert s["verdict"] != "not simulated" and s["channel"] == "velocity"
    assert s["without"] != s["with"]
