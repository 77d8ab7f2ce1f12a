"""The drive's voltage-limit mode told apart from a recording that reaches the limit (issue #7,
bldc_actuator/diagnosis/judge/drive_modes.py): recordings of the simulated actuator (current-command steps that run it
to its top speed, with sensor noise and a quantised encoder) whose drive uses one mode, diagnosed against a model
that says ``proportional``. The modes are identical below the limit (test_voltage_limit.py), so equation error
cannot see them: the finding must come from the simulation, name the recording's mode, write it into
``drive.voltage_limit_mode``, and simulate the held-out windows better; a proportional drive gives nothing."""

from __future__ import annotations

import numpy as np
import pytest

from bldc_actuator.diagnosis.judge import drive_modes
from bldc_actuator.diagnosis.frame import equation_error as ee
from bldc_actuator.diagnosis.pipeline import diagnose
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams

NOMINAL = ActuatorParams().replace(**{"gear.gear_ratio": 9.0, "motor.viscous_damping": 2e-3})


def steps_recording(truth: ActuatorParams, duration=20.0, rate=1000.0, seed=0, noise=0.03,
                    keep_d=True) -> Signals:
    """Current-command steps (0.25 s each, ±2..14 A) that run the motor into the voltage limit."""
    rng = np.random.default_rng(seed)
    act = Actuator(truth)
    n, dt = int(duration * rate), 1.0 / rate
    levels = rng.choice([-14, -9, -5, -2, 2, 5, 9, 14], size=int(duration / 0.25) + 1)
    names = ("current_command", "current", "current_d", "position", "velocity", "voltage_q", "voltage_d")
    out = {k: np.zeros(n) for k in names}
    q, prev = 2 * np.pi / 2 ** 14, 0.0
    for k in range(n):
        s = act.state
        pos = round(s.theta / q) * q
        out["velocity"][k] = (pos - prev) / dt if k else 0.0
        prev = pos
        cmd = float(levels[int(k * dt / 0.25)])
        out["current_command"][k] = cmd
        out["current"][k] = s.i_q + noise * rng.standard_normal()
        out["current_d"][k] = s.i_d + noise * rng.standard_normal()
        out["position"][k] = pos
        out["voltage_q"][k] = s.v_q + 0.02 * rng.standard_normal()
        out["voltage_d"][k] = s.v_d + 0.02 * rng.standard_normal()
        act.set_current_command(cmd)
        act.step(dt)
    if not keep_d:
        for k in ("current_d", "voltage_d"):
            out.pop(k)
    return Signals(np.arange(n) * dt, out, source="synthetic")


@pytest.mark.parametrize("mode", ["q_priority", "d_priority"])
@pytest.mark.parametrize("keep_d", [True, False])
def test_identify_names_the_recording_drive_mode(mode, keep_d):
    sig = steps_recording(NOMINAL.replace(**{"drive.voltage_limit_mode": mode}), seed=3, keep_d=keep_d)
    ctx = ee.prepare([(sig, False)], NOMINAL, fc=None, holdout=0.3)
    r = drive_modes.identify(ctx, NOMINAL, 0.1)
    (f,) = r["findings"]
    assert f["mode"] == mode and f["parameters"] == {"voltage_limit_mode": mode}
    assert f["simulation"]["with"] < f["simulation"]["without"] - f["simulation"]["noise_floor"]
    assert f["simulation"]["training_score"][mode] == min(f["simulation"]["training_score"].values())


def test_identify_finds_nothing_on_a_proportional_drive_and_says_when_the_limit_is_never_reached():
    sig = steps_recording(NOMINAL, seed=4)
    ctx = ee.prepare([(sig, False)], NOMINAL, fc=None, holdout=0.3)
    r = drive_modes.identify(ctx, NOMINAL, 0.1)
    assert not r["findings"] and r["rejected"]
    slow = steps_recording(NOMINAL.replace(**{"drive.bus_voltage": 200.0}), seed=4)
    far = NOMINAL.replace(**{"drive.bus_voltage": 200.0})
    r = drive_modes.identify(ee.prepare([(slow, False)], far, fc=None, holdout=0.3), far, 0.1)
    assert not r["findings"] and "does not reach the voltage limit" in r["not_checkable"][0]["reason"]


