"""The drive's back-EMF / cross-coupling feed-forward identified from a recording (issue #14,
bldc_actuator/diagnosis/drive_feedforward.py): recordings of the simulated actuator (current-command steps, sensor
noise, a quantised encoder; the bus high enough that the voltage limit is never reached) whose drive has no
feed-forward (``drive.decoupling_enabled: false``: its integrator carries the back-EMF, so it delivers less than
its command while the speed changes), diagnosed against a file that says it has one. The closed-loop replay's
CURRENT must name the recording's drive, and only when the file is wrong; a K_t x1.15 behind such a drive must then
simulate the held-out windows better with the updated parameters, because of the identified option."""

from __future__ import annotations

import pytest

from bldc_actuator.diagnosis import drive_feedforward
from bldc_actuator.diagnosis.frame import equation_error as ee
from bldc_actuator.diagnosis.frame import simulate as refit
from bldc_actuator.diagnosis.pipeline import diagnose

from test_drive_modes import NOMINAL, steps_recording

FILE = NOMINAL.replace(**{"drive.bus_voltage": 200.0})       # never at the voltage limit: the modes play no part
K = FILE.motor.torque_constant_q


def _identify(truth_decoupling: bool, file_decoupling: bool, seed: int):
    truth = FILE.replace(**{"drive.decoupling_enabled": truth_decoupling})
    nominal = FILE.replace(**{"drive.decoupling_enabled": file_decoupling})
    ctx = ee.prepare([(steps_recording(truth, duration=8.0, seed=seed), False)], nominal, fc=None, holdout=0.3)
    return drive_feedforward.identify(ctx, nominal, refit.windows(ctx, 0.1, 60, "train"),
                                      refit.windows(ctx, 0.1, 60, "holdout"), 0.1)


@pytest.mark.parametrize("truth, file", [(False, True), (True, False)])
def test_identify_names_the_recording_drive_feedforward(truth, file):
    r = _identify(truth, file, seed=3)
    (f,) = r["findings"]
    assert f["updated_fields"] == {"drive.decoupling_enabled": truth} and r["updated_fields"] == f["updated_fields"]
    s = f["simulation"]
    assert s["with"] < s["without"] - s["noise_floor"] and s["candidate"] is truth
    tr = s["training_current_error"]
    assert tr[drive_feedforward._label(truth)] < tr[drive_feedforward._label(file)]


@pytest.mark.parametrize("decoupling", [True, False])
def test_identify_finds_nothing_when_the_file_is_right(decoupling):
    r = _identify(decoupling, decoupling, seed=4)
    assert not r["findings"] and not r["updated_fields"] and r["rejected"]
    assert "reproduces the recorded current best" in r["rejected"][0]["reason"]


def test_kt_behind_a_drive_without_feedforward_simulates_better_with_the_identified_option():
    truth = FILE.replace(**{"drive.decoupling_enabled": False, "motor.torque_constant_q": 1.15 * K})
    rep = diagnose(steps_recording(truth, duration=8.0, seed=5), FILE)
    d = rep.to_dict()
    assert {f["effect"] for f in d["findings"]} == {"torque_constant_error", drive_feedforward.EFFECT}, d["verdict"]
    up = rep.updated_params
    assert up.drive.decoupling_enabled is False
    assert up.motor.torque_constant_q == pytest.approx(1.15 * K, rel=0.03)
    assert any("drive.decoupling_enabled: false" in n for n in d["notes"])
    ho = d["compare"]["replay"]["holdout"]
    assert ho["after"]["velocity_rms"] < 0.5 * ho["before"]["velocity_rms"]
    assert ho["after"]["current_rms"] < ho["before"]["current_rms"]
    # ...because of the identified option: the same updated motor behind the file's drive replays worse
    ctx = rep._internals["ctx"]
    starts = refit.windows(ctx, 0.1, 60, "holdout")
    found, file_drive = refit.replay(ctx, [up, up.replace(**{"drive.decoupling_enabled": True})], starts, 0.1)
    assert found["current_rms"] < file_drive["current_rms"]
    assert found["velocity_rms"] < file_drive["velocity_rms"]


def test_drive_check_excuses_only_the_noise_the_low_pass_leaves():
    """The emulated drive's current is compared with the LOW-PASSED recording: an error within 1.5 x the raw
    sensor noise but above 1.5 x the noise left after the low-pass is a drive that does not reproduce the current
    (third-party tp_kt: 0.0243 A against a raw noise of 0.0265 A), unless it is small against the current itself."""
    from bldc_actuator.diagnosis.judge import simulated as judge

    sig = steps_recording(FILE, duration=4.0, seed=6, noise=0.05)
    ctx = ee.prepare([(sig, False)], FILE, fc=None, holdout=0.3)
    probe = judge.drive_check(ctx, {"current_rms": 0.0, "signal_rms": {"current": 1.0}})
    raw, left = probe["current_noise"], probe["current_noise_lowpassed"]
    assert left < 0.7 * raw      # the low-pass removes most of the white noise
    assert left == pytest.approx(judge.current_noise_rms(ctx) * (ctx.dec.fc / (0.5 * ctx.fs)) ** 0.5)
    tiny_signal = {"current": 1e-3}          # the fraction-of-signal clause cannot pass
    between = judge.drive_check(ctx, {"current_rms": 1.4 * raw, "signal_rms": tiny_signal})
    assert 1.4 * raw > 1.5 * left and not between["ok"]
    assert judge.drive_check(ctx, {"current_rms": 1.4 * left, "signal_rms": tiny_signal})["ok"]
    assert judge.drive_check(ctx, {"current_rms": 1.4 * raw, "signal_rms": {"current": 10 * raw}})["ok"]
