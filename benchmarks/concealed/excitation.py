"""Joint reference trajectories (OUTPUT side, rad) at the controller rate, smooth to the second derivative.

Every generator returns θ_out(t); :func:`reference` differentiates it (central differences of a smooth
signal) into ω_out and α_out for the controller's feed-forward. Segments are joined by :func:`sequence`
with raised-cosine blends, so a recording can hold e.g. slow calibration sweeps followed by gait cycles.
"""

from __future__ import annotations

import math

import numpy as np

from .truth import Reference

RATE = 1000.0


def _t(duration: float, rate: float = RATE) -> np.ndarray:
    return np.arange(int(round(duration * rate))) / rate


def smoothstep(x: np.ndarray) -> np.ndarray:
    """0 → 1 on [0, 1] with zero first and second derivative at both ends (quintic)."""
    x = np.clip(x, 0.0, 1.0)
    return x ** 3 * (10.0 - 15.0 * x + 6.0 * x * x)


def gait(duration: float, seed: int, *, freq: float = 1.2, amplitude: float = 0.45, offset: float = 0.0,
         rate: float = RATE) -> np.ndarray:
    """Hip-like gait: a stride frequency wandering ±10 %, three harmonics with a seeded shape, amplitude
    wandering ±15 %; the stance part of each stride is slow (where friction and cogging show)."""
    rng = np.random.default_rng(seed)
    t = _t(duration, rate)
    def slow_wander():
        x = _lowpass(np.cumsum(rng.standard_normal(len(t))) / math.sqrt(rate), 0.15, rate)
        x -= np.mean(x)
        return x / max(1e-9, np.max(np.abs(x)))

    wander, wander_amp = slow_wander(), slow_wander()
    f = freq * (1.0 + 0.1 * wander)
    phase = 2.0 * math.pi * np.cumsum(f) / rate
    h2, h3 = rng.uniform(0.15, 0.3), rng.uniform(0.05, 0.12)
    p2, p3 = rng.uniform(0, 2 * math.pi, 2)
    shape = np.sin(phase) + h2 * np.sin(2 * phase + p2) + h3 * np.sin(3 * phase + p3)
    amp = amplitude * (1.0 + 0.15 * wander_amp) / (1.0 + h2 + h3)
    return offset + amp * shape


def sweep(duration: float, *, speeds=(0.05, 0.2, 0.6), span: float = 1.0, center: float = 0.0,
          rate: float = RATE) -> np.ndarray:
    """Slow back-and-forth sweeps over about ``center ± span`` at each of ``speeds`` [rad/s] in turn (equal
    time each) with smooth reversals and smooth speed changes (a calibration move: constant speed for
    friction, cogging and load)."""
    t = _t(duration, rate)
    n = len(t)
    per = max(1, n // len(speeds))
    level = np.array([speeds[min(i // per, len(speeds) - 1)] for i in range(n)], dtype=float)
    speed = _lowpass(level, 1.0, rate)                          # smooth speed changes (~0.5 s)
    phase = np.cumsum(speed / (4.0 * span)) / rate              # one cycle = 4 spans of travel
    v = speed * np.tanh(np.sin(2.0 * math.pi * phase) / 0.12) / math.tanh(1.0 / 0.12)
    theta = np.cumsum(v) / rate
    return center + theta - 0.5 * (theta.max() + theta.min())


def multisine(duration: float, seed: int, *, f_lo: float = 0.15, f_hi: float = 2.5, n: int = 12,
              amplitude: float = 0.5, rate: float = RATE) -> np.ndarray:
    """Random-phase multisine, log-spaced between ``f_lo`` and ``f_hi`` Hz, peak scaled to ``amplitude``."""
    rng = np.random.default_rng(seed)
    t = _t(duration, rate)
    freqs = np.geomspace(f_lo, f_hi, n) * rng.uniform(0.95, 1.05, n)
    phases = rng.uniform(0, 2 * math.pi, n)
    weights = 1.0 / np.sqrt(freqs / f_lo)  # less amplitude at high frequency (bounded acceleration)
    x = sum(w * np.sin(2 * math.pi * f * t + p) for w, f, p in zip(weights, freqs, phases))
    return amplitude * x / np.max(np.abs(x))


def swings(duration: float, *, freq: float = 2.5, amplitude: float = 1.2, rate: float = RATE) -> np.ndarray:
    """Fast large swings (kicks): drive the rotor towards its no-load speed, i.e. the voltage limit."""
    t = _t(duration, rate)
    env = 0.75 + 0.25 * np.sin(2 * math.pi * 0.11 * t)
    return amplitude * env * np.sin(2 * math.pi * freq * t)


def hold(duration: float, value: float = 0.0, rate: float = RATE) -> np.ndarray:
    return np.full(len(_t(duration, rate)), float(value))


def sequence(*parts: np.ndarray, blend: float = 1.0, fade: float = 0.6, rate: float = RATE,
             lead_in: float = 0.5) -> np.ndarray:
    """Concatenate trajectories rest-to-rest: each part fades in and out around its own mean over
    ``fade`` seconds, consecutive parts are joined by a quintic move of ``blend`` seconds, and the whole
    starts with a ``lead_in`` hold at 0 (the loop settles). Continuous to the second derivative."""
    nb, nf = int(round(blend * rate)), int(round(fade * rate))
    out = [np.zeros(int(round(lead_in * rate)))]
    level = 0.0
    for part in parts:
        part = np.asarray(part, dtype=float)
        c = float(np.mean(part))
        k = np.arange(len(part))
        env = smoothstep(k / max(1, nf)) * smoothstep((len(part) - 1 - k) / max(1, nf))
        out.append(level + (c - level) * smoothstep(np.arange(nb) / max(1, nb - 1)))
        out.append(c + env * (part - c))
        level = c
    return np.concatenate(out)


def reference(theta_out: np.ndarray, rate: float = RATE) -> Reference:
    theta_out = np.asarray(theta_out, dtype=float)
    omega = np.gradient(theta_out, 1.0 / rate)
    alpha = np.gradient(omega, 1.0 / rate)
    return Reference(theta_out, omega, alpha, rate)


def _lowpass(x: np.ndarray, cutoff: float, rate: float) -> np.ndarray:
    from scipy.signal import butter, sosfiltfilt

    sos = butter(2, cutoff / (0.5 * rate), output="sos")
    return sosfiltfilt(sos, x)
