"""The fresh concealed set's truth generator (benchmarks/concealed/fresh_sim.py, issue #24): it is written without
bldc_actuator's physics, and its plant and drive obey the physics they claim (analytic steady states, the energy
balance, the integrator against scipy's solve_ivp, the saturation and gear-friction laws). Cheap: short runs."""

from __future__ import annotations

import ast
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.concealed import fresh_sim as S  # noqa: E402

PHYSICS = ("kernel", "model", "effects", "frames", "abc_model", "current_loop_stability", "mujoco", "plant")


def _imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            out.add(("." * node.level) + (node.module or ""))
            out |= {("." * node.level) + (node.module or "") + "." + a.name for a in node.names}
    return out


def test_generator_imports_nothing_of_bldc_actuator():
    sim = _imports(REPO / "benchmarks" / "concealed" / "fresh_sim.py")
    assert not [m for m in sim if "bldc_actuator" in m], sim
    assert sim <= {"__future__", "__future__.annotations", "math", "time", "typing", "typing.Callable", "numpy"}, sim
    mot = _imports(REPO / "benchmarks" / "concealed" / "fresh_motulator.py")
    assert not [m for m in mot if "bldc_actuator" in m], mot
    runner = _imports(REPO / "benchmarks" / "concealed" / "thirdparty_sim.py")     # what the motulator case runs
    assert not [m for m in runner if "bldc_actuator" in m], runner
    cases = _imports(REPO / "benchmarks" / "concealed" / "fresh_cases.py")
    assert not [m for m in cases if "bldc_actuator" in m and any(p in m for p in PHYSICS)], cases
    # at run time too: simulating a case loads no bldc_actuator module
    code = ("import sys; sys.path.insert(0, %r)\n"
            "from benchmarks.concealed import fresh_sim as S, fresh_cases as F\n"
            "c = F.get_case('fr_null_speed'); S.simulate(F.simulation_spec(c), 0.01, 1)\n"
            "print(sorted(m for m in sys.modules if m.startswith('bldc_actuator')))" % str(REPO))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout


MOTOR = {"R": 0.36, "L": 6.0e-4, "K": 0.06, "p": 4, "J": 1.2e-5, "b": 1.0e-5}


def _voltage_spec(duty: float, b: float) -> dict:
    return {"motor": dict(MOTOR, b=b), "load": {"J": 2.0e-4},
            "drive": {"mode": "voltage", "f_c": 1000.0, "v_bus": 12.0, "i_max": 10.0, "outer": "voltage",
                      "encoder_counts": 0, "substeps": 2, "nominal": {k: MOTOR[k] for k in ("R", "L", "K")}},
            "excitation": {"kind": "multisine", "amps": [0.0], "freqs": [1.0], "offset": duty}}


def test_voltage_mode_steady_state_is_the_dc_motor_law():
    """Constant duty on a voltage-mode motor with viscous friction: ω = K v / (K² + R b), i = b ω / K."""
    duty, b = 0.5, 2.0e-2                 # R b = 2 K²: the resistance sets two thirds of the speed
    run = S.simulate(_voltage_spec(duty, b), 2.0, 1)
    v = duty * 12.0
    K, R = MOTOR["K"], MOTOR["R"]
    w_ss = K * v / (K * K + R * b)
    assert run["w"][-1] == pytest.approx(w_ss, rel=1e-3)
    assert run["i_q"][-1] == pytest.approx(b * w_ss / K, rel=1e-3)


def test_current_drive_reaches_its_command_and_the_viscous_speed():
    """A current step through the discrete PI loop (ADC off): i_q settles on its command, ω on K i / b."""
    b = 0.01
    spec = {"motor": dict(MOTOR, b=b), "load": {"J": 1.0e-3},
            "drive": {"f_c": 5000.0, "f_outer": 1000.0, "v_bus": 24.0, "i_max": 10.0, "bandwidth_hz": 500.0,
                      "outer": "current", "encoder_counts": 16384, "advance": 1.5, "velocity_estimator": "lpf",
                      "estimator_hz": 200.0, "substeps": 1, "nominal": {k: MOTOR[k] for k in ("R", "L", "K")}},
            "excitation": {"kind": "steps", "levels": [4.0], "dwell": 10.0}}
    run = S.simulate(spec, 1.2, 3)
    i_ref = run["i_q_ref"][-1]
    assert abs(i_ref) == 4.0
    assert run["i_q"][-1] == pytest.approx(i_ref, rel=5e-3)
    assert abs(run["i_d"][-1]) < 0.05
    assert run["w"][-1] == pytest.approx(MOTOR["K"] * i_ref / b, rel=1e-2)


