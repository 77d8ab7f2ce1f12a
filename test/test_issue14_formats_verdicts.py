"""Issue #14, symptoms 4 and 6: the three verdicts (found / nothing missing / not decidable with the reason),
identical on stdout, in report.md and in the JSON, on both routes (full and torque balance, one schema,
``--report`` honoured), on generated recordings whose truth is known:

* nothing is missing (the nominal model is the truth) -> "nothing missing";
* an unlogged 2.3 Hz load torque (no catalogued effect holds it) -> "not decidable: physics outside the
  catalogue" with the band it sits in, not "nothing missing";
* the same load 15x larger: the base model's replay error is several times the recorded speed -> "not
  decidable" with that reason;
* a current held at the drive's limit with K_t right -> no torque-constant finding, "current at the drive's
  limit";
* a 4 s recording -> "held-out set too short".
"""

from __future__ import annotations

import json
import math

import pytest

from bldc_actuator import cli
from bldc_actuator.diagnosis.io import cleaning
from bldc_actuator.diagnosis import cli as dcli
from bldc_actuator.diagnosis.pipeline import TORQUE_BALANCE, DiagnoseOptions, diagnose, route
from bldc_actuator.diagnosis.report.document import DiagnosisReport
from bldc_actuator.diagnosis.results import NOT_DECIDABLE, NOTHING_MISSING, decide
from bldc_actuator.params import ActuatorParams, dump_yaml
from issue14_generators import NOMINAL, dyno_run, limited_run, pd_run, write_csv


def _diagnose(sig):
    return diagnose(cleaning.clean(sig, params=NOMINAL), NOMINAL, options=DiagnoseOptions())


def _codes(rep):
    return [u.code for u in rep.verdict_record.undecidable]


def test_truth_as_nominal_says_nothing_missing():
    rep = _diagnose(pd_run(NOMINAL))
    assert rep.verdict_kind == NOTHING_MISSING and rep.verdict.startswith("nothing missing"), rep.verdict
    assert not any(x["large"] for x in rep.residual_structure)


def test_structured_residual_outside_the_catalogue_is_not_nothing_missing():
    rep = _diagnose(pd_run(NOMINAL, disturbance=lambda t: 0.1 * math.sin(2 * math.pi * 2.3 * t)))
    assert rep.verdict_kind == NOT_DECIDABLE and _codes(rep) == ["outside_catalogue"], rep.verdict
    big = next(x for x in rep.residual_structure if x["large"])
    assert big["equation"] == "mechanical"
    lo, hi = big["band_hz"]
    assert lo <= 2.3 <= hi                          # where it sits: the disturbance's frequency
    assert "physics outside the catalogue" in rep.verdict and "Hz" in rep.verdict


def test_base_replay_error_many_times_the_signal_is_not_decidable():
    rep = _diagnose(pd_run(NOMINAL, disturbance=lambda t: 1.5 * math.sin(2 * math.pi * 2.3 * t)))
    assert rep.verdict_kind == NOT_DECIDABLE
    u = next(u for u in rep.verdict_record.undecidable if u.code == "base_replay_error")
    assert u.blocking and "x the signal" in u.reason and "--params" in u.remedy
    replay = rep.compare["replay"]["all_windows_nominal"]
    assert replay["velocity_rms"] > 3 * replay["signal_rms"]["velocity"]


def test_current_at_the_drive_limit_gives_no_torque_constant_finding():
    rep = _diagnose(limited_run(NOMINAL))
    assert "torque_constant_error" not in rep.effects
    assert rep.verdict_kind == NOT_DECIDABLE and "clipped" in _codes(rep)
    assert "current at the drive's limit" in rep.verdict
    nc = next(x for x in rep.not_checkable if x["effect"] == "torque_constant_error")
    assert "drive's limit" in nc["reason"]


def test_short_holdout_is_not_decidable():
    rep = _diagnose(pd_run(NOMINAL, duration=4.0))
    assert rep.verdict_kind == NOT_DECIDABLE and _codes(rep) == ["holdout_too_short"], rep.verdict


# -- one verdict in every output ----------------------------------------------------------------------

def _outputs(tmp_path, capsys, csv, params_file, extra=()):
    j, d = tmp_path / "r.json", tmp_path / "rep"
    code = cli.main(["diagnose", str(csv), "--params", str(params_file), "--json", str(j), "--report", str(d),
                     "--no-plots", "--quiet", *extra])
    assert code == 0
    out = capsys.readouterr().out
    doc = json.loads(j.read_text())
    md = (d / "report.md").read_text()
    md_verdict = next(line for line in md.splitlines() if line.startswith("**Verdict: "))[len("**Verdict: "):-2]
    return out, doc, md, md_verdict


def test_same_verdict_on_stdout_report_and_json_full_route(tmp_path, capsys):
    sig = pd_run(NOMINAL, duration=4.0)
    csv = tmp_path / "run.csv"
    write_csv(csv, {"time": sig.time, **sig.channels})
    params_file = tmp_path / "p.yaml"
    dump_yaml(NOMINAL, params_file)
    out, doc, md, md_verdict = _outputs(tmp_path, capsys, csv, params_file)
    assert out.splitlines()[0] == doc["verdict"] == md_verdict
    assert doc["verdict_kind"] == NOT_DECIDABLE and doc["verdict_reasons"][0]["code"] == "holdout_too_short"
    assert "## Not decidable" in md and "--holdout-file" in md and "--holdout-file" in out


