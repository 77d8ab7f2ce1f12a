"""The third-party case sets' cache and truth (benchmarks/concealed/{case_kit,thirdparty,gem_cases}.py).

A peer simulator takes 7-17 s per simulated second, so a case's recordings are keyed by what makes them (the
simulation module's code, the writers, the case's recording spec: plant, the drive's tuning from the nominal file,
seeds, durations, log rate, sensors; library versions) and by nothing else: its truth (effects, values, aliases,
story, channel) and the nominal fields the simulated drive does not read are rewritten from the case on every
run without simulating. Runs without motulator or gym-electric-motor (nothing here simulates with them).
"""

from __future__ import annotations

import hashlib
import json
import sys
import types
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from benchmarks import run_concealed as R  # noqa: E402
from benchmarks.concealed import case_kit as kit  # noqa: E402
from benchmarks.concealed import gem_cases as G  # noqa: E402
from benchmarks.concealed import scoring  # noqa: E402
from benchmarks.concealed import thirdparty as T  # noqa: E402


def _truth_edits(case):
    """Edits of a case that change its truth or its nominal file but not what its simulation reads."""
    return [replace(case, story=case.story + " (reworded)"),
            replace(case, effects=case.effects + ("drive_current_controller",),
                    truth={**case.truth, "drive_current_controller": {"decoupling_enabled": False}}),
            replace(case, alias_ok={"dead_time": ("resistance_error",)}),
            replace(case, channel="voltage_q" if case.channel == "current" else "current"),
            replace(case, nominal={**case.nominal, "drive.decoupling_enabled": True}),
            replace(case, nominal={**case.nominal, "effects.coulomb_friction": 0.01}),   # a belief the drive ignores
            replace(case, name=case.name + "_renamed")]


@pytest.mark.parametrize("S", [T, G], ids=["motulator", "gem"])
def test_truth_only_edits_keep_every_recording_key(S):
    for case in S.CASES:
        key = S.recording_key(case)
        for edited in _truth_edits(case):
            assert S.recording_key(edited) == key, (case.name, edited)


def test_what_makes_a_motulator_recording_moves_its_key():
    case = T.get_case("tp_resistance")
    key = T.recording_key(case)
    moved = [replace(case, plant={"R_s": 0.2}),                               # the truth plant
             replace(case, plant={**case.plant, "F_c": 0.02}),
             replace(case, nominal={"motor.phase_resistance": 0.15}),        # the drive is tuned with it
             replace(case, nominal={"motor.rotor_inertia": 1e-4}),           # the speed loop is tuned with it
             replace(case, drive={"alpha_c_hz": 300.0}),
             replace(case, seed=case.seed + 1), T.reseeded(case, 2),
             replace(case, log_rate=10000.0), replace(case, train_s=5.0), replace(case, heldout_s=3.0),
             replace(case, torque_sensor=True)]
    keys = [T.recording_key(c) for c in moved]
    assert key not in keys and len(set(keys)) == len(keys)
    # the plant change is what moves it: the same plant reached another way keeps the key
    assert T.recording_key(replace(case, plant={"R_s": 0.182, "F_c": 0.0})) == key


def test_what_makes_a_gem_recording_moves_its_key():
    case = G.get_case("gem_resistance_loaded")
    key = G.recording_key(case)
    moved = [replace(case, motor={"r_s": 0.2}), replace(case, load={"b": 1e-4}), replace(case, tau_ext=0.3),
             replace(case, interlocking_time=1e-6), replace(case, nominal={**case.nominal, "motor.rotor_inertia": 1e-4}),
             replace(case, drive_knows_saliency=True, motor={**case.motor, "l_d": 6e-5}),
             replace(case, seed=case.seed + 1), replace(case, log_rate=100.0), replace(case, train_s=7.0)]
    keys = [G.recording_key(c) for c in moved]
    assert key not in keys and len(set(keys)) == len(keys)


def test_the_key_covers_the_simulation_code_and_the_writers(tmp_path):
    src = tmp_path / "fake_sim.py"
    src.write_text("X = 1\n")
    mod = types.ModuleType("fake_sim")
    mod.__file__ = str(src)
    spec = {"plant": {"R_s": 0.13}, "seeds": {"train": 1}}

    def writer_a(run):
        return run

    def writer_b(run):
        return run * 2

    k0 = kit.recording_key(spec, mod, (), (writer_a,))
    assert kit.recording_key(dict(spec), mod, (), (writer_a,)) == k0
    assert kit.recording_key({**spec, "plant": {"R_s": 0.14}}, mod, (), (writer_a,)) != k0
    assert kit.recording_key(spec, mod, (), (writer_b,)) != k0
    assert kit.recording_key(spec, mod, ("motulator",), (writer_a,)) != k0      # the peer's version enters
    src.write_text("X = 2\n")
    assert kit.recording_key(spec, mod, (), (writer_a,)) != k0


