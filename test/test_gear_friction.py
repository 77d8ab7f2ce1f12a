"""Issue #24, symptom 2: a friction that grows with the torque the gear transmits (BAM's load-dependent model,
|τ_f| = τ_c + μ |K i_q|) is a catalogued effect, ``torque_dependent_gear_friction``, with a simulator term.

(d) the kernel's stick/slip: the breakaway level grows with the transmitted torque, against the analytic
value; (a) a geared actuator on a pendulum under a position controller with two gains (so the torque levels
differ at similar speeds), recorded (1) through the project's kernel and (2) by an independent integration of a
hand-written ODE (scipy ``solve_ivp``): the effect is named with μ within its uncertainty, Coulomb and viscous
within theirs, no magnetic_saturation / iron_loss; (c) the same recordings with μ = 0 name no gear friction.
The voltage-mode route (a servo without current sensor) is tested in ``test_issue24_voltage_mode.py``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parent))

import issue24_generators as G  # noqa: E402

from bldc_actuator import effects  # noqa: E402
from bldc_actuator.diagnosis.effects import registry  # noqa: E402
from bldc_actuator.diagnosis.pipeline import diagnose  # noqa: E402
from bldc_actuator.diagnosis.signals import Signals  # noqa: E402
from bldc_actuator.model import Actuator  # noqa: E402
from bldc_actuator.params import ActuatorParams  # noqa: E402

GEAR_EFFECT = "torque_dependent_gear_friction"
MU, TC, B = 0.3, 0.02, 4e-4               # gear friction [-], Coulomb [N*m], viscous [N*m*s/rad] (motor side)
N, J, TAU_G = 10.0, 2e-4, 1.0             # gear ratio, inertia [kg*m^2] (load reflected), pendulum [N*m, output]


# ------------------------------------------------------------------------------ (d) the kernel's breakaway

def _breakaway(mu, tc=0.05, load_out=0.0, ramp=2.0, duration=4.0):
    """Motor torque K i_q [N*m] at which a rotor at rest under a slow current ramp (``ramp`` A/s) first moves."""
    p = ActuatorParams().replace(**{"effects.coulomb_friction": tc, "effects.gear_load_friction": mu,
                                    "load.load_torque": load_out})
    act, dt = Actuator(p), 1e-4
    for k in range(int(duration / dt)):
        act.set_current_command(ramp * k * dt)
        act.step(dt)
        if act.state.omega != 0.0:
            return p.motor.torque_constant_q * act.state.i_q
    return None


@pytest.mark.parametrize("mu", [0.0, 0.3, 0.6])
def test_the_breakaway_level_grows_with_the_transmitted_torque(mu):
    """No load: the drive is the motor's torque τ, static friction τ_c + μ|τ|: it breaks away at τ_c/(1 - μ)."""
    tau = _breakaway(mu)
    K_ramp_step = 0.091 * 2.0 * 1e-4                 # the ramp's change of K i over one step
    assert tau == pytest.approx(0.05 / (1.0 - mu), abs=3 * K_ramp_step + 1e-6)


def test_a_load_adds_to_the_breakaway_and_a_gear_with_mu_above_one_self_locks():
    # a constant load (below τ_c: it does not back-drive the rotor) at the output of a 1:1 gear
    tau = _breakaway(0.3, load_out=0.03)
    assert tau == pytest.approx((0.05 + 0.03) / 0.7, abs=1e-4)
    assert _breakaway(1.2) is None                   # μ >= 1: the motor's own torque never breaks it free


def test_the_energy_ledger_closes_with_gear_friction():
    """The gear friction's work is friction work: electrical in = Joule + ΔE_mag + ΔE_kin + viscous + friction
    to 1e-6 under a chirp through reversals and stick/slip, and it dissipates more than Coulomb friction alone."""
    from bldc_actuator import profiles

    out = {}
    for mu in (0.0, 0.4):
        act = Actuator(ActuatorParams().replace(**{"effects.coulomb_friction": 0.02, "effects.gear_load_friction": mu,
                                                   "motor.viscous_damping": 1e-4}))
        e0 = act.energy
        act.run(profiles.chirp(6.0, 0.2, 8.0, duration=4.0, rate=1000.0))
        e = act.energy
        assert abs(e.residual(e0)) <= 1e-6 * e.electrical_in
        out[mu] = e.friction
    assert out[0.4] > 1.2 * out[0.0] > 0


def test_the_shared_term_is_mu_times_the_absolute_torque():
    assert effects.gear_load_friction(np.array([-2.0, 0.0, 3.0]), 0.25) == pytest.approx([0.5, 0.0, 0.75])


# ------------------------------------------------------------------------------ (a, c) the full route

def _nominal() -> ActuatorParams:
    """What the user knows: the motor, the gear and the pendulum; friction is what is missing."""
    return ActuatorParams().replace(**{"motor.rotor_inertia": J, "motor.viscous_damping": 1e-4,
                                       "gear.gear_ratio": N, "load.gravity_torque": TAU_G})


def _truth(mu) -> ActuatorParams:
    return _nominal().replace(**{"effects.coulomb_friction": TC, "effects.gear_load_friction": mu,
                                 "motor.viscous_damping": B})


DURATION = 16.0
K_NOM = _nominal().motor.torque_constant_q


