"""Issue #14 (the gym-electric-motor benchmark, "a judge that does not depend on what it cannot know"): whether
the drive held each logged command over the sample interval is a property of the recording, not of its rate.

The window replay held every command of a log at or above 500 Hz. A drive whose speed loop updates the current
command at the current loop's 10 kHz, logged at 1 kHz, does not hold it: replayed held, the nominal model's
speed drifts (training windows: 0.033 rad/s held vs 0.004 interpolated), and the TRUE resistance (x1.4 under a
known load, found exactly by the equations) replayed worse than the nominal one, so the judge refused it
("worsens the simulated velocity"). The way is now decided from the data — the nominal model's replay of the
training windows both ways, before any finding is judged — and reported; a controller that held its command at
the log rate keeps the held replay and its verdicts.

Recordings from the project's own ``Actuator`` under a PI speed loop (12 Hz, nominal J and K, feed-forward of the
known load) with sensor noise; no hidden data."""

from __future__ import annotations

import numpy as np
import pytest

from bldc_actuator.diagnosis.frame import equation_error as ee
from bldc_actuator.diagnosis.frame import simulate
from bldc_actuator.diagnosis.pipeline import DiagnoseOptions, diagnose
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams

#: the user's file: the datasheet motor under a known constant 0.25 N*m load (i_q ~ 2.7 A), R(T) off
NOMINAL = ActuatorParams().replace(**{"motor.resistance_temperature_enabled": False, "load.load_torque": 0.25})
R_TRUE = 1.4 * NOMINAL.motor.phase_resistance
#: the motor's R x1.4; its drive was tuned on the datasheet R (as the replay assumes: keep_controller_of)
TRUTH = NOMINAL.replace(**{"motor.phase_resistance": R_TRUE,
                           "drive.controller_resistance": NOMINAL.motor.phase_resistance})
LOG_RATE = 1000.0


def speed_reference(t: np.ndarray, seed: int = 0) -> np.ndarray:
    """Motor speed [rad/s]: five tones (0.3-5.3 Hz, up to 20 rad/s, seeded phases) ramped in over 0.3 s."""
    rng = np.random.default_rng(seed)
    f = np.array([0.3, 0.75, 1.7, 3.1, 5.3]) * rng.uniform(0.85, 1.15, 5)
    a = np.array([20.0, 11.0, 6.0, 3.5, 1.5])
    ph = rng.uniform(0, 2 * np.pi, 5)
    return np.minimum(1.0, t / 0.3) * (np.sin(2 * np.pi * np.multiply.outer(t, f) + ph) @ a)


def speed_loop_recording(truth: ActuatorParams, nominal: ActuatorParams, *, loop_rate: float, duration: float = 10.0,
                         rate: float = LOG_RATE, seed: int = 0, bandwidth_hz: float = 12.0, reference=None,
                         encoder_step: float = 0.0, velocity_delay_ticks: int = 0,
                         velocity_filter_hz: float | None = None) -> tuple[Signals, np.ndarray]:
    """PI speed loop (``bandwidth_hz``, damping 1, gains from the NOMINAL J and K) around ``truth``, following
    ``reference(t)`` [rad/s] (default :func:`speed_reference` with ``seed``), computing a new current command every
    1 / ``loop_rate`` s; logged at ``rate`` (every ``loop_rate / rate``-th loop instant, the command computed there):
    q/d current (0.03 A noise), angle (quantized to ``encoder_step`` [rad] when > 0), speed (0.02 rad/s; read
    ``velocity_delay_ticks`` loop ticks late, or through a first-order ``velocity_filter_hz`` filter), q/d voltage
    (0.01 V). Returns the recording and the true motor speed at the logged instants."""
    rng = np.random.default_rng(seed)
    act = Actuator(truth)
    J, K = nominal.motor.rotor_inertia, nominal.motor.torque_constant_q
    wn = 2 * np.pi * bandwidth_hz
    kp, ki = 2 * wn * J, wn * wn * J
    sub = int(round(loop_rate / rate))
    dt = 1.0 / loop_rate
    n = int(round(duration * rate))
    t = np.arange(n * sub) * dt
    w_ref = speed_reference(t, seed) if reference is None else reference(t)
    names = ("current_command", "current", "current_d", "position", "velocity", "voltage_q", "voltage_d")
    out = {k: np.zeros(n) for k in names}
    w_true = np.zeros(n)
    hist = [0.0] * (velocity_delay_ticks + 1)
    a_f = 1.0 - np.exp(-2 * np.pi * velocity_filter_hz * dt) if velocity_filter_hz else 1.0
    w_filt = 0.0
    z = 0.0
    for k in range(n):
        for j in range(sub):
            w = act.joint_state()[1] * truth.gear.gear_ratio
            hist = hist[1:] + [w]
            w_filt += a_f * (w - w_filt)
            e = w_ref[k * sub + j] - w
            cmd = (kp * e + z) / K
            z += ki * e * dt
            if j == 0:
                s = act.state
                w_true[k] = s.omega
                out["current_command"][k] = cmd
                out["current"][k] = s.i_q + 0.03 * rng.standard_normal()
                out["current_d"][k] = s.i_d + 0.03 * rng.standard_normal()
                out["position"][k] = np.round(s.theta / encoder_step) * encoder_step if encoder_step else s.theta
                out["velocity"][k] = (w_filt if velocity_filter_hz else hist[0]) + 0.02 * rng.standard_normal()
                out["voltage_q"][k] = s.v_q + 0.01 * rng.standard_normal()
                out["voltage_d"][k] = s.v_d + 0.01 * rng.standard_normal()
            act.set_current_command(cmd)
            act.step(dt)
    return Signals(np.arange(n) / rate, out, source="synthetic"), w_true