def test_builtin_set_keeps_its_generator_stamp():
    """The builtin set's cache stays valid: its stamp is still the hash of its generator's sources + numpy."""
    import numpy

    h = hashlib.sha256()
    for name in ("truth.py", "truth_kernel.c", "excitation.py", "cases.py", "oracle.py"):
        h.update((REPO / "benchmarks" / "concealed" / name).read_bytes())
    h.update(numpy.__version__.encode())
    assert R.generator_hash("builtin") == h.hexdigest()[:16]


@dataclass(frozen=True)
class _Case:
    name: str
    plant: float
    story: str = ""
    effects: tuple = ()
    channel: str = "current"
    nominal: dict = field(default_factory=dict)
    train_s: float = 0.01
    heldout_s: float = 0.01
    seed: int = 0

    @property
    def is_null(self):
        return not self.effects


def _fake_set(calls):
    mod = types.ModuleType("fake_sim")
    mod.__file__ = __file__

    def key(case):
        return kit.recording_key({"plant": case.plant, "seeds": kit.seeds(case)}, mod, ())

    def job(args):
        case, role, duration, seed = args
        calls.append((case.name, role))
        return case.name, role, {"w": np.full(5, case.plant), "t": np.arange(5) * 1e-3}, 0.0

    def write_recordings(case, runs, d):
        for role in ("train", "heldout"):
            kit.write_csv(d / f"{role}.csv", {"time": runs[role]["t"], "w": runs[role]["w"]}, ("time", "w"))
        kit.save_train_truth(d / "train_truth.npz", **runs["train"])

    def write_truth(case, d):
        sig = kit.load_train_truth(d / "train_truth.npz")
        truth = {"case": case.name, "story": case.story, "effects": list(case.effects),
                 "concealment": kit.concealment(case, float(np.sqrt(np.mean(sig["w"] ** 2))), 0.03, 0.01)}
        (d / "truth.json").write_text(json.dumps(truth))
        return truth

    return dict(key=key, simulate_job=job, write_recordings=write_recordings, write_truth=write_truth,
                label="fake", workers=1)


def test_ensure_simulates_only_what_moved_and_rewrites_every_truth(tmp_path):
    calls: list = []
    fs = _fake_set(calls)
    cases = [_Case("a", 1.0, effects=("x",)), _Case("b", 2.0)]
    truths, made = kit.ensure(cases, tmp_path, **fs)
    assert made == ["a", "b"] and len(calls) == 4
    assert truths["a"]["concealment"]["effect_rms"] == pytest.approx(1.0)
    csv_a = (tmp_path / "a" / "train.csv").read_bytes()
    # a truth-only edit and an added case: only the new case is simulated, the edited truth is on disk
    calls.clear()
    cases = [replace(cases[0], story="new story", channel="voltage_q"), cases[1], _Case("c", 3.0)]
    truths, made = kit.ensure(cases, tmp_path, **fs)
    assert made == ["c"] and sorted(calls) == [("c", "heldout"), ("c", "train")]
    on_disk = json.loads((tmp_path / "a" / "truth.json").read_text())
    assert on_disk["story"] == "new story" and on_disk["concealment"]["channel"] == "voltage_q"
    assert (tmp_path / "a" / "train.csv").read_bytes() == csv_a
    # the plant moves: that case alone is simulated again, and its truth follows its new recordings
    calls.clear()
    cases[1] = replace(cases[1], plant=4.0, effects=("y",))
    truths, made = kit.ensure(cases, tmp_path, **fs)
    assert made == ["b"] and len(calls) == 2
    assert truths["b"]["concealment"]["effect_rms"] == pytest.approx(4.0)
    # a lost recording is simulated again; --regenerate simulates everything
    (tmp_path / "c" / "heldout.csv").unlink()
    assert kit.ensure(cases, tmp_path, **fs)[1] == ["c"]
    assert kit.ensure(cases, tmp_path, regenerate=True, **fs)[1] == ["a", "b", "c"]


def test_nominal_files_state_each_drive_as_it_is():
    """motulator's current controller is a complex-vector PI without back-EMF feed-forward: the nominal file says
    so, except in the cases that hide exactly that (their file claims a d/q PI with the feed-forward; truth:
    drive_current_controller, the form complex_vector without feed-forward). The drive written around GEM is a PI
    that feeds the back-EMF and the cross-coupling forward: its file says pi, true."""
    for case in T.CASES:
        d = T.nominal_params(case).drive
        if "drive_current_controller" in case.effects:
            assert (d.current_controller, d.decoupling_enabled) == ("pi", True)
            assert case.truth["drive_current_controller"] == {
                "drive_form": "complex_vector without feed-forward", "current_controller": "complex_vector",
                "decoupling_enabled": False}
        else:
            assert (d.current_controller, d.decoupling_enabled) == ("complex_vector", False), case.name
    drive_cases = {c.name for c in T.CASES if "drive_current_controller" in c.effects}
    assert drive_cases == {"tp_drive_ff", "tp_coulomb_drive_ff"}
    assert set(T.get_case("tp_coulomb_drive_ff").effects) == {"coulomb_friction", "drive_current_controller"}
    assert len({c.seed for c in T.CASES}) == len(T.CASES)          # every case its own seed
    for case in G.CASES:
        assert G.nominal_params(case).drive.decoupling_enabled is True
        assert G.nominal_params(case).drive.current_controller == "pi"
        assert "drive_current_controller" not in case.effects


