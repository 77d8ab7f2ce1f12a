"""The drive at the voltage limit (issue #7): ``drive.voltage_limit_mode`` proportional | d_priority |
q_priority | field_weakening. Each mode's top speed is checked against the steady state of the d/q equations
solved here independently of the kernel (scipy):

    v_d = R i_d - p ω L i_q,   v_q = R i_q + p ω L i_d + K ω,   K i_q = b ω        (no load, no friction)

with the limiter's own condition: proportional (and field weakening) scale the PI output onto the circle,
and in steady state the back-calculation anti-windup makes the applied voltage parallel to the current
error (e = i_ref - i); d_priority leaves v_d unclamped (so i_d = i_d,ref) and gives v_q the rest of the
circle; q_priority holds v_q on the circle and v_d = 0."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import fsolve

from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams, ParameterError

CMD = 15.0   # A: far above what the no-load top speed needs


def _params(mode, i_fw=0.0, **kw):
    return ActuatorParams().replace(**{"drive.voltage_limit_mode": mode, "drive.field_weakening_current_max": i_fw,
                                       "motor.resistance_temperature_enabled": False,
                                       "motor.magnet_temperature_enabled": False, **kw})


def _run(p, duration=0.25, cmd=CMD):
    a = Actuator(p)
    a.set_current_command(cmd)
    out = []
    for _ in range(int(duration * 2000)):
        a.step_ns(500_000)
        o = a.outputs()
        out.append((o["omega"], o["i_d"], o["i_q"], o["i_q_ref"], a.state.i_d_ref))
    return a, np.array(out)


def _steady(p, mode, i_d_ref=0.0, load=0.0):
    m = p.motor
    R, L, K, b, pp = m.phase_resistance, m.q_inductance, m.torque_constant_q, m.viscous_damping, m.pole_pairs
    from bldc_actuator import frames

    V = frames.voltage_limit_q(p.drive.bus_voltage, m.winding) * p.drive.modulation_limit

    def eqs(x):
        w, i_d, i_q = x
        v_d = R * i_d - pp * w * L * i_q
        v_q = R * i_q + pp * w * L * i_d + K * w
        torque = K * i_q - b * w - load / p.gear.gear_ratio
        if mode == "d_priority":
            return [i_d - i_d_ref, v_d ** 2 + v_q ** 2 - V ** 2, torque]
        if mode == "q_priority":
            return [v_q - V, v_d, torque]
        e_d, e_q = i_d_ref - i_d, CMD - i_q          # proportional: v parallel to the current error
        return [v_d * e_q - v_q * e_d, v_d ** 2 + v_q ** 2 - V ** 2, torque]

    w, i_d, i_q = fsolve(eqs, [V / K, i_d_ref, 0.0], xtol=1e-12)
    return w, i_d, i_q


@pytest.mark.parametrize("load", [0.0, 0.6])
@pytest.mark.parametrize("mode", ["proportional", "d_priority", "q_priority"])
def test_top_speed_matches_the_steady_state_of_the_dq_equations(mode, load):
    p = _params(mode, **{"load.load_torque": load})
    _, out = _run(p)
    w, i_d, i_q = _steady(p, mode, load=load)
    assert out[-1, 0] == pytest.approx(w, rel=2e-3), (mode, out[-1], w, i_d, i_q)
    assert out[-1, 1] == pytest.approx(i_d, abs=0.02 * CMD)
    assert out[-1, 2] == pytest.approx(i_q, abs=0.02 * CMD)


def test_modes_differ_at_the_limit_and_agree_below_it():
    loaded = {"load.load_torque": 0.6}
    tops = {m: _run(_params(m, **loaded))[1][-1] for m in ("proportional", "d_priority", "q_priority")}
    # under load the cross-coupling needs v_d = -p w L i_q < 0: d priority keeps it (i_d = 0, fastest);
    # proportional scaling shortens it too, so i_d drifts positive (slower); q priority leaves v_d = 0 and
    # i_d = p w L i_q / R flows, costing the most speed
    assert abs(tops["d_priority"][1]) < 0.05 and tops["proportional"][1] > 0.3 and tops["q_priority"][1] > 5
    assert tops["d_priority"][0] > tops["proportional"][0] * 1.005 > tops["q_priority"][0] * 1.05
    # below the limit (a small command, low speed held by a load): every mode is the same trajectory
    slow = {m: _run(_params(m, **{"load.load_torque": 0.05}), duration=0.05, cmd=1.0)[1]
            for m in ("proportional", "d_priority", "q_priority", "field_weakening")}
    for m, tr in slow.items():
        assert np.allclose(tr[:, :3], slow["proportional"][:, :3], rtol=0, atol=1e-9), m


def test_field_weakening_raises_the_top_speed_within_the_current_limit():
    base = _run(_params("d_priority"))[1][-1, 0]
    p = _params("field_weakening", i_fw=8.0)
    a, out = _run(p, duration=0.4)
    assert out[-1, 0] > base * 1.05                                   # faster than without weakening
    lim = p.drive.current_limit
    assert np.all(np.hypot(out[:, 4], out[:, 3]) <= lim * (1 + 1e-9))    # the references obey the limit
    assert np.all(out[:, 4] <= 0) and out[:, 4].min() >= -8.0 - 1e-12
    i_d_ref = out[-1, 4]
    if i_d_ref > -8.0 + 1e-6:      # regulator not at its bound: |v| held at the margin below the circle
        from bldc_actuator import kernel
        v = math.hypot(a.outputs()["v_d"], a.outputs()["v_q"])
        assert v == pytest.approx(kernel.FW_VOLTAGE_MARGIN * a.outputs()["v_limit_q"], rel=0.02)
    w, i_d, _ = _steady(p, "proportional", i_d_ref=i_d_ref)            # the steady state for that i_d,ref
    assert out[-1, 0] == pytest.approx(w, rel=5e-3)


def test_mode_is_validated():
    with pytest.raises(ParameterError, match="voltage_limit_mode"):
        _params("sideways")


def test_demo_analytic_steady_state_is_the_proportional_limiters_and_says_so():
    from bldc_actuator.demo import steady_speed_analytic

    w, _ = steady_speed_analytic(_params("proportional"), 25.0, 25.0, 0.0, CMD)
    a, out = _run(_params("proportional"), duration=0.5)
    assert w == pytest.approx(out[-1, 0] / a.params.gear.gear_ratio, rel=2e-3)
    with pytest.raises(ValueError, match="drive.voltage_limit_mode"):
        steady_speed_analytic(_params("q_priority"), 25.0, 25.0, 0.0, CMD)
