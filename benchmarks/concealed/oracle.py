"""Oracle check: is the hidden effect identifiable from the recorded channels at all?

An estimator that is told the effect's FORM (not its size) fits it by equation error on the training
recording, with parallel filtering (every regressor and the target through the same zero-phase low-pass,
then decimated). The electrical equation uses the current command as an instrument (the logged voltage
contains the PI's reaction to the same current-sensor noise as the logged current: ordinary least squares
biases R low in closed loop). When the oracle recovers the size, a miss is the diagnoser's; when it does not,
the data cannot show the effect and the case says so.

Independent of ``bldc_actuator``; reads only the CSV columns and the nominal numbers in the truth JSON. The
recording's rate is read from its time column (10 Hz averaged thermal logs up to 10 kHz drive logs): filters,
derivatives, the trimmed edges (0.2 s) and the decimation (to about 200 Hz) follow it; at 1 kHz they are the
numbers this oracle always used.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import butter, sosfiltfilt


RATE = 1000.0     #: the rate the oracle was written for (its filter and decimation numbers are per 1 kHz)


def rate_of(rec: dict) -> float:
    """Samples per second of a recording, from its time column."""
    t = np.asarray(rec["time"], dtype=float)
    return float(1.0 / np.median(np.diff(t))) if len(t) > 1 else RATE


def _lp(fc: float, rate: float = RATE):
    fc = min(fc, 0.4 * 0.5 * rate)       # a 10 Hz log: below its Nyquist rate
    sos = butter(4, fc / (0.5 * rate), output="sos")
    return lambda x: sosfiltfilt(sos, np.asarray(x, dtype=float))


def _d(x, rate: float = RATE):
    return np.gradient(np.asarray(x, dtype=float), 1.0 / rate)


def _window(rate: float) -> slice:
    """Trim 0.2 s at both ends (filter transients), keep about 200 samples per second."""
    trim = max(1, int(round(0.2 * rate)))
    return slice(trim, -trim, max(1, int(round(rate / 200.0))))


def _lstsq(cols: dict, y, rate: float = RATE):
    sl = _window(rate)
    X = np.column_stack(list(cols.values()))[sl]
    coef, *_ = np.linalg.lstsq(X, np.asarray(y)[sl], rcond=None)
    return dict(zip(cols, coef))


def mechanical(rec: dict, nominal: dict, extra: dict, fc: float = 30.0) -> dict:
    """``K_nom i = J α + b ω + Σ extra`` (J, b free; every column filtered alike)."""
    rate = rate_of(rec)
    F = _lp(fc, rate)
    th = rec["position"]
    w_raw = _d(th, rate)
    w_s = F(w_raw)
    cols = {"J": F(_d(_d(th, rate), rate)), "b": F(w_raw)}
    for name, fn in extra.items():
        cols[name] = F(fn(th, w_s, rec))
    return _lstsq(cols, F(nominal["motor.torque_constant_q"] * rec["current"]), rate)


def electrical(rec: dict, extra: dict, fc: float = 30.0) -> dict:
    """``v_q = R i + L di/dt + K ω + Σ extra``, instrumental variables (current command for the current)."""
    rate = rate_of(rec)
    F = _lp(fc, rate)
    w = _d(rec["position"], rate)
    i, ir = rec["current"], rec["current_command"]
    X = {"R": F(i), "L": F(_d(i, rate)), "K": F(w)}
    Z = {"R": F(ir), "L": F(_d(ir, rate)), "K": F(w)}
    for name, (fx, fz) in extra.items():
        X[name], Z[name] = F(fx(rec, i)), F(fz(rec, ir))
    sl = _window(rate)
    Xm = np.column_stack(list(X.values()))[sl]
    Zm = np.column_stack(list(Z.values()))[sl]
    coef = np.linalg.solve(Zm.T @ Xm, Zm.T @ F(rec["voltage_q"])[sl])
    return dict(zip(X, coef))


def _sign(w_s, eps=0.3):
    return np.tanh(w_s / eps)


def estimate(case_name: str, truth: dict, rec: dict, nominal: dict, cogging_order: int) -> tuple[str, float | None]:
    """(main parameter name, oracle estimate in the truth's unit) for the case's first hidden effect. ``nominal``:
    the case's whole nominal parameter set (flat names); ``cogging_order``: the stator's cogging periods per
    revolution (both given by :mod:`.cases`, which this module does not import)."""
    nominal = dict(nominal)
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
        order = cogging_order if effect == "cogging_torque" else nominal["motor.pole_pairs"]
        # angle-synchronous fit where the order is resolved by the 1 kHz samples and the recording
        rate = rate_of(rec)
        est = mechanical(rec, nominal, {"cs": lambda th, w, r: np.cos(order * th) * _slow(w, order, rate),
                                        "sn": lambda th, w, r: np.sin(order * th) * _slow(w, order, rate),
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
        w = _d(rec["position"], rate_of(rec))
        est = electrical(rec, {"dT": (lambda r, i: w * (r["housing_temperature"] - T0),
                                      lambda r, i: w * (r["housing_temperature"] - T0))})
        return main, est["dT"] / est["K"]
    if effect == "thermal_parameters":
        return main, thermal(rec, nominal, main)
    if effect == "voltage_saturation":
        v_max = nominal["drive.bus_voltage"] / math.sqrt(2.0)
        return main, float(np.percentile(np.abs(rec["voltage_q"]), 99.9) / v_max)
    return main, None


def thermal(rec: dict, nominal: dict, name: str) -> float:
    """One parameter of the two-node network (``thermal.<name>``, the others nominal) fitted by simulating the
    network from the logged current (Joule power R(T_w) i², R(T) as the nominal file says) against both logged
    temperatures (output error; 1-D bounded search over 0.2 .. 5 x nominal)."""
    from scipy.optimize import minimize_scalar

    q = max(1, int(round(rate_of(rec) / 2.0)))        # 2 Hz blocks: the network's time constants are >= 15 s
    n = (len(rec["time"]) // q) * q

    def blocks(x):
        return np.asarray(x, dtype=float)[:n].reshape(-1, q).mean(axis=1)

    t = blocks(rec["time"])
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    i2 = blocks(np.asarray(rec["current"], dtype=float) ** 2)
    Tw_m, Th_m = blocks(rec["winding_temperature"]), blocks(rec["housing_temperature"])
    R0, T0 = nominal["motor.phase_resistance"], nominal["motor.reference_temperature"]
    alpha = nominal["motor.copper_temperature_coefficient"] if nominal["motor.resistance_temperature_enabled"] else 0.0
    th = {k: float(nominal[f"thermal.{k}"]) for k in ("winding_to_housing_resistance", "housing_to_ambient_resistance",
                                                       "winding_heat_capacity", "housing_heat_capacity")}
    T_a = nominal["thermal.ambient_temperature"]

    def sse(x):
        c = dict(th, **{name: x})
        T_w, T_h = Tw_m[0], Th_m[0]
        out_w, out_h = np.empty(len(t)), np.empty(len(t))
        for k in range(len(t)):          # 3600 blocks for 30 minutes: plain Python is fast enough
            P = R0 * (1.0 + alpha * (T_w - T0)) * i2[k]
            q = (T_w - T_h) / c["winding_to_housing_resistance"]
            T_w += dt[k] * (P - q) / c["winding_heat_capacity"]
            T_h += dt[k] * (q - (T_h - T_a) / c["housing_to_ambient_resistance"]) / c["housing_heat_capacity"]
            out_w[k], out_h[k] = T_w, T_h
        return float(np.sum((out_w - Tw_m) ** 2) + np.sum((out_h - Th_m) ** 2))

    x0 = th[name]
    res = minimize_scalar(sse, bounds=(0.2 * x0, 5.0 * x0), method="bounded", options={"xatol": 1e-4 * x0})
    return float(res.x)


def _slow(w_s, order, rate=RATE, nyquist_margin=0.8):
    """Weight 1 where the order's frequency is below the recording's Nyquist rate, else 0."""
    f = order * np.abs(w_s) / (2 * math.pi)
    return (f < nyquist_margin * 0.5 * rate).astype(float)