def test_diagnose_writes_the_mode_into_the_parameter_file_and_simulates_better():
    truth = NOMINAL.replace(**{"drive.voltage_limit_mode": "q_priority"})
    rep = diagnose(steps_recording(truth, seed=5), NOMINAL)
    d = rep.to_dict()
    assert [f["effect"] for f in d["findings"]] == ["voltage_limit_mode"], d["verdict"]
    assert rep.updated_params.drive.voltage_limit_mode == "q_priority"
    ho = d["compare"]["replay"]["holdout"]
    assert ho["after"]["current_rms"] < ho["before"]["current_rms"]
    null = diagnose(steps_recording(NOMINAL, seed=6), NOMINAL).to_dict()
    assert not null["findings"], null["verdict"]


def test_windows_under_sets_a_batch_cannot_mix_are_simulated_in_groups():
    """Leave-one-out replays compare parameter sets that differ in the current-loop delay, which one BatchActuator
    cannot hold (a 10 kHz log made diagnose stop with that error): each group runs in its own batch, and a set's
    windows come out as they do alone."""
    from bldc_actuator.diagnosis.frame import simulate

    sig = steps_recording(NOMINAL, duration=4.0, seed=7)
    ctx = ee.prepare([(sig, False)], NOMINAL, fc=None, holdout=0.3)
    starts = simulate.windows(ctx, 0.1, 10, "all")
    delayed = NOMINAL.replace(**{"drive.current_loop_delay": 1e-4})
    both = simulate.simulate_windows(ctx, [NOMINAL, delayed], starts, 0.1)
    alone = simulate.simulate_windows(ctx, [NOMINAL], starts, 0.1)
    n = len(starts)
    np.testing.assert_array_equal(both["sim_i"][:, :n], alone["sim_i"])   # exact: same batch kernel, same process
    assert np.max(np.abs(both["sim_v"][:, n:] - alone["sim_v"])) > 1e-3      # the delay acts


def test_no_mode_is_judged_where_the_models_complex_vector_loop_diverges():
    """A model whose drive runs the complex-vector current law (drive.current_controller: complex_vector, 1 kHz loop
    bandwidth at 10 kHz, one period of delay) is unstable above ~61 rad/s (bldc_actuator/current_loop_stability.py);
    the recording reaches the voltage limit near 180 rad/s. Replaying the limit windows with that model says nothing
    about the limit modes (its current diverges): they are left out, and the check says why instead of naming a
    mode."""
    from bldc_actuator.diagnosis.frame import simulate
    from bldc_actuator.params import current_loop_limit

    truth = NOMINAL.replace(**{"drive.voltage_limit_mode": "d_priority"})
    model = NOMINAL.replace(**{"drive.current_controller": "complex_vector", "drive.decoupling_enabled": False,
                               "drive.current_loop_delay": 1e-4})
    lim = current_loop_limit(model)
    sig = steps_recording(truth, duration=20.0, seed=1)
    ctx = ee.prepare([(sig, False)], model, fc=None, holdout=0.3)
    assert float(np.max(np.abs(ctx.sig["omega_s"]))) > 2 * lim.speed_limit
    # the model's replay there departs from the recording more than the same model with the PI law on every
    # window (up to 2x: the voltage circle bounds the divergence where the demand exceeds it)
    starts = [s for s in simulate.windows(ctx, 0.1, 10 ** 9, "train")
              if abs(ctx.sig["omega_s"][s]) > 1.5 * lim.speed_limit]
    e_cv, e_pi = simulate.window_errors(ctx, [model, model.replace(**{"drive.current_controller": "pi"})], starts[:10],
                                        0.1)
    assert np.all(e_cv["current"] > e_pi["current"]) and np.mean(e_cv["current"]) > 1.5 * np.mean(e_pi["current"])
    r = drive_modes.identify(ctx, model, 0.1)
    assert not r["findings"]
    (nc,) = r["not_checkable"]
    assert "complex_vector is unstable" in nc["reason"] and f"{lim.speed_limit:.4g} rad/s" in nc["reason"]
    assert lim.unstable_above("the model's drive.current_controller complex_vector") in nc["reason"]
