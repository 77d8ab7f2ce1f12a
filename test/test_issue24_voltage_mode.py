"""Issue #24, symptom 3: a voltage-mode actuator without a current sensor (a hobby-grade servo: coreless DC
motor, 288:1 gear, a PWM bridge, logs at 190 Hz of output angle and speed, duty and supply, no current) has a
route: the mechanical equation closes with i = (v - K ω)/R, K_t/R and the friction are identified with their
uncertainties, the combinations are said as combinations, and friction is judged by replaying the mechanical
equation under the recorded voltage on held-out windows.

The data are made here by an independent integration (scipy ``solve_ivp``, LSODA, a tanh-smoothed Coulomb
sign) of the motor's own ODE, not by the project's kernel, written as a CSV of the log's columns and read through
``--map`` expressions (``voltage_q=duty*v_bus``, speeds and angles at the output x 288)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bldc_actuator.diagnosis import pipeline
from bldc_actuator.diagnosis import voltage_mode as vm
from bldc_actuator.diagnosis.io import loaders
from bldc_actuator.diagnosis.io.cleaning import clean
from bldc_actuator.diagnosis.io.mapping import Mapping
from bldc_actuator.params import ActuatorParams

GEAR = 288.0
RATE = 190.0
K, R, L, J = 0.006, 4.0, 1.0e-4, 2.0e-7           # N*m/A, ohm, H, kg*m^2 (motor side, load reflected)
B_TRUE, TC_TRUE = 4.0e-6, 4.0e-4                    # viscous [N*m*s/rad], Coulomb [N*m] at the motor side
MAP = ["time=t", "voltage_q=duty*v_bus", "velocity=speed_out*288", "position=angle_out*288"]


def _nominal(**over) -> ActuatorParams:
    base = {"motor.torque_constant_q": K, "motor.phase_resistance": R, "motor.q_inductance": L,
            "motor.rotor_inertia": J, "motor.viscous_damping": 1.0e-6, "effects.coulomb_friction": 0.0,
            "gear.gear_ratio": GEAR}
    base.update(over)
    return ActuatorParams().replace(**base)


def _duty(t):
    return (0.42 * np.sin(2 * np.pi * 0.37 * t) + 0.22 * np.sin(2 * np.pi * 1.1 * t + 1.0)
            + 0.10 * np.sin(2 * np.pi * 2.9 * t + 2.0))


def _vbus(t):
    return 12.0 - 0.25 * np.sin(2 * np.pi * 0.05 * t)


def _log(tmp_path, b, tc, *, duration=40.0, noise=0.004, seed=3):
    """The servo's CSV: t, angle_out, speed_out, duty, v_bus (no current)."""
    w_s = 0.2                                       # rad/s: the Coulomb sign's smoothing in the generator

    def rhs(t, x):
        v = _duty(t) * _vbus(t)
        w = x[1]
        return [w, (K / R * (v - K * w) - b * w - tc * np.tanh(w / w_s)) / J]

    t = np.arange(int(duration * RATE)) / RATE
    sol = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0], method="LSODA", t_eval=t, rtol=1e-8, atol=1e-8,
                    max_step=1e-3)
    assert sol.success
    rng = np.random.default_rng(seed)
    speed_out = sol.y[1] / GEAR + noise * rng.standard_normal(len(t))
    angle_out = sol.y[0] / GEAR + 1e-4 * rng.standard_normal(len(t))
    cols = {"t": t, "angle_out": angle_out, "speed_out": speed_out, "duty": _duty(t), "v_bus": _vbus(t)}
    p = tmp_path / "servo.csv"
    p.write_text(",".join(cols) + "\n" + "\n".join(",".join(f"{v:.10g}" for v in r)
                                                    for r in np.column_stack(list(cols.values()))) + "\n")
    return p


