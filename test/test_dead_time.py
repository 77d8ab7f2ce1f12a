"""Inverter dead time on wye AND delta windings (issue #14, symptom 3).

The kernel's d-q voltage error (:func:`kernel.dead_time_error_dq`) is checked against the three-phase circuit
(:mod:`bldc_actuator.abc_model`, Kirchhoff on the winding network, no frames conversion inside): the inverter
legs put ``-V_dt sign(i_line)`` on the leads, the circuit says what each winding gets (the wye neutral floats,
the delta windings sit between two leads), and the d-q transform of those winding voltages must equal what the
kernel adds, over a sweep of angles and current directions. Then the diagnosis round trip on a delta motor.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bldc_actuator import abc_model, frames, kernel
from bldc_actuator.diagnosis.frame.candidates import dead_time_q_factor
from bldc_actuator.diagnosis.pipeline import DiagnoseOptions, diagnose
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.model import Actuator, ActuatorState
from bldc_actuator.params import ActuatorParams

from test_issue14_judge_helpers import closed_loop_recording

V_DT = 0.4      # [V] per leg


def _circuit_winding_voltages(winding: str, i_w: np.ndarray, th_e: np.ndarray) -> np.ndarray:
    """Winding voltages (3, n) the circuit gives when each lead is held at its leg's dead-time error
    ``-V_DT sign(line current)``; line currents from the circuit's incidence matrix. One sample per time step of a voltage-driven :func:`abc_model.simulate` run: KVL
    at each output instant, whatever the currents did in between (the rotor is locked: no back-EMF)."""
    motor = abc_model.AbcMotor(winding, r_phase=0.2, l_self=1e-3, l_mutual=-0.4e-3, k_b_phase=0.05)
    i_line = motor.line_currents(i_w)
    u_leads = -V_DT * np.sign(i_line)                                                          # (3, n)
    dt, n = 1e-6, i_w.shape[1]
    drive = abc_model.Drive.terminal_voltages(lambda t, th, w: u_leads[:, min(int(t / dt), n - 1)])
    t_eval = (np.arange(n) + 0.5) * dt
    res = abc_model.simulate(motor, drive, t_eval, omega=0.0, rtol=1e-3, atol=1e-6)
    return res.v_w


@pytest.mark.parametrize("winding", ["wye", "delta"])
def test_kernel_dead_time_error_equals_the_abc_circuits_winding_voltages(winding):
    """Sweep: 61 electrical angles × 12 current directions (motoring, braking, ±d, mixed) in the d-q plane."""
    th = np.linspace(0.0, 2 * np.pi, 61, endpoint=False) + 0.013      # off the exact sign changes
    phis = np.arange(12) * (2 * np.pi / 12) + 0.1
    TH, PHI = (x.ravel() for x in np.meshgrid(th, phis))
    i_dq = 5.0 * np.exp(1j * PHI)
    i_w = np.array(frames.dq_to_abc(i_dq.real, i_dq.imag, TH))        # the winding currents the state means
    v_w = _circuit_winding_voltages(winding, i_w, TH)
    e_d, e_q = frames.abc_to_dq(v_w[0], v_w[1], v_w[2], TH)
    flag = 1.0 if winding == "delta" else 0.0
    k = np.array([kernel.dead_time_error_dq(complex(i), 0j, float(t), V_DT, flag, 0.0) for i, t in zip(i_dq, TH)])
    np.testing.assert_allclose(k.real, e_d, atol=1e-9)
    np.testing.assert_allclose(k.imag, e_q, atol=1e-9)
    # the error opposes the current on average (it takes power), never zero
    assert np.all(np.abs(k) > 0.5 * V_DT)
    assert np.mean((k * np.conj(i_dq)).real) < 0
    if winding == "delta":     # each winding sees two legs: √3 times the wye error's size, on average
        wye = np.array([kernel.dead_time_error_dq(complex(i), 0j, float(t), V_DT, 0.0, 0.0) for i, t in zip(i_dq, TH)])
        assert np.mean(np.abs(k)) / np.mean(np.abs(wye)) == pytest.approx(math.sqrt(3), rel=0.02)
    # over a finite interval a current that stays on its side gets the full error (the kernel's clamp only
    # acts on a line current the error would push through zero within the interval)
    k_h = np.array([kernel.dead_time_error_dq(complex(i), 0j, float(t), V_DT, flag, 1e-4 / 57e-6)
                    for i, t in zip(i_dq, TH)])
    i_line = abc_model.AbcMotor(winding, 0.2, 1e-3, -0.4e-3, 0.05).line_currents(i_w)
    far = np.all(np.abs(i_line) > (3.0 if winding == "delta" else 1.0) * 2 / 3 * 1e-4 / 57e-6 * V_DT, axis=0)
    assert far.mean() > 0.5
    np.testing.assert_allclose(k_h[far], k[far], atol=1e-12)
    assert np.all(np.abs(k_h[~far]) <= np.abs(k[~far]) + 1e-12)


@pytest.mark.parametrize("winding", ["wye", "delta"])
def test_dead_time_is_compensated_by_the_current_loop(winding):
    """Rotor held, 25 angles, a small and a large current: the loop settles (no limit cycle: the sign taken at
    each 100 µs interval's start made this 57 µH delta motor chatter by 8 A peak to peak), and in steady state
    the winding gets R i, so the controller's voltage is R i minus the dead-time error the abc circuit puts on
    the windings for those currents (the full sign error: a settled current does not cross zero)."""
    p = ActuatorParams().replace(**{"motor.winding": winding, "drive.dead_time": 2e-6, "drive.pwm_frequency": 20000.0,
                                    "motor.rotor_inertia": 100.0, "motor.resistance_temperature_enabled": False})
    v_dt = 2e-6 * 20000.0 * p.drive.bus_voltage
    R = p.motor.phase_resistance
    for i_ref in (-12.0, 0.7):
        for th_e in np.linspace(0.0, 2 * np.pi, 25) + 0.011:
            act = Actuator(p, ActuatorState(theta=th_e / p.motor.pole_pairs))
            act.set_current_command(i_ref)
            act.step(0.05)
            i_q = []
            for _ in range(20):
                act.step(1e-4)
                i_q.append(act.state.i_q)
            assert np.ptp(i_q) < 1e-4, (th_e, np.ptp(i_q))
            s = act.state
            th = p.motor.pole_pairs * s.theta
            i_w = np.repeat(np.array(frames.dq_to_abc(s.i_d, s.i_q, th)).reshape(3, 1), 2, axis=1)
            v_w = _circuit_winding_voltages(winding, i_w, np.full(2, th))[:, 0] * (v_dt / V_DT)
            e_d, e_q = frames.abc_to_dq(v_w[0], v_w[1], v_w[2], th)
            i_line = abc_model.AbcMotor(winding, 0.2, 1e-3, -0.4e-3, 0.05).line_currents(i_w[:, 0])
            if np.min(np.abs(i_line)) < 0.1 * abs(i_ref):
                # a line current near zero is held at zero by its leg (zero-current clamping) until the
                # integrator's push exceeds V_dt: still converging, and not through zero and back
                continue
            assert s.i_q == pytest.approx(i_ref, abs=1e-4) and abs(s.i_d) < 1e-3     # (the held rotor creeps)
            assert s.v_q == pytest.approx(R * s.i_q - e_q, abs=5e-4), th_e
            assert s.v_d == pytest.approx(R * s.i_d - e_d, abs=5e-4), th_e
            assert math.hypot(e_d, e_q) > 0.5 * v_dt      # a real correction, not a no-op


# ------------------------------------------------------------------------------ diagnosis round trip, delta

NOMINAL = ActuatorParams().replace(**{"gear.gear_ratio": 9.0, "motor.winding": "delta",
                                      "motor.rotor_inertia": 5 * ActuatorParams().motor.rotor_inertia})
TRUTH = NOMINAL.replace(**{"drive.dead_time": 0.4 / (20000.0 * NOMINAL.drive.bus_voltage),
                           "drive.pwm_frequency": 20000.0})


def _recording(truth: ActuatorParams, seed: int, duration: float = 12.0, rate: float = 1000.0) -> Signals:
    """Closed-loop recording from the project's simulator (:func:`closed_loop_recording`: a PD position loop at
    15 Hz on a 14-bit encoder, gains from the nominal parameters, q/d current and voltage with noise, like a drive
    logs them) following sines of several speeds (current of both signs)."""
    ph = 0.7 * seed

    def reference(t):
        return (4 * np.sin(2 * np.pi * 0.3 * t + ph) + 1.5 * np.sin(2 * np.pi * 1.3 * t)
                + 1.2 * np.sin(2 * np.pi * 4.7 * t) + 0.4 * np.sin(2 * np.pi * 9.1 * t + ph))

    return closed_loop_recording(truth, NOMINAL, reference, duration=duration, rate=rate, seed=seed)


# the diagnosis on top of the kernel: once, on the compiled path (on the pure-Python pass it took > 600 s at
# load 10, issue #25; the kernel's dead-time terms are checked on both paths above)
@pytest.mark.one_kernel_path
def test_dead_time_on_a_delta_motor_is_found_written_and_simulated():
    """Delta motor, each leg 0.4 V short (t_d f_pwm V_bus): diagnose names dead_time, writes drive.dead_time
    within 10 % of the truth (the q-equivalent 2.70 V_dt = 1.08 V, not the wye 0.624 V), and the short-window
    simulation with the updated parameters reproduces the held-out recording better than the nominal one."""
    rep = diagnose(_recording(TRUTH, seed=1), NOMINAL,
                   options=DiagnoseOptions(holdout_signals=_recording(TRUTH, seed=2), progress=False))
    assert "dead_time" in rep.effects, (rep.effects, [(r["effect"], r["reason"]) for r in rep.rejected])
    f = rep.finding("dead_time")
    assert f["fields"]["dead_time"] == "drive.dead_time" and f["simulated"]
    assert rep.updated_params.drive.dead_time == pytest.approx(TRUTH.drive.dead_time, rel=0.10)
    assert f["parameters"]["dead_time_voltage"] == pytest.approx(dead_time_q_factor("delta") * 0.4, rel=0.10)
    assert not rep.not_simulated, rep.not_simulated
    sim = f["simulation"]                       # short-window simulation of the held-out recording
    assert sim["verdict"] == "confirmed" and sim["with"] < 0.3 * sim["without"], sim
    assert f["held_out"]["after"] < 0.3 * f["held_out"]["before"], f["held_out"]