def test_torque_balance_route_one_schema_report_and_data_issues(tmp_path, capsys):
    """Torque and motion, no current: the torque-balance route writes report.md (``--report`` was ignored), the
    JSON has the full route's keys (compare.*, verdict_kind), and a 0.27 V "supply voltage" is a data issue."""
    p = ActuatorParams().replace(**{"effects.coulomb_friction": 0.02, "motor.viscous_damping": 2e-4})
    t, w, tau = dyno_run(p, duration=6.0, w_ref=lambda x: 3.0 * math.sin(2 * math.pi * 0.2 * x))
    csv = tmp_path / "dyno.csv"
    write_csv(csv, {"time": t, "torque": tau, "velocity": w, "bus_voltage": 0.27 + 0 * t})
    params_file = tmp_path / "p.yaml"
    dump_yaml(ActuatorParams(), params_file)
    out, doc, md, md_verdict = _outputs(tmp_path, capsys, csv, params_file)
    assert out.splitlines()[0] == doc["verdict"] == md_verdict
    assert doc["method"].startswith("torque balance") and "torque balance" in out
    full_keys = {"verdict", "verdict_kind", "verdict_reasons", "findings", "rejected", "data_issues", "not_checkable",
                 "compare", "setup", "notes", "residual_structure"}
    assert full_keys <= set(doc)
    assert doc["compare"]["equation_error"]["torque_balance"]["updated"]["holdout_rms"] > 0
    assert {"coulomb_friction"} <= {f["effect"] for f in doc["findings"]} and doc["verdict_kind"] == "found"
    bus = next(i for i in doc["data_issues"] if i["channel"] == "bus_voltage")
    assert bus["kind"] == "unit_suspect" and "0.27" in bus["detail"]
    assert "bus_voltage" in out and "bus_voltage" in md


def test_route_is_chosen_by_the_channels():
    p = ActuatorParams()
    t, w, tau = dyno_run(p, duration=1.0, w_ref=lambda x: 2.0)
    from bldc_actuator.diagnosis.signals import Signals

    assert route(Signals(t, {"torque": tau, "velocity": w}, "x")) == TORQUE_BALANCE
    assert route(Signals(t, {"torque": tau, "velocity": w, "current": 0 * t}, "x")) != TORQUE_BALANCE


def test_not_checkable_in_simulation_is_marked_in_every_output(tmp_path, capsys):
    f = {"effect": "thermal_parameters", "description": "d", "form": "f", "parameters": {"a": 1.0},
         "uncertainty": {"a": 0.1}, "units": {"a": ""}, "fields": {}, "simulated": True, "evidence": [],
         "held_out": {}, "metrics": [], "delta_bic": 20.0, "correlations": [],
         "simulation": {"verdict": "not checkable in simulation"}, "not_checkable_in_simulation": True}
    rec = decide(["thermal_parameters"], [], not_checkable_in_simulation=["thermal_parameters"])
    rep = DiagnosisReport(channels=[], findings=[f], rejected=[], windows=[], data_issues=[], not_checkable=[],
                          aliases=[], verdict_record=rec)
    rep.write_json(tmp_path / "r.json")
    rep.write_markdown(tmp_path / "md", plots=False)

    class Args:
        json = report = updated_params = None

    dcli._print_summary(rep, Args())
    out = capsys.readouterr().out
    doc = json.loads((tmp_path / "r.json").read_text())
    md = (tmp_path / "md" / "report.md").read_text()
    assert rec.text() == "found: missing physics: thermal_parameters (not checkable in simulation)"
    assert out.splitlines()[0] == doc["verdict"] == rec.text() and rec.text() in md
    assert "[not checkable in simulation]" in out and "### thermal_parameters (not checkable in simulation)" in md
    assert doc["findings"][0]["not_checkable_in_simulation"] is True


def test_verdict_kinds():
    assert decide([], []).kind == NOTHING_MISSING
    from bldc_actuator.diagnosis.results import Undecidable

    u = Undecidable("x", "why", blocking=True)
    v = decide(["a"], [u])
    assert v.kind == NOT_DECIDABLE and "suspected" in v.text() and "a" in v.text()
    with pytest.raises(ValueError, match="Verdict.kind"):
        type(v)("maybe")


def test_cli_takes_joint_with_map(tmp_path, capsys):
    """``--joint`` and ``--map`` together (they were exclusive): the profile reads the joint, the map fixes one
    column; the JSON says which column became the torque channel."""
    sig = pd_run(NOMINAL, duration=4.0)
    cols = {"time": sig.time}
    for j in (1, 2):
        cols[f"Position{j}"] = sig.channels["position"] / 9.0
        cols[f"Velocity{j}"] = sig.channels["velocity"] / 9.0
        cols[f"Cur{j}"] = sig.channels["current"]
        cols[f"Torque{j}"] = 0.0 * sig.time + 0.01 * j
    csv = tmp_path / "arm.csv"
    write_csv(csv, cols)
    params_file = tmp_path / "p.yaml"
    dump_yaml(NOMINAL, params_file)
    out, doc, md, md_verdict = _outputs(tmp_path, capsys, csv, params_file,
                                        extra=("--joint", "joint2", "--map", "torque=Torque{j}"))
    assert out.splitlines()[0] == doc["verdict"] == md_verdict
    assert "torque" in doc["channels"]
    assert any("--map over the input profile: torque=Torque2" in n for n in doc["notes"])