def _servo_csv(path, rhs, x0, *, speed_state: int, seed: int, duration: float = 40.0):
    """The servo's CSV from the ODE ``rhs`` (state 0 the motor angle, ``speed_state`` the logged speed): t,
    angle_out, speed_out, duty, v_bus with the log's noise."""
    t = np.arange(int(duration * RATE)) / RATE
    sol = solve_ivp(rhs, (0.0, t[-1]), x0, method="LSODA", t_eval=t, rtol=1e-8, atol=1e-8, max_step=1e-3)
    assert sol.success
    rng = np.random.default_rng(seed)
    cols = {"t": t, "angle_out": sol.y[0] / GEAR + 1e-4 * rng.standard_normal(len(t)),
            "speed_out": sol.y[speed_state] / GEAR + 0.004 * rng.standard_normal(len(t)), "duty": _duty(t),
            "v_bus": _vbus(t)}
    path.write_text(",".join(cols) + "\n" + "\n".join(",".join(f"{v:.10g}" for v in r)
                                                       for r in np.column_stack(list(cols.values()))) + "\n")
    return path


def _signals(path, params):
    return clean(loaders.load(path, mapping=Mapping.parse(MAP), params=params), params=params)


@pytest.fixture(scope="module")
def friction_log(tmp_path_factory):
    return _log(tmp_path_factory.mktemp("vm"), B_TRUE, TC_TRUE)


def test_route_selects_voltage_mode_when_current_is_absent(friction_log):
    sig = _signals(friction_log, _nominal())
    assert "current" not in sig.channels and "voltage_q" in sig.channels
    assert pipeline.route(sig) == pipeline.VOLTAGE_MODE


def test_recovers_k_over_r_and_friction_within_their_uncertainties(friction_log):
    p = _nominal()
    res = vm.diagnose(_signals(friction_log, p), p)
    cmb = res.combinations
    kr = cmb["torque_constant_over_resistance"]
    assert abs(kr["value"] - K / R) <= 3 * kr["sd"], kr
    tc = cmb["coulomb_friction"]
    assert abs(tc["value"] - TC_TRUE) <= 3 * tc["sd"], tc
    d = cmb["back_emf_plus_viscous"]
    assert abs(d["value"] - (K * K / R + B_TRUE)) <= 3 * d["sd"], d
    b = cmb["viscous_damping"]
    assert abs(b["value"] - B_TRUE) <= 3 * b["sd"], b
    assert "given K_t" in b["identifiable"] and "independent of J" in cmb["effective_back_emf_constant"]["identifiable"]
    assert "not identifiable" in cmb["torque_constant_and_resistance_apart"]["identifiable"]
    # the friction differs from nominal (Coulomb 0, viscous 1e-6): both named, and confirmed by the replay
    named = {f.effect: f for f in res.findings}
    friction = {vm.effect_for("effects.coulomb_friction"), vm.effect_for("motor.viscous_damping")}
    assert friction <= set(named), (named, [(r.effect, r.reason) for r in res.rejected])
    for e in friction:
        s = named[e].simulation
        assert s["with"] < s["without"] and s["paired_gain"] > 2 * s["paired_se"], s
    # K/R equals its nominal value: not a finding
    assert vm.effect_for("motor.phase_resistance") not in named
    assert res.simulation["updated"] < res.simulation["nominal"]


def test_diagnose_reports_through_the_common_report(friction_log):
    p = _nominal()
    rep = pipeline.diagnose(_signals(friction_log, p), p)
    assert rep.method.startswith("voltage mode")
    assert rep.verdict_kind == "found" and "needs current" not in rep.verdict
    d = rep.to_dict()
    assert {f["effect"] for f in d["findings"]} >= {vm.effect_for("effects.coulomb_friction")}
    up = rep.updated_params
    assert abs(up.effects.coulomb_friction - TC_TRUE) < 0.02 * TC_TRUE
    assert abs(up.motor.viscous_damping - B_TRUE) < 0.02 * B_TRUE
    assert up.motor.phase_resistance == R          # K_t/R at its nominal value: R is not rewritten


def test_a_null_names_nothing(tmp_path):
    """The log made with the nominal friction: nothing is missing."""
    p = _nominal(**{"motor.viscous_damping": B_TRUE, "effects.coulomb_friction": TC_TRUE})
    path = _log(tmp_path, B_TRUE, TC_TRUE, seed=11)
    rep = pipeline.diagnose(_signals(path, p), p)
    assert rep.findings == [], rep.findings
    assert rep.verdict_kind == "nothing missing", rep.verdict


