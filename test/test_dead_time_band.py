"""Dead time with a current band (issue #14, third-party set): a drive whose current reverses within a switching
period (ripple) or chatters about zero from one control period to the next (a sign sampled once per period, as in
motulator's converter) loses on each leg an error proportional to the current inside a band and the full
``V_dt`` outside it: ``e_K = -V_dt clip(i_K / band, -1, 1)`` (``drive.dead_time_current_band``; 0 = the sign).

Checked against the three-phase circuit (the same leads-to-windings network as the sign in test_dead_time.py),
against the analytic linear region (a wye winding sees a resistance V_dt/band, a delta one 3 V_dt/band), against
the sign's clamp as the band shrinks, and in a diagnosis round trip where the sign form misses the size.
"""

from __future__ import annotations

import numpy as np
import pytest

from bldc_actuator import abc_model, frames, kernel
from bldc_actuator.diagnosis.pipeline import DiagnoseOptions, diagnose
from bldc_actuator.params import ActuatorParams

from test_issue14_judge_helpers import closed_loop_recording

V_DT = 0.4      # [V] per leg


def _circuit_dq(winding: str, i_dq: np.ndarray, th: np.ndarray, band: float) -> np.ndarray:
    """d-q of the winding voltages the abc circuit gives when each lead is held at ``-V_DT clip(i_line/band)``."""
    motor = abc_model.AbcMotor(winding, r_phase=0.2, l_self=1e-3, l_mutual=-0.4e-3, k_b_phase=0.05)
    i_w = np.array(frames.dq_to_abc(i_dq.real, i_dq.imag, th))
    u_leads = -V_DT * np.clip(motor.line_currents(i_w) / band, -1.0, 1.0)
    dt, n = 1e-6, i_w.shape[1]
    drive = abc_model.Drive.terminal_voltages(lambda t, th_, w: u_leads[:, min(int(t / dt), n - 1)])
    res = abc_model.simulate(motor, drive, (np.arange(n) + 0.5) * dt, omega=0.0, rtol=1e-3, atol=1e-6)
    e_d, e_q = frames.abc_to_dq(res.v_w[0], res.v_w[1], res.v_w[2], th)
    return e_d + 1j * e_q


@pytest.mark.parametrize("winding", ["wye", "delta"])
def test_band_error_equals_the_abc_circuit_and_is_a_resistance_inside_the_band(winding):
    flag = 1.0 if winding == "delta" else 0.0
    th = np.linspace(0.0, 2 * np.pi, 37, endpoint=False) + 0.013
    phis = np.arange(8) * (2 * np.pi / 8) + 0.1
    TH, PHI = (x.ravel() for x in np.meshgrid(th, phis))
    band = 1.0
    for amp in (0.2, 1.5, 6.0):          # inside the band, across it, far outside it
        i_dq = amp * np.exp(1j * PHI)
        k = np.array([kernel.dead_time_error_dq(complex(i), 0j, float(t), V_DT, flag, 0.0, band)
                      for i, t in zip(i_dq, TH)])
        np.testing.assert_allclose(k, _circuit_dq(winding, i_dq, TH, band), atol=1e-9)
        if amp == 0.2:   # every line current inside the band: the legs act as a resistance on the windings
            r = V_DT / band * (3.0 if winding == "delta" else 1.0)
            np.testing.assert_allclose(k, -r * i_dq, atol=1e-12)
        if amp == 6.0:   # every line current outside it: the sign's error
            s = np.array([kernel.dead_time_error_dq(complex(i), 0j, float(t), V_DT, flag, 0.0, 0.0)
                          for i, t in zip(i_dq, TH)])
            far = np.all(np.abs(abc_model.AbcMotor(winding, 0.2, 1e-3, -0.4e-3, 0.05).line_currents(
                np.array(frames.dq_to_abc(i_dq.real, i_dq.imag, TH)))) > band, axis=0)
            assert far.mean() > 0.5
            np.testing.assert_allclose(k[far], s[far], atol=1e-12)


@pytest.mark.parametrize("winding", ["wye", "delta"])
def test_band_over_an_interval_tends_to_the_sign_clamp(winding):
    """Over a finite interval the band's error is taken at the interval's end (stable for any interval): as the
    band shrinks it becomes the sign's Filippov clamp (the current that would cross zero is held there)."""
    flag = 1.0 if winding == "delta" else 0.0
    rng = np.random.default_rng(3)
    h_over_L = 1e-4 / 57e-6
    for _ in range(300):
        i = complex(*rng.normal(0.0, 0.6, 2))
        di = complex(*rng.normal(0.0, 0.3, 2))
        th = float(rng.uniform(0, 2 * np.pi))
        clamp = kernel.dead_time_error_dq(i, di, th, V_DT, flag, h_over_L, 0.0)
        tiny = kernel.dead_time_error_dq(i, di, th, V_DT, flag, h_over_L, 1e-9)
        assert abs(tiny - clamp) < 1e-6
        # the band's end-of-interval error never exceeds the sign's size, and it opposes the current it acts on
        wide = kernel.dead_time_error_dq(i, di, th, V_DT, flag, h_over_L, 0.5)
        assert abs(wide) <= abs(kernel.dead_time_error_dq(i, 0j, th, V_DT, flag, 0.0, 0.0)) + 1e-12


NOMINAL = ActuatorParams().replace(**{"gear.gear_ratio": 9.0, "drive.pwm_frequency": 20000.0,
                                      "motor.rotor_inertia": 5 * ActuatorParams().motor.rotor_inertia})
BAND = 2.0     # [A] line current
TRUTH = NOMINAL.replace(**{"drive.dead_time": V_DT / (20000.0 * NOMINAL.drive.bus_voltage),
                           "drive.dead_time_current_band": BAND})


def _recording(seed: int, duration: float = 12.0):
    ph = 0.7 * seed

    def reference(t):
        return (4 * np.sin(2 * np.pi * 0.3 * t + ph) + 1.5 * np.sin(2 * np.pi * 1.3 * t)
                + 1.2 * np.sin(2 * np.pi * 4.7 * t) + 0.4 * np.sin(2 * np.pi * 9.1 * t + ph))

    return closed_loop_recording(TRUTH, NOMINAL, reference, duration=duration, rate=1000.0, seed=seed)


def test_dead_time_with_a_band_is_found_sized_and_simulated():
    """A wye drive, each leg 0.4 V short outside a 2 A band: diagnose names dead_time with its band form, writes
    drive.dead_time within 10 % and the band within 30 %, and the simulation with them reproduces the held-out
    recording (the sign form, the only form before, sized this dead time 47 % low and named a resistance error
    besides: the in-band part of the error is linear in the current)."""
    rep = diagnose(_recording(1), NOMINAL, options=DiagnoseOptions(holdout_signals=_recording(2), progress=False))
    assert "dead_time" in rep.effects, (rep.effects, [(r["effect"], r["reason"]) for r in rep.rejected])
    assert "resistance_error" not in rep.effects, rep.effects
    f = rep.finding("dead_time")
    assert f["simulated"] and f["simulation"]["verdict"] == "confirmed", f.get("simulation")
    up = rep.updated_params.drive
    assert up.dead_time == pytest.approx(TRUTH.drive.dead_time, rel=0.10), f["parameters"]
    assert up.dead_time_current_band == pytest.approx(BAND, rel=0.30), f["parameters"]
