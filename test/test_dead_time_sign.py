"""The dead time's converter form (``drive.dead_time_sign``, issue #14, third-party case tp_dead_time).

The equation error fits the dead time against the current at each sample: the leg error of the current at the
control period's start (``kernel.dead_time_error_dq`` with ``h/L = 0``). The kernel's default form (``clamp``)
applies it at the interval's END with zero-current clamping: a line current within ``(2/3)(h/L) V_dt`` of zero
(0.2 A at 10 kHz, 80 µH, 0.24 V) is held at zero, and a band is widened by that much. A drive whose converter
takes each leg's current direction once per period (a switching-cycle averaged converter: motulator's) is the
``period_start`` form. Replayed in the wrong form the found dead time reproduced motulator's held-out q-voltage
0.03 V instead of 0.02 V and worsened its speed beyond the judge's floor (refused). Here the recordings come from
the project's own actuator with ``period_start``: the judge must identify that form from the training windows
(as the drive's current-controller form is identified: the replayed current first, the q-voltage on a tie) and
write it with the finding."""

from __future__ import annotations

import json
import textwrap

import numpy as np
import pytest

from bldc_actuator import kernel
from bldc_actuator.diagnosis.pipeline import DiagnoseOptions, diagnose
from bldc_actuator.params import ActuatorParams

from kernel_paths_helper import run_on_kernel_path
from test_issue14_judge_helpers import closed_loop_recording

#: a small joint like the third-party set's: 80 µH, 10 kHz current loop, 5 kHz PWM on 24 V (V_dt 0.24 V per leg
#: at 2 µs), a known viscous load so the current follows the speed through zero in both directions
BASE = {"motor.phase_resistance": 0.13, "motor.q_inductance": 8.0e-5, "motor.torque_constant_q": 0.0743,
        "motor.rotor_inertia": 6.0e-5, "motor.viscous_damping": 0.0064, "drive.current_loop_rate": 10000.0,
        "drive.current_loop_bandwidth": 500.0, "drive.current_loop_delay": 1.0e-4, "drive.pwm_frequency": 5000.0}
NOMINAL = ActuatorParams().replace(**BASE)
DEAD = {"drive.dead_time": 2e-6, "drive.dead_time_current_band": 0.3}


def _recording(truth: ActuatorParams, seed: int):
    ph = 0.9 * seed

    def reference(t):
        return (3.0 * np.sin(2 * np.pi * 0.25 * t + ph) + 0.8 * np.sin(2 * np.pi * 1.1 * t)
                + 0.3 * np.sin(2 * np.pi * 3.7 * t + ph))

    return closed_loop_recording(truth, NOMINAL, reference, duration=8.0, seed=seed, bandwidth_hz=10.0)


def _diagnose(truth: ActuatorParams):
    a = _recording(truth, 1)
    i = a.channels["current"]
    assert np.percentile(i, 1) < -0.8 and np.percentile(i, 99) > 0.8      # both signs, through zero
    assert np.mean(np.abs(i) < 0.5) > 0.4                                 # much of it near zero
    return diagnose(a, NOMINAL, options=DiagnoseOptions(holdout_signals=_recording(truth, 2), progress=False))


def test_a_period_start_dead_time_is_written_in_its_form_and_replays_the_held_out_voltage():
    """Before (the finding replayed in the kernel's clamp form): held-out q-voltage error 0.268 -> 0.038 V, and the
    file's clamp written. After: the training windows' replay identifies period_start (current 0.0142 A clamp vs
    0.0124 A period_start; q-voltage 0.041 vs 0.0088 V), written with the finding; held-out 0.268 -> 0.0089 V;
    2.00 µs, band 0.300 A."""
    truth = NOMINAL.replace(**DEAD, **{"drive.dead_time_sign": "period_start"})
    rep = _diagnose(truth)
    assert "dead_time" in rep.effects, (rep.effects, [(r["effect"], r["reason"]) for r in rep.rejected])
    f = rep.finding("dead_time")
    assert f["simulation"]["verdict"] == "confirmed", f["simulation"]
    up = rep.updated_params.drive
    assert up.dead_time_sign == "period_start"
    assert up.dead_time == pytest.approx(2e-6, rel=0.05)
    assert f["simulation"]["with"] < 0.02, f["simulation"]          # 0.0089 V; 0.038 V in the clamp form
    assert f["simulation"]["with"] < 0.1 * f["simulation"]["without"]


def test_a_clamping_plant_is_still_found_and_confirmed_in_the_chosen_form():
    """The same joint whose plant clamps (the kernel's default form, the ideal sign): the equation error fits its
    period-start equivalent (2.0 µs, band 0.14 A); the training replay's current picks period_start (0.0285 vs
    0.032 A), and the finding is confirmed in the held-out replay, whichever form the choice writes."""
    rep = _diagnose(NOMINAL.replace(**{"drive.dead_time": 2e-6}))
    assert "dead_time" in rep.effects, (rep.effects, [(r["effect"], r["reason"]) for r in rep.rejected])
    assert rep.finding("dead_time")["simulation"]["verdict"] == "confirmed"
    assert rep.updated_params.drive.dead_time == pytest.approx(2e-6, rel=0.05)
    assert any("dead time's converter form" in n for n in rep.notes)


SCENARIO = textwrap.dedent('''
    import json, math, sys
    from bldc_actuator.model import Actuator, COMPILED
    from bldc_actuator.params import ActuatorParams
    rows = []
    for band in (0.0, 0.3):
        for form in ("clamp", "period_start"):
            p = ActuatorParams().replace(**json.loads(sys.argv[1])).replace(**{
                "drive.dead_time": 2e-6, "drive.dead_time_current_band": band, "drive.dead_time_sign": form})
            act = Actuator(p)
            for k in range(400):                  # small currents through zero: where the forms differ
                act.set_current_command(0.4 * math.sin(2 * math.pi * 5.0 * k * 1e-3))
                act.step(1e-3)
                s = act.state
                rows.append([s.i_d, s.i_q, s.omega, s.v_d, s.v_q])
    json.dump({"compiled": COMPILED, "rows": rows}, sys.stdout)
''')


def _run(no_numba: bool) -> dict:
    return run_on_kernel_path(SCENARIO, json.dumps(BASE), no_numba=no_numba)


@pytest.mark.skipif(not kernel.COMPILED, reason="numba not installed (or disabled): only the Python path exists")
def test_both_forms_compiled_equal_python_and_differ_near_zero_current():
    a, b = _run(False), _run(True)
    assert a["compiled"] and not b["compiled"]
    ra, rb = np.array(a["rows"]), np.array(b["rows"])
    np.testing.assert_allclose(ra, rb, rtol=0, atol=1e-12)
    clamp, start = ra[:400], ra[400:800]
    # the forms differ in the voltage the loop must supply at the crossings (the clamp holds the current at zero)
    assert np.max(np.abs(clamp[:, 4] - start[:, 4])) > 0.05
