"""A recording's declared drive tuning (bldc_actuator/drive_tuning.py): simulate's CSV declares the motor values its
drive's current loop was tuned with, the diagnosis replays the recording with that drive. Physics: the replay of
the true motor with the declared drive reproduces the recording's speed better than with a drive tuned on --params
(the drive that made it), and a malformed declaration is an error naming the key, range and unit."""

from __future__ import annotations

import numpy as np
import pytest

from bldc_actuator import drive_tuning
from bldc_actuator.params import controller_motor, load_preset


def test_a_declaration_reads_back_as_the_drive_fields():
    p = load_preset("ak80_9").replace(**{"motor.phase_resistance": 0.2, "drive.controller_inductance": 1e-4})
    back = drive_tuning.from_metadata(drive_tuning.declaration(p), "test")
    assert back == {"drive.controller_resistance": 0.2, "drive.controller_inductance": 1e-4,
                    "drive.controller_torque_constant": p.motor.torque_constant_q}
    nominal = load_preset("ak80_9")
    applied, note = drive_tuning.apply(nominal, back)
    assert controller_motor(applied) == pytest.approx(controller_motor(p))
    assert applied.motor == nominal.motor                   # the motor stays the user's nominal
    assert "drive.controller_resistance 0.2" in note
    assert drive_tuning.apply(nominal, None) == (nominal, None)
    assert drive_tuning.from_metadata({"voltage_timing": "applied"}, "test") is None


@pytest.mark.parametrize("raw", ["abc", "-0.1", "nan", "0"])
def test_a_malformed_declaration_names_the_key_range_and_unit(raw):
    with pytest.raises(ValueError, match=r"drive_tuned_with_phase_resistance_ohm: expected a positive number in ohm"):
        drive_tuning.from_metadata({"drive_tuned_with_phase_resistance_ohm": raw}, "f.csv comment lines")


def test_the_declared_drive_is_the_one_that_reproduces_the_recording(tmp_path):
    """R x1.3 simulated (its drive tuned on 0.169): prepared against the nominal 0.13, the context's drive is tuned on
    0.169, and the replay of the true motor with it tracks the recorded speed closer than with a drive tuned on 0.13."""
    from bldc_actuator.cli import main
    from bldc_actuator.diagnosis.frame import equation_error as ee
    from bldc_actuator.diagnosis.frame import simulate
    from bldc_actuator.diagnosis.io.cleaning import clean
    from bldc_actuator.diagnosis.io.loaders import load
    from bldc_actuator.params import dump_yaml

    nominal = load_preset("ak80_9")
    truth = nominal.replace(**{"motor.phase_resistance": 0.169})
    dump_yaml(truth, tmp_path / "r.yaml")
    assert main(["simulate", "--profile", "chirp", "--amplitude", "2", "--f0", "2", "--f1", "40", "--duration", "4",
                 "--rate", "5000", "--no-plot", "--params", str(tmp_path / "r.yaml"), "--out", str(tmp_path / "r")]) == 0
    sig = clean(load(tmp_path / "r.csv", params=nominal))
    ctx = ee.prepare([(sig, False)], nominal)
    assert controller_motor(ctx.params)[0] == pytest.approx(0.169)
    assert ctx.params.motor.phase_resistance == pytest.approx(0.13)
    assert any("declares the motor values its drive" in n for n in ctx.notes)
    starts = list(range(200, len(ctx.t) - 2000, 2000))
    import copy
    bare = copy.copy(sig)
    bare.meta = dict(sig.meta, declared={k: v for k, v in sig.meta["declared"].items() if k not in drive_tuning.KEYS})
    ctx_bare = ee.prepare([(bare, False)], nominal)            # no declaration: a drive tuned on --params' 0.13
    assert controller_motor(ctx_bare.params)[0] == pytest.approx(0.13)
    true_motor = nominal.replace(**{"motor.phase_resistance": 0.169})
    declared, undeclared = (float(np.mean(simulate.replay(c, [true_motor], starts, 0.1)[0]["per_window"]["velocity"]))
                            for c in (ctx, ctx_bare))
    assert declared < 0.8 * undeclared          # 0.073 against 0.113 rad/s here


def _csv(path, tuning: dict[str, str]):
    lines = [f"# {k}: {v}" for k, v in tuning.items()]
    path.write_text("\n".join(lines + ["time,current,voltage_q", "0,1,2", "0.001,1,2", ""]))
    return path


def test_a_malformed_declaration_is_refused_at_load_and_different_tunings_are_not_merged(tmp_path):
    from bldc_actuator.diagnosis.io.loaders import load, load_many
    from bldc_actuator.diagnosis.io.mapping import LoadError

    bad = _csv(tmp_path / "bad.csv", {"drive_tuned_with_q_inductance_h": "-1"})
    with pytest.raises(LoadError, match=r"bad.csv.*drive_tuned_with_q_inductance_h: expected a positive number in H"):
        load(bad)
    a = _csv(tmp_path / "a.csv", {"drive_tuned_with_phase_resistance_ohm": "0.13"})
    b = _csv(tmp_path / "b.csv", {"drive_tuned_with_phase_resistance_ohm": "0.169"})
    assert drive_tuning.declared([load_many([a, a])]) == {"drive.controller_resistance": 0.13}
    with pytest.raises(LoadError, match="different current-loop tunings"):
        load_many([a, b])


def test_an_mcap_declares_each_joints_tuning(tmp_path):
    """The node's MCAP metadata: the first joint's pairs, another joint's own as ``<key>.<joint>``."""
    from bldc_actuator.diagnosis.io.mapping import LoadError
    from bldc_actuator.diagnosis.io.mcapio import declared_pairs, declared_voltage_timing

    p = load_preset("ak80_9")
    knee = p.replace(**{"motor.phase_resistance": 0.2})
    meta = {"node": "/a", **drive_tuning.declaration(p)}
    meta.update({f"{k}.knee": v for k, v in drive_tuning.declaration(knee).items()})
    rec = [("bldc_actuator", meta)]
    assert drive_tuning.from_metadata(declared_pairs(rec, "hip"), "t")["drive.controller_resistance"] == \
        pytest.approx(p.motor.phase_resistance)
    assert drive_tuning.from_metadata(declared_pairs(rec, "knee"), "t")["drive.controller_resistance"] == 0.2
    with pytest.raises(LoadError, match="drive_tuned_with_torque_constant_q_nm_per_a"):
        declared_voltage_timing([("bldc_actuator", {"drive_tuned_with_torque_constant_q_nm_per_a": "x"})], None,
                                tmp_path / "r.mcap")
