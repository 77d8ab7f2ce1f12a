"""Issue #14, symptom 1: the replay's window start must be the steady state of the drive being simulated, for
every drive option the model has (decoupling on/off, sensor offsets and gains, dead time, loop delay, the
voltage-limit modes at the limit). Recordings from the project's own closed-loop Actuator under the truth; the
replay (multiple shooting from recorded states) under the TRUE parameters must then start without a transient
and beat the nominal ones."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bldc_actuator.diagnosis.frame import equation_error as ee
from bldc_actuator.diagnosis.frame import simulate
from bldc_actuator.diagnosis.pipeline import DiagnoseOptions, diagnose
from bldc_actuator.params import ActuatorParams

from test_issue14_judge_helpers import closed_loop_recording

BASE = ActuatorParams().replace(**{"gear.gear_ratio": 9.0})


def reference(t):
    """Motor-side angle [rad]: slow large swings (up to ~30 rad/s) and faster small ones."""
    return 3 * np.sin(2 * np.pi * 0.4 * t) + 1.5 * np.sin(2 * np.pi * 1.3 * t) + 8 * np.sin(2 * np.pi * 0.11 * t)


def _ctx(sig, p):
    return ee.prepare([(sig, False)], p)


def test_no_decoupling_delta_drive_the_true_torque_constant_replays_best_and_is_accepted():
    """The issue's case: a delta drive without back-EMF feed-forward, K_t sqrt(3/2) above nominal. Started with
    ``z_q = R i`` every window opened with a current transient growing with K omega (replay speed error:
    nominal 1.28, TRUE K 1.79 rad/s). The drive's integrator holds R i + K omega: the true K now replays an
    order of magnitude better, and diagnose accepts and writes it."""
    nom = BASE.replace(**{"motor.winding": "delta", "drive.decoupling_enabled": False})
    true = nom.replace(**{"motor.torque_constant_q": nom.motor.torque_constant_q * math.sqrt(1.5)})
    sig = closed_loop_recording(true, nom, reference, duration=20.0, seed=1)
    ctx = _ctx(sig, nom)
    starts = simulate.windows(ctx, 0.1, 120, "all")
    r = simulate.replay(ctx, [nom, true], starts, 0.1)
    assert r[1]["velocity_rms"] < 0.2 * r[0]["velocity_rms"], (r[0]["velocity_rms"], r[1]["velocity_rms"])
    rep = diagnose(sig, nom, options=DiagnoseOptions())
    assert [f["effect"] for f in rep.to_dict()["findings"]] == ["torque_constant_error"]
    assert rep.updated_params.motor.torque_constant_q == pytest.approx(true.motor.torque_constant_q, rel=0.01)


DRIVES = {
    "decoupling_off_wye": {"drive.decoupling_enabled": False},
    "sensor_gain_and_offset": {"drive.current_sensor_gain_a": 1.06, "drive.current_sensor_gain_b": 0.95,
                               "drive.current_sensor_offset_a": 0.15},
    "dead_time": {"drive.dead_time": 1e-6},
    "dead_time_delta_no_decoupling": {"drive.dead_time": 1e-6, "motor.winding": "delta",
                                      "drive.decoupling_enabled": False},
    "loop_delay_no_decoupling": {"drive.current_loop_delay": 1e-4, "drive.decoupling_enabled": False},
    "q_priority_at_the_limit": {"drive.voltage_limit_mode": "q_priority", "drive.bus_voltage": 3.0},
    "d_priority_at_the_limit_no_decoupling": {"drive.voltage_limit_mode": "d_priority", "drive.bus_voltage": 3.0,
                                              "drive.decoupling_enabled": False},
}


#: the bound [A] on the first 3 ms where the dead time sets the floor (else 0.035 A, against 0.03 A sensor noise)
DEAD_TIME_BOUND = {"dead_time": 0.05, "dead_time_delta_no_decoupling": 0.07}


@pytest.mark.parametrize("name", sorted(DRIVES))
def test_every_window_starts_in_the_drives_own_steady_state(name):
    """Replayed under the parameters that made the recording, the simulated current of the first 3 ms of each
    window follows the recording to the sensor noise (0.03 A): no start transient, whatever the drive option
    (the old start, ``z = R i`` whatever the drive, gave 0.048 A for decoupling off and 0.069 A for d priority
    at the limit without decoupling; all are now 0.019-0.021 A).

    Dead time (1 µs: V_dt = 0.48 V per leg against currents of 0.05-0.3 A): the drive's integrator holds
    ``R i`` plus the dead-time hexagon (0.68-0.78 V), which the start now puts in (the kernel's own
    interval-average error at the steady interval change). The floor is not the noise: the line currents sit
    clamped at zero for much of each electrical period, and the low-passed recording misses the true current by
    0.038 A rms (wye) and 0.053 A (delta), so a replay started from the recording drive's own integrator scores
    0.033-0.036 A (wye, seeds 1-6) and 0.051 A (delta without decoupling). The start scores 0.040-0.044 A and
    0.050-0.054 A; started at ``z = R i`` (the dead time left out, as before) 0.216-0.220 A and 0.31 A."""
    truth = BASE.replace(**DRIVES[name])
    sig = closed_loop_recording(truth, truth, reference, duration=8.0, seed=3, noise_i=0.03)
    ctx = _ctx(sig, truth)
    starts = simulate.windows(ctx, 0.1, 60, "all")
    sim = simulate.simulate_windows(ctx, [truth], starts, 0.1)
    head = sim["sim_i"][:3] - sim["meas_i"][:3]
    err = float(np.sqrt(np.mean(head ** 2)))
    assert err < DEAD_TIME_BOUND.get(name, 0.035), err
    if "limit" in name:   # windows start at the voltage limit (else the case tests nothing)
        v = np.hypot(sig.channels["voltage_q"], sig.channels["voltage_d"])
        assert np.sum(v[np.array(starts)] > 0.97 * 3.0 / math.sqrt(2)) >= 1


def test_a_drive_unlike_the_users_parameters_is_judged_by_the_measured_current():
    """Coulomb friction behind a drive whose parameters the user got wrong (the file says a 0.15 A current
    limit; the drive limits at 20 A): the emulated drive clips its commands and misses the recorded current
    (the drive check, reported as a number, fails), so the torque-side finding is judged by the mechanical
    equation driven by the MEASURED current, which needs nothing of the drive, and confirmed (before: refused,
    "not checkable in simulation", the emulated drive's speed error 52 % of the recorded speed)."""
    nominal = BASE
    truth = nominal.replace(**{"effects.coulomb_friction": 0.02})
    user = nominal.replace(**{"drive.current_limit": 0.15})
    sig = closed_loop_recording(truth, nominal, reference, duration=16.0, seed=5)
    rep = diagnose(sig, user, options=DiagnoseOptions())
    f = rep.finding("coulomb_friction")
    assert f is not None and f["parameters"]["coulomb_friction"] == pytest.approx(0.02, rel=0.02)
    sim = f["simulation"]
    assert sim["verdict"] == "confirmed" and sim["replay"].startswith("mechanical equation driven by the measured")
    chk = sim["drive_check"]
    assert not chk["ok"] and chk["current_error_rms"] > 2 * chk["current_noise"]
    assert sim["with"] < 0.05 * sim["without"]
    # the drive described right: the emulation reproduces the current, and the closed-loop replay (reported
    # beside the measured-current one, which judges a torque-side finding wherever the current is recorded) agrees
    rep2 = diagnose(sig, nominal, options=DiagnoseOptions())
    sim2 = rep2.finding("coulomb_friction")["simulation"]
    assert sim2["drive_check"]["ok"] and sim2["replay"].startswith("mechanical equation driven by the measured")
    assert sim2["verdict"] == "confirmed" and sim2["closed_loop_replay"]["verdict"] == "confirmed"


def test_a_true_torque_constant_behind_a_drive_without_feed_forward_is_judged_by_the_measured_current():
    """Issue #14 (third-party set, tp_kt): K_t x1.15 behind a drive WITHOUT back-EMF feed-forward while the
    user's file says it has one (motulator's current controller has none: its integrator carries the back-EMF).
    While the speed changes such a drive delivers less current than its command (the back-EMF ramp its own torque
    causes is a disturbance the integrator follows with a lag: i / i_ref ~ 1 / (1 + K^2 / (J K_i)), here ~20 %
    short), and the emulated drive, which delivers its command, already gives the nominal K too much torque: the
    true K made its simulated speed WORSE (0.62 -> 1.06 rad/s; the old judge refused the finding). The
    mechanical equation driven by the measured current needs nothing of the drive and confirms it (0.60 -> 0.33
    rad/s); the closed-loop verdict is reported beside it, with the drive identified from the recorded current."""
    nominal = ActuatorParams().replace(**{"drive.current_loop_bandwidth": 500.0})
    truth = nominal.replace(**{"drive.decoupling_enabled": False,
                               "motor.torque_constant_q": 1.15 * nominal.motor.torque_constant_q})
    sig = closed_loop_recording(truth, nominal, reference, duration=16.0, seed=1)
    rep = diagnose(sig, nominal, options=DiagnoseOptions())
    f = rep.finding("torque_constant_error")
    assert f is not None, rep.to_dict()["verdict"]
    assert f["parameters"]["torque_constant_q"] == pytest.approx(truth.motor.torque_constant_q, rel=0.02)
    sim = f["simulation"]
    assert sim["verdict"] == "confirmed" and sim["replay"].startswith("mechanical equation driven by the measured")
    assert sim["with"] < 0.7 * sim["without"]
    # the drive's missing feed-forward is identified from the recorded current (drive_feedforward.py) and the
    # closed-loop replay then runs that drive: there the true K improves the simulated speed too (before the
    # identification the file's drive made it worse, 0.62 -> 1.06 rad/s)
    assert rep.updated_params.drive.decoupling_enabled is False
    assert rep.finding("drive_current_controller")["simulation"]["verdict"] == "confirmed"
    closed = sim["closed_loop_replay"]
    assert closed["verdict"] == "confirmed" and closed["with"] < closed["without"]
