"""Replaying a recording the project's own closed-loop actuator made with a true dead time (issue #14,
tp_dead_time_loaded): the window replay with the TRUE parameters must reproduce it at least as well as the nominal
(no dead time) does, in current, speed and q-voltage. It did not: the true dead time leaves a current ripple at six
times the electrical frequency (500 Hz at 25 rad/s with 21 pole pairs) that the recorded, low-passed channels
lack; compared unfiltered, and started at the smoothed speed (no restoring force corrects the speed ripple's
offset at the start), the true 2 µs replayed worse than none, and the simulation judge refused the true dead time
("worsens the simulated velocity")."""

from __future__ import annotations

import numpy as np
import pytest

from bldc_actuator.diagnosis.frame import equation_error as ee
from bldc_actuator.diagnosis.frame import simulate as refit
from bldc_actuator.params import ActuatorParams

from test_issue14_judge_helpers import closed_loop_recording

NOMINAL = ActuatorParams().replace(**{"load.load_torque": 0.25})    # ~2.75 A held against the load
TRUTH = NOMINAL.replace(**{"drive.dead_time": 2e-6})                 # V_dt 0.96 V per leg


def _replay(scale: float):
    def ref(t):
        return scale * (3 * np.sin(2 * np.pi * 0.4 * t) + 1.5 * np.sin(2 * np.pi * 1.3 * t)
                        + 8 * np.sin(2 * np.pi * 0.11 * t))
    sig = closed_loop_recording(TRUTH, NOMINAL, ref, duration=12.0, seed=1)
    assert np.percentile(sig.channels["current"], 0.5) > 2.0      # one-signed: the dead time is an offset
    ctx = ee.prepare([(sig, False)], NOMINAL)
    starts = refit.windows(ctx, 0.1, 40, "holdout")
    assert len(starts) >= 20
    nom, tru = refit.replay(ctx, [NOMINAL, TRUTH], starts, 0.1)
    return nom, tru


def test_the_true_dead_time_replays_a_generated_one_signed_recording_better_than_the_nominal():
    """Small swings (current 2.5-2.9 A). Before: current 0.034 A true vs 0.029 A nominal (worse); after: 0.017
    vs 0.026 A, speed 0.060 vs 0.125 rad/s, q-voltage 0.030 vs 1.49 V."""
    nom, tru = _replay(0.3)
    assert tru["current_rms"] < 0.8 * nom["current_rms"], (tru["current_rms"], nom["current_rms"])
    assert tru["velocity_rms"] < 0.8 * nom["velocity_rms"], (tru["velocity_rms"], nom["velocity_rms"])
    assert tru["voltage_rms"] < 0.1 * nom["voltage_rms"], (tru["voltage_rms"], nom["voltage_rms"])


def test_with_larger_swings_the_true_dead_time_is_no_worse_in_current_and_speed():
    """Larger swings (speeds to 37 rad/s): the ripple passes the recording's 100 Hz low-pass only in the slowest
    windows, where the replay cannot hold its phase over 0.1 s. Before: current 0.143 A true vs 0.026 A nominal,
    speed 0.137 vs 0.056 rad/s; after: 0.022 vs 0.020 A (the low-passed current noise is 0.013 A), speed
    0.050 vs 0.052 rad/s, q-voltage 0.017 vs 1.47 V."""
    nom, tru = _replay(2.0)
    assert tru["current_rms"] < nom["current_rms"] + 0.005, (tru["current_rms"], nom["current_rms"])
    assert tru["velocity_rms"] < 1.05 * nom["velocity_rms"], (tru["velocity_rms"], nom["velocity_rms"])
    assert tru["voltage_rms"] < 0.1 * nom["voltage_rms"], (tru["voltage_rms"], nom["voltage_rms"])
    assert tru["voltage_rms"] == pytest.approx(0.017, abs=0.01)
