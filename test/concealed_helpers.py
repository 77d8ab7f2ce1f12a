"""Helpers shared by the tests that diagnose concealed-benchmark cases (test_issue7_symptoms.py,
test_judge_simulation.py, test_gate_and_coarse_logs.py): generate a case's recordings with the independent truth
generator, load and clean them as the CLI does, and diagnose them."""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from benchmarks.concealed import cases as C  # noqa: E402


def case_recordings(case, tmp_path: Path):
    """(training, held-out, nominal parameters) of ``case``: generated under ``tmp_path`` unless already there,
    loaded and cleaned."""
    from bldc_actuator.diagnosis.io import cleaning, loaders

    d = tmp_path / case.name
    if not (d / "train.csv").exists():
        C.generate([case], tmp_path, workers=2)
    p = C.nominal_params(case)
    tr = cleaning.clean(loaders.load(d / "train.csv", params=p), params=p)
    ho = cleaning.clean(loaders.load(d / "heldout.csv", params=p), params=p)
    return tr, ho, p


def diagnose_case(case, tmp_path: Path, **opts):
    """The :class:`DiagnosisReport` of ``case`` (``opts``: further :class:`DiagnoseOptions`)."""
    from bldc_actuator.diagnosis.pipeline import DiagnoseOptions, diagnose

    tr, ho, p = case_recordings(case, tmp_path)
    return diagnose(tr, p, options=DiagnoseOptions(holdout_signals=ho, progress=False, **opts))
