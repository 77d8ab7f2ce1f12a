"""Which replay judges a torque-side finding (``judge.simulated.torque_side_replay``): the rule on the verdicts of
the builtin case that exposed each clause (figures from the runs named in each test)."""

from __future__ import annotations

from bldc_actuator.diagnosis.judge.simulated import (REPLAY_CLOSED_LOOP, REPLAY_MEASURED_CURRENT,
                                                     torque_side_replay)


def _cd(verdict, without, with_, corrected, worse=False):
    return {"verdict": verdict, "without": without, "with": with_, "worse": worse,
            "noise_corrected": {"without": corrected[0], "with": corrected[1]}}


def _check(ok, ok_raw, close=False):
    return {"ok": ok, "ok_raw_noise": ok_raw, "close": close}


CLOSED_CONFIRMED = {"verdict": "confirmed", "without": 0.4906, "with": 0.2967, "noise_floor": 0.080, "worse": None}


def test_a_blind_measured_current_replay_hands_over_to_the_closed_loop_under_the_raw_noise_check():
    # kt_frame_10khz (10 kHz drive log, 0.043 A RMS current under 0.17 A noise): the measured-current replay's
    # noise drift (0.70 / 0.86 rad/s) is its whole error (0.70 -> 0.34): blind; the drive misses the current by
    # 0.074 A: within 1.5 x the raw noise, not within 1.5 x the 0.025 A left after the low-pass
    blind = _cd("not confirmed", 0.698, 0.336, (0.0, 0.0))
    assert torque_side_replay(blind, CLOSED_CONFIRMED, _check(False, True)) == REPLAY_CLOSED_LOOP
    # ... but not when the drive fails the raw-noise check too: then nothing better is left
    assert torque_side_replay(blind, CLOSED_CONFIRMED, _check(False, False)) == REPLAY_MEASURED_CURRENT


def test_an_unresolved_but_not_blind_replay_needs_the_full_drive_check():
    unresolved = _cd("not confirmed", 0.62, 0.60, (0.31, 0.29))
    assert torque_side_replay(unresolved, CLOSED_CONFIRMED, _check(True, True)) == REPLAY_CLOSED_LOOP
    # the third-party tp_kt drive (no feed-forward behind a file that says it has one): raw-noise pass only
    assert torque_side_replay(unresolved, CLOSED_CONFIRMED, _check(False, True)) == REPLAY_MEASURED_CURRENT


def test_a_confirmed_finding_is_kept_unless_a_close_drive_contradicts_it():
    confirmed = _cd("confirmed", 3.19, 2.60, (3.0, 2.4))
    closed_worse = {"verdict": "not confirmed", "without": 0.94, "with": 2.97, "noise_floor": 0.05, "worse": True}
    # r_thermal_30min: the drive reproduces the current to 0.2 % of its RMS and its replay gets 3x worse
    assert torque_side_replay(confirmed, closed_worse, _check(True, True, close=True)) == REPLAY_CLOSED_LOOP
    assert torque_side_replay(confirmed, closed_worse, _check(True, True, close=False)) == REPLAY_MEASURED_CURRENT
    assert torque_side_replay(confirmed, CLOSED_CONFIRMED, _check(True, True, close=True)) == REPLAY_MEASURED_CURRENT