def _ref(t):
    """Motor-side angle reference [rad] and its rate: the pendulum swung over ±3 rad at the output."""
    a = [(30.0, 0.31, 0.0), (8.0, 1.13, 1.0), (3.0, 2.7, 2.0)]
    th = sum(A * math.sin(2 * math.pi * f * t + ph) for A, f, ph in a)
    dth = sum(A * 2 * math.pi * f * math.cos(2 * math.pi * f * t + ph) for A, f, ph in a)
    return th, dth


def _gains(t):
    """Two position-loop gains (first half soft, second half stiff): the same motion at other torque levels."""
    wn = 2 * math.pi * (3.0 if t < DURATION / 2 else 9.0)
    return J * wn ** 2 / K_NOM, 2 * 0.7 * J * wn / K_NOM


def _command(t, pos, vel):
    kp, kd = _gains(t)
    th, dth = _ref(t)
    return max(-15.0, min(15.0, kp * (th - pos) + kd * (dth - vel)))


def _kernel_log(mu, seed=11):
    return G.record(_truth(mu), _command, duration=DURATION, rate=1000.0, seed=seed)


def _ode_log(mu, seed=12, rate=1000.0, noise_i=0.03):
    """The same actuator as a hand-written ODE: an ideal current loop (i_q = the command), the friction's sign
    smoothed (tanh(ω/0.05 rad/s)), integrated by LSODA; logged like the drive logs (current + noise, a 14-bit
    encoder, backward-difference speed)."""
    K = K_NOM
    w_s = 0.05

    def cmd(t, th, w):
        kp, kd = _gains(t)
        r, dr = _ref(t)
        return min(15.0, max(-15.0, kp * (r - th) + kd * (dr - w)))

    def rhs(t, x):
        th, w = x
        tau_m = K * cmd(t, th, w)
        load = TAU_G * math.sin(th / N) / N
        fric = (TC + mu * abs(tau_m)) * math.tanh(w / w_s) + B * w
        return [w, (tau_m - fric - load) / J]

    t = np.arange(int(DURATION * rate)) / rate
    halves = [t < DURATION / 2, t >= DURATION / 2]
    th, w = np.zeros(len(t)), np.zeros(len(t))
    x0, t0 = [0.0, 0.0], 0.0
    for sel in halves:                                # the gain switch: integrate each half on its own
        tt = t[sel]
        sol = solve_ivp(rhs, (t0, tt[-1]), x0, method="LSODA", t_eval=tt, rtol=1e-7, atol=1e-9, max_step=5e-3)
        assert sol.success
        th[sel], w[sel] = sol.y
        x0, t0 = [float(sol.y[0, -1]), float(sol.y[1, -1])], float(tt[-1])
    rng = np.random.default_rng(seed)
    q = 2 * math.pi / 2 ** 14
    pos = np.round(th / q) * q
    vel = np.concatenate([[0.0], np.diff(pos) * rate])
    i = np.array([cmd(tk, a, b) for tk, a, b in zip(t, th, w)])
    out = {"current_command": i, "current": i + noise_i * rng.standard_normal(len(t)), "position": pos,
           "velocity": vel}
    return Signals(t, out, source="synthetic")


def _check_named(rep, mu):
    named = {f["effect"]: f for f in rep.findings}
    assert GEAR_EFFECT in named, (rep.verdict, [(r["effect"], r.get("reason")) for r in rep.rejected])
    g = named[GEAR_EFFECT]
    val, sd = g["parameters"]["gear_load_friction"], g["uncertainty"]["gear_load_friction"]
    assert abs(val - mu) <= 3 * sd + 0.03 * mu, g
    tc = named.get("coulomb_friction") or named.get("asymmetric_friction")
    assert tc is not None, rep.verdict
    assert abs(tc["parameters"]["coulomb_friction"] - TC) <= 3 * tc["uncertainty"]["coulomb_friction"] + 0.05 * TC
    visc = named.get("viscous_friction")
    assert visc is not None, rep.verdict
    assert abs(visc["parameters"]["viscous_damping"] - B) <= 3 * visc["uncertainty"]["viscous_damping"] + 0.05 * B
    assert not {"magnetic_saturation", "iron_loss", "torque_constant_error"} & set(named), rep.verdict
    assert rep.updated_params.effects.gear_load_friction == pytest.approx(val, abs=3 * sd + 0.01 * mu)   # written


@pytest.fixture(scope="module")
def kernel_logs():
    return _kernel_log(MU), _kernel_log(0.0)


@pytest.fixture(scope="module")
def ode_logs():
    return _ode_log(MU), _ode_log(0.0)


def test_gear_friction_is_named_on_the_kernel_recording(kernel_logs):
    _check_named(diagnose(kernel_logs[0], _nominal()), MU)


def test_gear_friction_is_named_on_the_independent_ode_recording(ode_logs):
    _check_named(diagnose(ode_logs[0], _nominal()), MU)


@pytest.mark.parametrize("which", ["kernel", "ode"])
def test_no_gear_friction_where_mu_is_zero(which, kernel_logs, ode_logs):
    sig = (kernel_logs if which == "kernel" else ode_logs)[1]
    rep = diagnose(sig, _nominal())
    assert GEAR_EFFECT not in rep.effects, rep.verdict
    assert "coulomb_friction" in rep.effects or "asymmetric_friction" in rep.effects, rep.verdict


def test_the_record_says_what_separates_it():
    e = registry.get(GEAR_EFFECT)
    assert {"coulomb_friction", "magnetic_saturation", "torque_constant_error"} <= set(e.confusable)
    assert e.params[0].field == "effects.gear_load_friction"
