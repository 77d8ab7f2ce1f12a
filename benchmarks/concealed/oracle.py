"""Oracle check: is the hidden effect identifiable from the recorded channels at all?

An estimator that is told the effect's FORM (not its size) fits it by equation error on the training
recording, with parallel filtering (every regressor and the target through the same zero-phase low-pass,
then decimated). The electrical equation uses the current command as an instrument (the logged voltage
contains the PI's reaction to the same current-sensor noise as the logged current: ordinary least squares
biases R low in closed loop). When the oracle recovers the size, a miss is the diagnoser's; when it does not,
the data cannot show the effect and the case says so.

Independent of ``bldc_actuator``; reads only the CSV columns and the nominal numbers in the truth JSON.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import butter, sosfiltfilt

from .cases import COGGING_ORDER, NOMINAL_BASE

RATE = 1000.0


def _lp(fc: float):
    sos = butter(4, fc / (0.5 * RATE), output="sos")
    return lambda x: sosfiltfilt(sos, np.asarray(x, dtype=float))


def _d(x):
    return np.gradient(np.asarray(x, dtype=float), 1.0 / RATE)


def _lstsq(cols: dict, y, step: int = 5, trim: int = 200):
    X = np.column_stack(list(cols.values()))[trim:-trim:step]
    coef, *_ = np.linalg.lstsq(X, np.asarray(y)[trim:-trim:step], rcond=None)
    return dict(zip(cols, coef))


def mechanical(rec: dict, nominal: dict, extra: dict, fc: float = 30.0) -> dict:
    """``K_nom i = J α + b ω + Σ extra`` (J, b free; every column filtered alike)."""
    F = _lp(fc)
    th = rec["position"]
    w_raw = _d(th)
    w_s = F(w_raw)
    cols = {"J": F(_d(_d(th))), "b": F(w_raw)}
    for name, fn in extra.items():
        cols[name] = F(fn(th, w_s, rec))
    return _lstsq(cols, F(nominal["motor.torque_constant_q"] * rec["current"]))


def electrical(rec: dict, extra: dict, fc: float = 30.0) -> dict:
    """``v_q = R i + L di/dt + K ω + Σ extra``, instrumental variables (current command for the current)."""
    F = _lp(fc)
    w = _d(rec["position"])
    i, ir = rec["current"], rec["current_command"]
    X = {"R": F(i), "L": F(_d(i)), "K": F(w)}
    Z = {"R": F(ir), "L": F(_d(ir)), "K": F(w)}
    for name, (fx, fz) in extra.items():
        X[name], Z[name] = F(fx(rec, i)), F(fz(rec, ir))
    sl = slice(200, -200, 5)
    Xm = np.column_stack(list(X.values()))[sl]
    Zm = np.column_stack(list(Z.values()))[sl]
    coef = np.linalg.solve(Zm.T @ Xm, Zm.T @ F(rec["voltage_q"])[sl])
    return dict(zip(X, coef))


def _sign(w_s, eps=0.3):
    return np.tanh(w_s / eps)


def estimate(case_name: str, truth: dict, rec: dict) -> tuple[str, float | None]:
    """(main parameter name, oracle estimate in the truth's unit) for the case's first hidden effect."""
    nominal = dict(NOMINAL_BASE)
    nominal.update(truth.get("nominal_overrides", {}))
    if not truth["effects"]:
        return "", None
    effect = truth["effects"][0]
    main = next(iter(truth["truth"][effect]))
    N = nominal["gear.gear_ratio"]
    K = nominal["motor.torque_constant_q"]
    Fc_nom = nominal.get("effects.coulomb_friction", 0.0)
    known_fric = (lambda th, w, r: Fc_nom * _sign(w))
    if effect == "coulomb_friction":
        return main, mechanical(rec, nominal, {"c": lambda th, w, r: _sign(w)})["c"]
    if effect == "viscous_friction":
        return main, mechanical(rec, nominal, {"c": lambda th, w, r: _sign(w)})["b"]
    if effect == "asymmetric_friction":
        return main, mechanical(rec, nominal, {"c": lambda th, w, r: _sign(w),
                                               "a": lambda th, w, r: np.abs(_sign(w))})["a"]
    if effect == "stribeck_friction":
        ws = truth["truth"][effect].get("stribeck_velocity", 2.0)
        est = mechanical(rec, nominal, {"c": lambda th, w, r: _sign(w),
                                        "s": lambda th, w, r: _sign(w) * np.exp(-(w / ws) ** 2)})
        return main, est["s"]
    if effect == "position_dependent_load":
        est = mechanical(rec, nominal, {"gs": lambda th, w, r: np.sin(th / N) / N,
                                        "gc": lambda th, w, r: np.cos(th / N) / N,
                                        "fc": known_fric})
        return main, math.hypot(est["gs"], est["gc"])
    if effect == "inertia_error":
        return main, mechanical(rec, nominal, {"fc": known_fric})["J"] / nominal["motor.rotor_inertia"]
    if effect in ("cogging_torque", "electrical_angle_ripple"):
        order = COGGING_ORDER if effect == "cogging_torque" else nominal["motor.pole_pairs"]
        # angle-synchronous fit where the order is resolved by the 1 kHz samples and the recording
        est = mechanical(rec, nominal, {"cs": lambda th, w, r: np.cos(order * th) * _slow(w, order),
                                        "sn": lambda th, w, r: np.sin(order * th) * _slow(w, order),
                                        "c": lambda th, w, r: _sign(w)}, fc=200.0)
        amp = math.hypot(est["cs"], est["sn"])
        return main, amp if effect == "cogging_torque" else amp / K
    if effect == "torque_constant_error":
        return main, electrical(rec, {})["K"] / K
    if effect == "resistance_temperature":
        T0 = nominal["motor.reference_temperature"]
        est = electrical(rec, {"dT": (lambda r, i: i * (r["winding_temperature"] - T0),
                                      lambda r, i: i * (r["winding_temperature"] - T0))})
        return main, est["dT"] / est["R"]
    if effect == "magnet_temperature":
        T0 = nominal["motor.reference_temperature"]
        w = _d(rec["position"])
        est = electrical(rec, {"dT": (lambda r, i: w * (r["housing_temperature"] - T0),
                                      lambda r, i: w * (r["housing_temperature"] - T0))})
        return main, est["dT"] / est["K"]
    if effect == "voltage_saturation":
        v_max = nominal["drive.bus_voltage"] / math.sqrt(2.0)
        return main, float(np.percentile(np.abs(rec["voltage_q"]), 99.9) / v_max)
    return main, None


def _slow(w_s, order, nyquist_margin=0.8):
    """Weight 1 where the order's frequency is below the 1 kHz recording's Nyquist rate, else 0."""
    f = order * np.abs(w_s) / (2 * math.pi)
    return (f < nyquist_margin * 0.5 * RATE).astype(float)