def test_scoring_counts_the_drive_current_controller_finding():
    truth = {"case": "tp_coulomb_drive_ff", "effects": ["coulomb_friction", "drive_current_controller"],
             "truth": {"coulomb_friction": {"coulomb_friction": 0.02},
                       "drive_current_controller": {"decoupling_enabled": False}}}
    finding = {"effect": "drive_current_controller", "parameters": {"decoupling_enabled": False},
               "held_out": {"before": 0.03, "after": 0.02}}
    coulomb = {"effect": "coulomb_friction", "parameters": {"coulomb_friction": 0.0198}}
    s = scoring.score_case(truth, {"findings": [coulomb, finding]}, {})
    assert s.ok and not s.false_positives
    dd = next(e for e in s.effects if e.effect == "drive_current_controller")
    assert dd.value_correct is True and dd.estimate is False and dd.rel_error is None
    assert scoring.summarise([s])["parameters_scored"] == 1          # the flag is not a relative error
    assert "false" in scoring.rows([s], {"tp_coulomb_drive_ff": {}})[0][5]
    # a flag the wrong way round, or a number where the flag belongs, is not a correct estimate
    wrong = dict(finding, parameters={"drive.decoupling_enabled": True})
    assert next(e for e in scoring.score_case(truth, {"findings": [coulomb, wrong]}, {}).effects
                if e.effect == "drive_current_controller").value_correct is False
    number = dict(finding, parameters={"decoupling_enabled": 0.0})
    assert next(e for e in scoring.score_case(truth, {"findings": [coulomb, number]}, {}).effects
                if e.effect == "drive_current_controller").estimate is None
    # missed on the combined case: counted as missed, Coulomb still scored
    s = scoring.score_case(truth, {"findings": [coulomb]}, {})
    assert s.missed == ["drive_current_controller"] and not s.ok
    # where the file is right about the drive, naming it is an extra / a false positive as before
    plain = {"case": "tp_null", "effects": [], "truth": {}}
    assert scoring.score_case(plain, {"findings": [finding]}, {}).false_positives == ["drive_current_controller"]


def test_scoring_counts_the_drive_form_the_finding_names():
    """The third-party drive cases' truth is the drive FORM (controller law + feed-forward): a finding that names
    complex_vector without feed-forward is correct; one that only clears the feed-forward flag of a PI is not."""
    truth = {"case": "tp_drive_ff", "effects": ["drive_current_controller"],
             "truth": {"drive_current_controller": T.DRIVE_TRUTH}}
    right = {"effect": "drive_current_controller", "parameters": {"drive_form": "complex_vector without feed-forward",
                                                                 "current_controller": "complex_vector",
                                                                 "decoupling_enabled": False}}
    composed = {"effect": "drive_current_controller", "parameters": {"current_controller": "complex_vector",
                                                                    "decoupling_enabled": False}}
    flag_only = {"effect": "drive_current_controller", "parameters": {"decoupling_enabled": False}}
    for f, ok in ((right, True), (composed, True), (flag_only, False)):
        s = scoring.score_case(truth, {"findings": [f]}, {})
        assert s.ok and not s.false_positives
        (e,) = s.effects
        assert e.parameter == "drive_form" and e.value_correct is ok, (f, e)


def test_reports_and_truths_written_under_the_former_name_score_under_todays():
    """The drive-side finding was called ``drive_decoupling`` until it named the whole current-controller form
    (``drive_current_controller``): a report, or a truth file, written before the rename is scored as today's, so an
    old run's findings count as found (not as a miss plus an extra)."""
    from bldc_actuator.diagnosis import drive_feedforward

    assert drive_feedforward.EFFECT == "drive_current_controller"
    assert scoring.RENAMED_EFFECTS == drive_feedforward.FORMER_EFFECTS
    new_truth = {"case": "tp_drive_ff", "effects": ["drive_current_controller"],
                 "truth": {"drive_current_controller": T.DRIVE_TRUTH}}
    old_truth = {"case": "tp_drive_ff", "effects": ["drive_decoupling"], "truth": {"drive_decoupling": T.DRIVE_TRUTH}}
    params = {"drive_form": "complex_vector without feed-forward", "current_controller": "complex_vector",
              "decoupling_enabled": False}
    old_report = {"findings": [{"effect": "drive_decoupling", "parameters": params}],
                  "rejected": [{"effect": "drive_decoupling", "reason": "x"}]}
    new_report = {"findings": [{"effect": "drive_current_controller", "parameters": params}]}
    for truth in (new_truth, old_truth):
        for report in (old_report, new_report):
            s = scoring.score_case(truth, report, {})
            assert s.ok and s.found == ["drive_current_controller"] and not s.false_positives, (truth, report)
            assert s.effects[0].value_correct is True
    # the input is not modified
    assert old_report["findings"][0]["effect"] == "drive_decoupling" and old_truth["effects"] == ["drive_decoupling"]