@pytest.fixture(scope="module")
def fast_loop() -> Signals:
    """The command updated at 10 kHz, logged at 1 kHz (the GEM case's drive)."""
    return speed_loop_recording(TRUTH, NOMINAL, loop_rate=10_000.0)[0]


@pytest.fixture(scope="module")
def held_loop() -> Signals:
    """The command computed at the log rate and held until the next sample (the builtin cases' joint controller)."""
    return speed_loop_recording(TRUTH, NOMINAL, loop_rate=LOG_RATE)[0]


def _by_log_rate(monkeypatch) -> None:
    """The replay's old rule: hold or interpolate by the log rate alone."""
    monkeypatch.setattr(simulate, "command_replay",
                        lambda ctx, params, starts, length, z=2.0: ee.CommandReplay(ctx.fs >= simulate.REPLAY_HOLD_RATE,
                                                                                    1, "log rate"))


def _decided(sig: Signals) -> ee.CommandReplay:
    ctx = ee.prepare([(sig, False)], NOMINAL, holdout=0.3)
    return simulate.command_replay(ctx, NOMINAL, simulate.windows(ctx, 0.1, 120, "train"), 0.1)


def test_the_interpolation_steps_are_the_drives_loop_ticks():
    assert simulate.replay_substeps(1000.0) == 1                                   # default: held at 1 kHz
    assert simulate.replay_substeps(1000.0, hold=False, loop_rate=10_000.0) == 10  # one per current-loop tick
    assert simulate.replay_substeps(1000.0, hold=False, loop_rate=1e6) == simulate.MAX_INTERPOLATION_SUBSTEPS
    assert simulate.replay_substeps(100.0, hold=False, loop_rate=10_000.0) == 5    # below 500 Hz: as before
    assert simulate.replay_substeps(100.0, hold=True) == 1


def test_a_command_updated_between_samples_is_interpolated(fast_loop):
    """The nominal model replays the training windows several times better interpolated (the speed error is what
    the held command's half-sample lag drives): decided by the data, not the rate."""
    cr = _decided(fast_loop)
    assert cr.decided_by == "training replay" and not cr.hold and cr.substeps == 10
    e = cr.errors
    assert e["interpolate"]["velocity"] < 0.5 * e["hold"]["velocity"], e
    assert cr.score < -cr.noise_floor < 0


def test_a_command_held_at_the_log_rate_is_held(held_loop):
    cr = _decided(held_loop)
    assert cr.decided_by == "training replay" and cr.hold and cr.substeps == 1
    assert cr.errors["hold"]["velocity"] < 0.5 * cr.errors["interpolate"]["velocity"], cr.errors


def test_the_true_resistance_behind_a_fast_speed_loop_is_confirmed(fast_loop, monkeypatch, tmp_path):
    """The equations find R; the judge now confirms it (the held replay refused it: the reproduction of the bug)."""
    report = diagnose(fast_loop, NOMINAL, options=DiagnoseOptions())
    md = report.write_markdown(tmp_path, plots=False).read_text()
    assert "Short-window simulation: the logged commands interpolated between samples (10 sub-steps per sample), " \
           "decided by the training replay" in md
    rep = report.to_dict()
    f = {x["effect"]: x for x in rep["findings"]}
    assert list(f) == ["resistance_error"], rep["verdict"]
    assert f["resistance_error"]["parameters"]["phase_resistance"] == pytest.approx(R_TRUE, rel=0.02)
    sim = f["resistance_error"]["simulation"]
    assert sim["verdict"] == "confirmed" and sim["with"] < 0.1 * sim["without"]
    cmd = rep["compare"]["replay"]["command"]
    assert cmd["mode"] == "interpolate" and cmd["decided_by"] == "training replay"
    assert any(n.startswith("window replay: the logged commands are interpolated") for n in rep["notes"])

    _by_log_rate(monkeypatch)     # the old rule: the same recording, the command held for the whole 1 ms sample
    old = diagnose(fast_loop, NOMINAL, options=DiagnoseOptions()).to_dict()
    # the held replay makes the simulated velocity worse with the true R (it refused R until issue #24: 0.028 ->
    # 0.033 rad/s of a 13.6 rad/s signal; a worsening below tolerance x 1 % of the recorded RMS no longer refuses)
    old_f = {x["effect"]: x for x in old["findings"]}
    assert "resistance_error" in old_f, old["verdict"]
    old_sim = old_f["resistance_error"]["simulation"]
    assert old_sim["other_channel"] == "velocity" and old_sim["other_channel_change"] > 0, old_sim


def test_a_command_held_at_the_log_rate_judges_as_before(held_loop, monkeypatch):
    """The decision keeps the held replay: findings, values and simulated verdicts exactly as by the rate rule."""
    rep = diagnose(held_loop, NOMINAL, options=DiagnoseOptions()).to_dict()
    assert rep["compare"]["replay"]["command"]["mode"] == "hold"
    _by_log_rate(monkeypatch)
    old = diagnose(held_loop, NOMINAL, options=DiagnoseOptions()).to_dict()
    assert [x["effect"] for x in rep["findings"]] == [x["effect"] for x in old["findings"]] == ["resistance_error"]
    for a, b in zip(rep["findings"], old["findings"]):
        assert a["parameters"] == b["parameters"]
        assert a["simulation"]["verdict"] == b["simulation"]["verdict"] == "confirmed"
        assert a["simulation"]["with"] == b["simulation"]["with"]
    assert rep["compare"]["replay"]["holdout"] == old["compare"]["replay"]["holdout"]
