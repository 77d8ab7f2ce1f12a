"""The held-out simulation as judge (bldc_actuator/diagnosis/judge/simulated.py), beyond the leave-one-out verdicts that
test_issue7_symptoms.py covers: it decides between aliased forms (arbitrate_aliases) and judges the drive's fitted
voltage limit (judge_voltage_limit).

On the concealed benchmark's fresh seeds 1 and 2 a hidden friction asymmetry (a constant offset while moving) was
named position_dependent_load (sin/cos of the output angle + constant: three parameters, the angle terms fitting
nothing): equation error preferred it by 2 % of held-out RMS, an extra effect by the issue #7 count. The simulator
cannot tell the two apart on these recordings, so the simpler form is kept; on the gravity case, where the angle
terms are real, nothing changes."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.concealed import cases as C  # noqa: E402
from benchmarks.concealed import truth as T  # noqa: E402
from concealed_helpers import case_recordings, diagnose_case  # noqa: E402

pytestmark = pytest.mark.skipif(T._c_library() is None, reason="no C compiler for the truth generator")


def _diagnose(case, tmp_path, **opts):
    return diagnose_case(case, tmp_path, **opts).to_dict()


@pytest.mark.slow
def test_asymmetric_friction_on_a_fresh_seed_is_not_named_a_position_dependent_load(tmp_path):
    """The symptom (equation error naming the load) is gone at its root since the speed's noise scale is taken
    from the top of the band (a smaller friction smoothing: the direction step is sharper than the angle terms);
    the simulator still examines the alias and keeps the friction."""
    case = C.reseeded(C.get_case("asymmetric"), 1)
    eq_only = _diagnose(case, tmp_path / "eq", simulation_gate=False)
    assert [f["effect"] for f in eq_only["findings"]] == ["asymmetric_friction"]
    rep = _diagnose(case, tmp_path / "sim")
    assert [f["effect"] for f in rep["findings"]] == ["asymmetric_friction"]
    fa = rep["findings"][0]["parameters"]["friction_asymmetry"]
    assert fa == pytest.approx(case.truth["asymmetric_friction"]["friction_asymmetry"], rel=0.15)
    (rec,) = rep["compare"]["alias_simulation"]
    assert rec["kept"] == "asymmetric_friction" and rec["channel"] == "velocity"
    ho = rep["compare"]["replay"]["holdout"]
    assert ho["after"]["velocity_rms"] < 0.2 * ho["before"]["velocity_rms"]


@pytest.mark.slow
def test_the_simulator_replaces_a_load_equation_error_preferred_by_the_simpler_friction(tmp_path):
    """arbitrate_aliases on the old symptom, built directly: a selection that named position_dependent_load
    (sin/cos of the angle + constant) with the friction asymmetry as its alias. Both replay the held-out windows
    alike, so the form with fewer parameters replaces it."""
    from bldc_actuator.diagnosis.judge import simulated as judge
    from bldc_actuator.diagnosis.frame.candidates import SPECIAL
    from bldc_actuator.diagnosis.pipeline import DiagnoseOptions
    from bldc_actuator.diagnosis.frame.selection import forward_select
    from bldc_actuator.diagnosis.search import stage as search

    tr, ho, p = case_recordings(C.reseeded(C.get_case("asymmetric"), 1), tmp_path)
    opts = DiagnoseOptions(holdout_signals=ho, progress=False)
    s = search.run(tr, p, opts, lambda m: None)
    names = [n for n in s.names if n not in SPECIAL]
    linear = [n for n in names if n != "asymmetric_friction"]
    sel = forward_select(s.ctx, s.located, s.lib, linear, opts.gate)
    assert "position_dependent_load" in [a.effect for a in sel.accepted]
    sel.aliases = [{"effects": ["position_dependent_load", "asymmetric_friction"], "chosen": "position_dependent_load",
                    "correlation": 0.997}]
    new, records = judge.arbitrate_aliases(
        s.ctx, sel, lambda out: forward_select(s.ctx, s.located, s.lib, [n for n in names if n not in out], opts.gate),
        s.lib, s.starts_holdout, opts.window_s)
    (rec,) = records
    assert rec["kept"] == "asymmetric_friction", rec
    assert "asymmetric_friction" in [a.effect for a in new.accepted]
    assert "position_dependent_load" not in [a.effect for a in new.accepted]


@pytest.mark.slow
def test_a_real_gravity_load_keeps_its_angle_terms(tmp_path):
    rep = _diagnose(C.reseeded(C.get_case("gravity"), 1), tmp_path)
    assert [f["effect"] for f in rep["findings"]] == ["position_dependent_load"]


@pytest.mark.slow
def test_the_fitted_voltage_limit_is_judged_by_the_simulated_current(tmp_path):
    """The modulator reaches 80 % of the SVPWM circle: the fitted drive.modulation_limit makes the simulated drive
    lose tracking where the real one does (it had no simulation verdict before: accepted unjudged)."""
    case = C.get_case("v_saturation")
    rep = _diagnose(case, tmp_path)
    (f,) = rep["findings"]
    assert f["effect"] == "voltage_saturation"
    assert f["parameters"]["voltage_limit_ratio"] == pytest.approx(0.80, rel=0.05)
    sim = f["simulation"]
    assert sim["verdict"] == "confirmed" and sim["channel"] == "current"
    assert sim["with"] < 0.5 * sim["without"]
    ho = rep["compare"]["replay"]["holdout"]
    assert ho["after"]["current_rms"] < 0.5 * ho["before"]["current_rms"]
    assert ho["after"]["velocity_rms"] < 0.5 * ho["before"]["velocity_rms"]
