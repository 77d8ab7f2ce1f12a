"""Issue #24 symptom 10: the verdict has ONE source (the typed :class:`Verdict` record); every output — the JSON's
``verdict``/``verdict_kind``/``verdict_reasons``/``nothing_missing``, report.md, the CLI's print, the Python
result object — is derived from it and can never contradict it."""

import json

import pytest

from bldc_actuator.diagnosis import cli as dcli
from bldc_actuator.diagnosis.report.document import DiagnosisReport
from bldc_actuator.diagnosis.results import FOUND, NOT_DECIDABLE, NOTHING_MISSING, Undecidable, decide


def _finding(effect="coulomb_friction"):
    return {"effect": effect, "description": "d", "form": "f", "parameters": {"a": 1.0}, "uncertainty": {"a": 0.1},
            "units": {"a": "N*m"}, "fields": {}, "simulated": True, "evidence": [], "held_out": {}, "metrics": [],
            "delta_bic": 20.0, "correlations": []}


def _report(findings, rec):
    return DiagnosisReport(channels=[], findings=findings, rejected=[], windows=[], data_issues=[],
                           not_checkable=[], aliases=[], verdict_record=rec)


class _Args:
    json = report = updated_params = None


def _outputs(rep, tmp_path, capsys):
    rep.write_json(tmp_path / "r.json")
    md = rep.write_markdown(tmp_path / "md", plots=False).read_text()
    capsys.readouterr()
    dcli._print_summary(rep, _Args())
    return json.loads((tmp_path / "r.json").read_text()), md, capsys.readouterr().out


def test_not_decidable_without_a_finding_does_not_say_nothing_missing(tmp_path, capsys):
    rec = decide([], [Undecidable("holdout_too_short", "the held-out set has 9 replay window(s) of 0.1 s "
                                  "(needs >= 25)", "record longer")])
    rep = _report([], rec)
    assert rec.kind == NOT_DECIDABLE
    d, md, out = _outputs(rep, tmp_path, capsys)
    assert d["verdict_kind"] == NOT_DECIDABLE
    assert d["nothing_missing"] is False          # was True: computed from "no findings", not from the verdict
    assert rep.nothing_missing is False
    assert d["verdict"] == rec.text() and d["verdict"].startswith("not decidable")
    assert f"**Verdict: {rec.text()}**" in md
    assert out.splitlines()[0] == rec.text()
    assert [u["code"] for u in d["verdict_reasons"]] == ["holdout_too_short"]


@pytest.mark.parametrize("found, reasons, kind, nothing", [
    ([], [], NOTHING_MISSING, True),
    (["coulomb_friction"], [], FOUND, False),
    (["coulomb_friction"], [Undecidable("holdout_too_short", "short", "record longer")], FOUND, False),
    (["coulomb_friction"], [Undecidable("base_replay_error", "far off", "check", blocking=True)], NOT_DECIDABLE,
     False),
])
def test_every_output_reads_the_one_verdict_record(tmp_path, capsys, found, reasons, kind, nothing):
    rec = decide(found, reasons)
    rep = _report([_finding(e) for e in found], rec)
    d, md, out = _outputs(rep, tmp_path, capsys)
    assert (rep.verdict_kind, d["verdict_kind"], rec.kind) == (kind, kind, kind)
    assert rep.nothing_missing is nothing and d["nothing_missing"] is nothing
    assert rep.verdict == d["verdict"] == rec.text() == out.splitlines()[0]
    assert d["verdict_record"] == rec.to_dict()


def test_the_verdict_text_cannot_be_set_apart_from_its_record():
    rec = decide([], [])
    with pytest.raises(TypeError):
        DiagnosisReport(channels=[], findings=[], rejected=[], windows=[], data_issues=[], not_checkable=[],
                        aliases=[], verdict="found: missing physics: x", verdict_record=rec)
    rep = _report([], rec)
    with pytest.raises(AttributeError):
        rep.verdict = "found: missing physics: x"


def test_a_finding_missing_from_the_verdict_is_refused():
    with pytest.raises(ValueError, match="verdict_record"):
        _report([_finding("coulomb_friction")], decide([], []))


def test_report_md_says_not_checkable_once_per_effect(tmp_path):
    rep = _report([], decide([], []))
    rep.not_checkable = [{"effect": "current_loop_delay", "reason": "not checkable at 100 Hz: the loop is faster",
                          "needs": []},
                         {"effect": "dead_time", "reason": "needs current", "needs": ["current"]}]
    md = rep.write_markdown(tmp_path, plots=False).read_text()
    assert "not checkable: not checkable" not in md
    assert "- **current_loop_delay**: not checkable at 100 Hz" in md
    assert "- **dead_time**: needs current" in md


def test_report_plots_never_use_offset_notation():
    """A 0.1 s window at t = 227 s drew ``1e-6−2.2734075e2`` on its axes; every report figure gets plain labels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from bldc_actuator.diagnosis.report.document import plain_tick_labels

    fig, (a, b) = plt.subplots(1, 2)
    t = 227.34075 + np.linspace(0, 1e-4, 50)
    a.plot(t, 1000.0 + 1e-5 * np.sin(t))
    b.semilogy([1, 2], [1e-3, 1.0])
    plain_tick_labels(fig)
    fig.canvas.draw()
    for axis in (a.xaxis, a.yaxis):
        assert axis.get_major_formatter().get_offset() == ""
    plt.close(fig)


def test_json_and_markdown_go_into_folders_that_do_not_exist_yet(tmp_path):
    rep = _report([], decide([], []))
    rep.write_json(tmp_path / "a" / "b" / "report.json")      # was FileNotFoundError (a traceback from the CLI)
    assert json.loads((tmp_path / "a" / "b" / "report.json").read_text())["verdict_kind"] == NOTHING_MISSING