def _pmsm_plant(**motor) -> S.Plant:
    return S.Plant({"motor": dict(MOTOR, **motor), "load": {"J": 1.0e-4, "b": 1.0e-3},
                    "drive": {"mode": "current"}})


def test_rk4_plant_matches_solve_ivp_and_balances_energy():
    """A held stationary-frame voltage for 20 ms: the fixed-step RK4 agrees with scipy's solve_ivp, and the
    electrical energy in equals copper + friction losses + kinetic + magnetic energy gained."""
    from scipy.integrate import solve_ivp

    pl = _pmsm_plant(tau_c=0.0)
    u = (3.0, 1.0)
    x0 = [0.5, 1.0, 5.0, 0.2, 25.0, 25.0]
    h, n = 1.0e-5, 2000
    xs = [x0]
    for k in range(n):
        xs.append(S.rk4(pl.deriv, xs[-1], k * h, h, u))
    xs = np.array(xs)
    ref = solve_ivp(lambda t, x: pl.deriv(list(x), t, u), (0.0, n * h), x0, rtol=1e-10, atol=1e-12,
                    method="DOP853")
    assert np.allclose(xs[-1, :4], ref.y[:4, -1], rtol=1e-6, atol=1e-8)
    t = np.arange(n + 1) * h
    i_d, i_q, w, th = xs[:, 0], xs[:, 1], xs[:, 2], xs[:, 3]
    the = pl.p * th
    v_d = np.cos(the) * u[0] + np.sin(the) * u[1]
    v_q = -np.sin(the) * u[0] + np.cos(the) * u[1]
    e_in = np.trapezoid(v_d * i_d + v_q * i_q, t)
    J = pl.J_rigid
    b_tot = pl.bm + pl.bo
    losses = np.trapezoid(pl.R0 * (i_d ** 2 + i_q ** 2) + b_tot * w ** 2, t)
    stored = 0.5 * J * (w[-1] ** 2 - w[0] ** 2) + 0.5 * pl.L * ((i_d[-1] ** 2 + i_q[-1] ** 2) - (i_d[0] ** 2 + i_q[0] ** 2))
    assert e_in == pytest.approx(losses + stored, rel=1e-4)


def test_saturation_and_gear_friction_laws():
    pl = _pmsm_plant(a_sat=0.15, i_sat=10.0)
    assert pl.K(10.0, 25.0) == pytest.approx(0.06 * 0.85)
    assert pl.K(5.0, 25.0) == pytest.approx(0.06 * (1 - 0.15 * 0.5 ** 1.5))
    # the gear friction at |τ_e| >= τ_ref is c1 |τ_e| against the motion; at small torque c0 |τ_e|
    g = S.Plant({"motor": dict(MOTOR, b=0.0), "gear": {"ratio": 10.0, "c0": 0.27, "c1": 0.43, "tau_ref": 0.1},
                 "load": {"J": 1.0e-3}, "drive": {"mode": "current"}})
    for i_q, c in ((5.0, 0.43), (0.01, 0.27 + 0.16 * 0.0006 / 0.1)):
        x = [0.0, i_q, 50.0, 0.0, 25.0, 25.0]
        tau_e = 0.06 * i_q
        acc = g.deriv(x, 0.0, (0.0, 0.0))[2]
        assert acc * g.J_rigid == pytest.approx(tau_e - c * tau_e * math.tanh(50.0 / 0.05), rel=1e-6)


def test_backlash_dead_zone_transmits_nothing_inside_the_gap():
    gap = math.radians(1.0)
    pl = S.Plant({"motor": dict(MOTOR, b=0.0), "gear": {"ratio": 9.0, "stiffness": 300.0, "damping": 0.3,
                                                         "backlash": gap},
                  "load": {"J": 5.0e-3}, "drive": {"mode": "current"}})
    inside = [0.0, 0.0, 0.0, 9.0 * 0.4 * gap, 25.0, 25.0, 0.0, 0.0]
    assert pl.deriv(inside, 0.0, (0.0, 0.0))[6] == 0.0
    outside = [0.0, 0.0, 0.0, 9.0 * 1.5 * gap, 25.0, 25.0, 0.0, 0.0]
    assert pl.deriv(outside, 0.0, (0.0, 0.0))[6] * 5.0e-3 == pytest.approx(300.0 * gap)


def test_pll_tracks_a_ramp_without_lag():
    est = S.VelocityEstimator("pll", 1e-3, 30.0)
    lsb = 2 * math.pi / 4096
    for k in range(3000):
        w = est.update(S.quantize(20.0 * k * 1e-3, lsb))
    assert w == pytest.approx(20.0, rel=2e-2)
