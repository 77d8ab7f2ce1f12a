"""The replay's q-voltage channel (``voltage_rms``): in a current-controlled drive a resistance error barely moves
the current or the speed (the PI absorbs it) but shows in the voltage the drive applies. The held-out
comparison, and the benchmark's simulated verdict, therefore carry the q-voltage at the recorded speed."""

from __future__ import annotations

import numpy as np

from bldc_actuator.diagnosis.frame import equation_error as ee
from bldc_actuator.diagnosis.frame import simulate
from bldc_actuator.params import ActuatorParams

from test_issue14_judge_helpers import closed_loop_recording, triangle_then_sines

BASE = ActuatorParams().replace(**{"gear.gear_ratio": 9.0, "motor.resistance_temperature_enabled": False})


def test_a_resistance_error_shows_in_the_replayed_voltage_not_in_the_current():
    true = BASE.replace(**{"motor.phase_resistance": BASE.motor.phase_resistance * 3.0})   # hot winding + cables
    sig = closed_loop_recording(true, BASE, triangle_then_sines, duration=16.0, seed=3)
    ctx = ee.prepare([(sig, False)], BASE)
    starts = simulate.windows(ctx, 0.1, 80, "all")
    nom, tru = simulate.replay(ctx, [BASE, true], starts, 0.1)
    # expected voltage error of the nominal replay: (R_true - R_nom) i_q at the recorded current
    i_q = ctx.sig["i_q"]
    dR = true.motor.phase_resistance - BASE.motor.phase_resistance
    expected = dR * float(np.sqrt(np.mean(i_q ** 2)))
    assert expected > 0.05                                   # the effect is there to see
    assert nom["voltage_rms"] > 0.5 * expected, (nom["voltage_rms"], expected)
    assert tru["voltage_rms"] < 0.3 * nom["voltage_rms"], (nom["voltage_rms"], tru["voltage_rms"])
    # the current barely tells them apart (the PI absorbs the resistance)
    assert abs(tru["current_rms"] - nom["current_rms"]) < 0.2 * nom["current_rms"]


def test_no_voltage_channel_without_a_recorded_voltage():
    sig = closed_loop_recording(BASE, BASE, triangle_then_sines, duration=8.0, seed=4,
                                channels=("current_command", "current", "position", "velocity"))
    ctx = ee.prepare([(sig, False)], BASE)
    starts = simulate.windows(ctx, 0.1, 20, "all")
    (r,) = simulate.replay(ctx, [BASE], starts, 0.1)
    assert r["voltage_rms"] is None and np.isfinite(r["velocity_rms"])