def test_the_replay_sticks_below_the_break_away_voltage():
    """The judge's ODE: under a voltage below τ_c R/K the motor does not start; above it, it reaches the
    steady speed ((K/R) v - τ_c)/(K²/R + b)."""
    kr, dmp, tc = K / R, K * K / R + B_TRUE, TC_TRUE
    n = 400
    dt = np.full((2, n - 1), 1 / RATE)
    v = np.vstack([np.full(n, 0.9 * tc / kr), np.full(n, 3.0)])
    w = vm.simulate_speed(J, kr, dmp, tc, 0.0, v, dt, np.zeros(2))
    assert np.all(w[0] == 0.0)
    np.testing.assert_allclose(w[1, -1], (kr * 3.0 - tc) / dmp, rtol=1e-6)


def test_the_electrical_lag_is_modelled_where_the_sampling_resolves_it(tmp_path):
    """A BLDC in voltage mode (q-axis equivalent) logged at 1 kHz with L/R = 2 ms: the current lags the voltage
    by two samples, i = LP[(v - K ω)/R]; the route models the lag and still recovers K/R and the friction."""
    k, r, l, j, b, tc, rate = 0.05, 0.5, 1.0e-3, 1.0e-4, 2.0e-4, 0.02, 1000.0

    def volt(t):
        return (4.0 * np.sin(2 * np.pi * 0.5 * t) + 1.5 * np.sin(2 * np.pi * 3.1 * t + 0.4)
                + 0.8 * np.sin(2 * np.pi * 11.0 * t + 1.3))

    def rhs(t, x):
        w, i = x
        return [(k * i - b * w - tc * np.tanh(w / 0.05)) / j, (volt(t) - r * i - k * w) / l]

    t = np.arange(int(20.0 * rate)) / rate
    sol = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0], method="LSODA", t_eval=t, rtol=1e-8, atol=1e-9, max_step=5e-4)
    assert sol.success
    w = sol.y[0] + 0.05 * np.random.default_rng(5).standard_normal(len(t))
    p = ActuatorParams().replace(**{"motor.torque_constant_q": k, "motor.phase_resistance": r,
                                    "motor.q_inductance": l, "motor.rotor_inertia": j,
                                    "motor.viscous_damping": 1e-5, "effects.coulomb_friction": 0.0})
    path = tmp_path / "vq.csv"
    path.write_text("time,voltage_q,velocity\n" + "\n".join(f"{a:.10g},{v:.10g},{x:.10g}"
                                                            for a, v, x in zip(t, volt(t), w)) + "\n")
    sig = clean(loaders.load(path, params=p), params=p)
    res = vm.diagnose(sig, p)
    assert res.electrical_lag, res.notes
    cmb = res.combinations
    for name, truth in (("torque_constant_over_resistance", k / r), ("back_emf_plus_viscous", k * k / r + b),
                        ("coulomb_friction", tc)):
        assert abs(cmb[name]["value"] - truth) <= 3 * cmb[name]["sd"], (name, cmb[name], truth)
    assert vm.effect_for("effects.coulomb_friction") in {f.effect for f in res.findings}


def test_a_pendulum_on_the_output_is_told_from_friction(tmp_path):
    """The servo swinging a pendulum (τ_g sin θ_out at the output): the gravity-like load is found with its
    amplitude and phase, and the friction is still recovered beside it."""
    tau_g, phase = 0.25, 0.3                         # N*m at the output, rad
    w_s = 0.2

    def rhs(t, x):
        v = _duty(t) * _vbus(t)
        th, w = x
        load = tau_g * np.sin(th / GEAR + phase) / GEAR
        return [w, (K / R * (v - K * w) - B_TRUE * w - TC_TRUE * np.tanh(w / w_s) - load) / J]

    path = _servo_csv(tmp_path / "pendulum.csv", rhs, [0.0, 0.0], speed_state=1, seed=7)
    p = _nominal()
    res = vm.diagnose(_signals(path, p), p)
    named = {f.effect: f for f in res.findings}
    load = named.get(vm.effect_for("load.gravity_torque"))
    assert load is not None, [(r.effect, r.reason) for r in res.rejected]
    g, ph = load.parameters["gravity_torque"], load.parameters["gravity_phase"]
    assert abs(g - tau_g) <= 3 * load.uncertainty["gravity_torque"], load
    assert abs(ph - phase) <= 3 * load.uncertainty["gravity_phase"], load
    tc = res.combinations["coulomb_friction"]
    assert abs(tc["value"] - TC_TRUE) <= 3 * tc["sd"], tc
    assert vm.effect_for("effects.coulomb_friction") in named


