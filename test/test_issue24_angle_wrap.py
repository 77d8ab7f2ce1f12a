"""Issue #24, symptom 4: an angle that never wraps was "unwrapped".

A servo's output angle mapped to the motor side (x 288.35) moves ~20 rad per sample on fast moves; the old test
(|d theta - v dt| > 0.9 pi is a wrap) tripped on a lagging speed channel and invented whole turns. Whether a
channel wraps is now read from the channel itself (it stays within one turn); a genuinely wrapping angle is still
unwrapped, and what was done is said in the notes (and as a ``wrapped`` DataIssue by the cleaning).
"""

from __future__ import annotations

import math

import numpy as np

from bldc_actuator.diagnosis.frame import equation_error as ee
from bldc_actuator.diagnosis.io import cleaning
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.params import ActuatorParams

GEAR = 288.35
FS = 100.0


def _servo_moves(seconds: float = 30.0, move_rad: float = 1.0, move_s: float = 0.25, seed: int = 3):
    """Output-side minimum-jerk moves of +-``move_rad`` in ``move_s``, one per second; (t, theta_out, omega_out)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / FS)
    th = np.zeros_like(t)
    w = np.zeros_like(t)
    target = 0.0
    for k in range(int(seconds)):
        start = target
        target = start + move_rad * rng.choice([-1.0, 1.0])
        s = np.clip((t - k - 0.3) / move_s, 0.0, 1.0)
        sel = t >= k
        th[sel] = start + (target - start) * (10 * s[sel] ** 3 - 15 * s[sel] ** 4 + 6 * s[sel] ** 5)
        w[sel] = (target - start) / move_s * (30 * s[sel] ** 2 - 60 * s[sel] ** 3 + 30 * s[sel] ** 4)
    return t, th, w


def _lagging(w: np.ndarray, samples: int = 3, noise: float = 0.0, seed: int = 4) -> np.ndarray:
    """The speed channel a drive logs: ``samples`` late and noisy."""
    rng = np.random.default_rng(seed)
    return np.concatenate([np.full(samples, w[0]), w[:-samples]]) + noise * rng.standard_normal(len(w))


def _signals(pos, vel, t):
    i = 0.5 + 0.1 * np.sin(2 * np.pi * 0.7 * t)
    return Signals(t, {"position": pos, "velocity": vel, "current": i, "current_command": i}, source="synthetic")


def test_a_motor_side_angle_moving_20_rad_per_sample_gains_no_turns():
    t, th_out, w_out = _servo_moves()
    th, w = GEAR * th_out, GEAR * w_out
    assert np.max(np.abs(np.diff(th))) > 18.0                 # the case: ~20 rad per sample on fast moves
    vel = _lagging(w, 3, noise=0.01 * np.max(np.abs(w)))
    ctx = ee.prepare([(_signals(th, vel, t), False)], ActuatorParams())
    turns = (ctx.sig["theta"] - th) / (2 * math.pi)
    assert np.max(np.abs(turns)) < 1e-6, f"invented turns: {np.max(np.abs(turns)):.0f}"
    assert not any("was wrapped" in n for n in ctx.notes)
    assert any("a continuous angle, taken as recorded" in n for n in ctx.notes)


def test_the_cleaning_does_not_unwrap_it_either():
    t, th_out, w_out = _servo_moves()
    th, w = GEAR * th_out, GEAR * w_out
    s = cleaning.clean(_signals(th, _lagging(w, 3), t), params=ActuatorParams())
    assert not [i for i in s.issues if i.kind == "wrapped"]
    assert np.allclose(s.channels["position"], th)


def test_a_genuinely_wrapping_angle_is_still_unwrapped_and_said_so():
    # slower moves (up to ~1.3 rad per sample), the angle wrapped to [-pi, pi) and to [0, 2 pi), speed lagging
    t, th_out, w_out = _servo_moves(move_rad=0.05, move_s=0.4)
    th, w = GEAR * th_out, GEAR * w_out
    for wrapped in ((th + math.pi) % (2 * math.pi) - math.pi, th % (2 * math.pi)):
        ctx = ee.prepare([(_signals(wrapped, _lagging(w, 1), t), False)], ActuatorParams())
        assert np.allclose(np.diff(ctx.sig["theta"]), np.diff(th), atol=1e-6)
        assert any("position was wrapped" in n for n in ctx.notes)
        # the cleaning reports it as a data issue (and unwraps it first)
        s = cleaning.clean(_signals(wrapped, _lagging(w, 1), t), params=ActuatorParams())
        wr = [i for i in s.issues if i.kind == "wrapped" and i.channel == "position"]
        assert wr and wr[0].count > 0
        assert np.allclose(np.diff(s.channels["position"]), np.diff(th), atol=1e-6)
