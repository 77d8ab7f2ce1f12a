"""The held-out simulation decides between aliased forms (bldc_actuator/diagnosis/judge.arbitrate_aliases).

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

pytestmark = pytest.mark.skipif(T._c_library() is None, reason="no C compiler for the truth generator")


def _diagnose(case, tmp_path, **opts):
    from bldc_actuator.diagnosis import cleaning, loaders
    from bldc_actuator.diagnosis.pipeline import DiagnoseOptions, diagnose

    C.generate([case], tmp_path, workers=2)
    d = tmp_path / case.name
    p = C.nominal_params(case)
    tr = cleaning.clean(loaders.load(d / "train.csv", params=p), params=p)
    ho = cleaning.clean(loaders.load(d / "heldout.csv", params=p), params=p)
    return diagnose(tr, p, options=DiagnoseOptions(holdout_signals=ho, progress=False, **opts)).to_dict()


@pytest.mark.slow
def test_asymmetric_friction_on_a_fresh_seed_is_not_named_a_position_dependent_load(tmp_path):
    case = C.reseeded(C.get_case("asymmetric"), 1)
    eq_only = _diagnose(case, tmp_path / "eq", simulation_gate=False)
    assert [f["effect"] for f in eq_only["findings"]] == ["position_dependent_load"]   # the symptom
    rep = _diagnose(case, tmp_path / "sim")
    assert [f["effect"] for f in rep["findings"]] == ["asymmetric_friction"]
    fa = rep["findings"][0]["parameters"]["friction_asymmetry"]
    assert fa == pytest.approx(case.truth["asymmetric_friction"]["friction_asymmetry"], rel=0.15)
    (al,) = rep["aliases"]
    assert al["chosen"] == "asymmetric_friction" and "cannot tell them apart" in al["message"]
    ho = rep["compare"]["replay"]["holdout"]
    assert ho["after"]["velocity_rms"] < 0.2 * ho["before"]["velocity_rms"]


@pytest.mark.slow
def test_a_real_gravity_load_keeps_its_angle_terms(tmp_path):
    rep = _diagnose(C.reseeded(C.get_case("gravity"), 1), tmp_path)
    assert [f["effect"] for f in rep["findings"]] == ["position_dependent_load"]