def test_effect_names_come_from_the_library():
    from bldc_actuator.diagnosis.frame.candidates import EFFECT_NAMES

    names = {f: vm.effect_for(f) for f in ("effects.coulomb_friction", "motor.viscous_damping",
                                           "motor.phase_resistance", "load.gravity_torque")}
    assert set(names.values()) <= set(EFFECT_NAMES) and len(set(names.values())) == 4, names


def _servo_duty(t, th, w, dur):
    """A position servo's PWM duty: PD on the output angle against a two-sine reference, its gain tripled
    halfway (the same motion at other torque levels), clipped to ±1."""
    kp = 1.0 if t < dur / 2 else 3.0
    r = 1.2 * np.sin(2 * np.pi * 0.23 * t) + 0.4 * np.sin(2 * np.pi * 0.87 * t + 1.0)
    dr = (1.2 * 2 * np.pi * 0.23 * np.cos(2 * np.pi * 0.23 * t)
          + 0.4 * 2 * np.pi * 0.87 * np.cos(2 * np.pi * 0.87 * t + 1.0))
    return float(np.clip(kp * (r - th / GEAR) + 0.05 * (dr - w / GEAR), -1.0, 1.0))


def test_a_friction_growing_with_the_transmitted_torque_is_named_without_a_current_sensor(tmp_path, friction_log):
    """Issue #24 symptom 2: a position servo on a pendulum with gear friction μ |K i| on top of Coulomb +
    viscous (what published identifications of such servos need, BAM's load-dependent model), two loop gains:
    the route names torque_dependent_gear_friction with μ (its column from the current the voltage gives,
    i = (v - K ω)/R), Coulomb beside it, and writes μ to the parameter file. While motoring μ|K i| is the K_t/R
    column; the servo brakes when it lowers the pendulum or decelerates, which tells them apart: K_t/R comes out
    nominal and R is not called off. The friction-only (open-loop, never braking) log names no gear friction."""
    mu, w_s, tau_g, phase, dur = 0.3, 0.2, 0.25, 0.3, 40.0

    def rhs(t, x):
        th, w = x
        tau_m = K / R * (_servo_duty(t, th, w, dur) * _vbus(t) - K * w)
        load = tau_g * np.sin(th / GEAR + phase) / GEAR
        return [w, (tau_m - B_TRUE * w - (TC_TRUE + mu * abs(tau_m)) * np.tanh(w / w_s) - load) / J]

    t = np.arange(int(dur * RATE)) / RATE
    sol = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0], method="LSODA", t_eval=t, rtol=1e-8, atol=1e-8, max_step=1e-3)
    assert sol.success
    rng = np.random.default_rng(9)
    duty = np.array([_servo_duty(a, b, c, dur) for a, b, c in zip(t, sol.y[0], sol.y[1])])
    cols = {"t": t, "angle_out": sol.y[0] / GEAR + 1e-4 * rng.standard_normal(len(t)),
            "speed_out": sol.y[1] / GEAR + 0.004 * rng.standard_normal(len(t)), "duty": duty, "v_bus": _vbus(t)}
    path = tmp_path / "gear.csv"
    path.write_text(",".join(cols) + "\n" + "\n".join(",".join(f"{v:.10g}" for v in r)
                                                       for r in np.column_stack(list(cols.values()))) + "\n")
    p = _nominal(**{"load.gravity_torque": tau_g, "load.gravity_phase": phase})
    rep = pipeline.diagnose(_signals(path, p), p)
    gear = vm.effect_for(vm.GEAR_FIELD)
    named = {f["effect"]: f for f in rep.findings}
    assert gear in named, (rep.verdict, rep.rejected, rep.notes)
    g = named[gear]
    val, sd = g["parameters"]["gear_load_friction"], g["uncertainty"]["gear_load_friction"]
    assert abs(val - mu) <= 3 * sd + 0.05 * mu, g
    assert rep.updated_params.effects.gear_load_friction == pytest.approx(val)
    tc = rep.compare["voltage_mode"]["combinations"]["coulomb_friction"]
    assert abs(tc["value"] - TC_TRUE) <= 3 * tc["sd"] + 0.05 * TC_TRUE, tc
    kr = rep.compare["voltage_mode"]["combinations"]["torque_constant_over_resistance"]
    assert abs(kr["value"] - K / R) <= 3 * kr["sd"] + 0.05 * K / R, kr
    assert vm.effect_for("motor.phase_resistance") not in named
    assert "outside the catalogue" not in rep.verdict
    # the same log as a training file and a separate held-out file (--holdout-file): judged on the second
    cut = t < 0.7 * dur
    parts = []
    for name, sel in (("train.csv", cut), ("heldout.csv", ~cut)):
        part = tmp_path / name
        part.write_text(",".join(cols) + "\n" + "\n".join(",".join(f"{v:.10g}" for v in r) for r in
                                                           np.column_stack([x[sel] for x in cols.values()])) + "\n")
        parts.append(_signals(part, p))
    split = vm.diagnose(parts[0], p, holdout_signals=parts[1])
    hit = {f.effect: f for f in split.findings}.get(gear)
    assert hit is not None, ([(r.effect, r.reason) for r in split.rejected], split.notes)
    assert abs(hit.parameters["gear_load_friction"] - mu) <= 3 * hit.uncertainty["gear_load_friction"] + 0.05 * mu
    assert hit.simulation["windows"] >= 10
    clean_rep = pipeline.diagnose(_signals(friction_log, p), p)
    assert gear not in {f["effect"] for f in clean_rep.findings}, clean_rep.verdict


def test_a_filtered_speed_estimate_is_measured_against_the_angle_and_the_equation_lagged_alike(tmp_path):
    """The servo's drive logs its speed through a first-order low pass at 20 Hz (lag 1/(2 pi 20) = 7.96 ms, 1.5
    samples at 190 Hz; integrated here as a state of the ODE), the angle as it is. The route measures that lag
    against the angle's speed, lags the voltage and the friction's direction alike, and recovers K/R and Coulomb
    friction; taken as an aligned speed the same log puts K/R and Coulomb off by many of their standard errors."""
    tau = 1.0 / (2 * np.pi * 20.0)
    w_s = 0.2

    def rhs(t, x):
        th, w, w_est = x
        v = _duty(t) * _vbus(t)
        return [w, (K / R * (v - K * w) - B_TRUE * w - TC_TRUE * np.tanh(w / w_s)) / J, (w - w_est) / tau]

    path = _servo_csv(tmp_path / "lagged.csv", rhs, [0.0, 0.0, 0.0], speed_state=2, seed=13)
    p = _nominal()
    sig = _signals(path, p)
    lag, gain = vm.velocity_lag(sig)
    assert abs(lag - tau) < 0.1 * tau and abs(gain - 1.0) < 0.02, (lag, gain)
    res = vm.diagnose(sig, p)
    assert any("lags the angle's speed" in n for n in res.notes), res.notes
    cmb = res.combinations
    for name, truth in (("torque_constant_over_resistance", K / R), ("coulomb_friction", TC_TRUE)):
        assert abs(cmb[name]["value"] - truth) <= 3 * cmb[name]["sd"], (name, cmb[name], truth)
    # the same log with its speed taken as aligned (the angle dropped: no lag can be measured)
    bare = _signals(path, p)
    bare.channels = {k: v for k, v in bare.channels.items() if k != "position"}
    off = vm.diagnose(bare, p).combinations
    assert any(abs(off[name]["value"] - truth) > 5 * off[name]["sd"]
               for name, truth in (("torque_constant_over_resistance", K / R), ("coulomb_friction", TC_TRUE))), off
