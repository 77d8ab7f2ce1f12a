"""The actuator under MuJoCo bodies (issue #17): CoupledSim against an independent integration of the same
mechanics, the energy ledger across the two simulators, and the voltage-limited steady state."""

from __future__ import annotations

import dataclasses
import math
import textwrap

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bldc_actuator import kernel
from bldc_actuator.demo import steady_speed_analytic
from bldc_actuator.mujoco import CoupledSim
from bldc_actuator.params import load_preset
from kernel_paths_helper import run_on_kernel_path

M, L, G = 2.0, 0.3, 9.81      # the pendulum: point mass [kg] at L [m] below the hinge, gravity [m/s²]


def pendulum_xml(h: float = 1e-3, gravity: float = G) -> str:
    return f"""<mujoco><option timestep="{h}" gravity="0 0 -{gravity}"/>
    <worldbody><body name="link"><joint name="j" type="hinge" axis="0 1 0"/>
    <inertial pos="0 0 -{L}" mass="{M}" diaginertia="1e-9 1e-9 1e-9"/></body></worldbody></mujoco>"""


def _params(coulomb=0.0298, viscous=1e-4):
    p = load_preset("ak80_9")
    return dataclasses.replace(p, effects=dataclasses.replace(p.effects, coulomb_friction=coulomb),
                               motor=dataclasses.replace(p.motor, viscous_damping=viscous))


def _command(t):
    return 4.0 + 3.0 * math.sin(2.0 * math.pi * 1.5 * t)   # output torque [N·m], below the voltage limit


@pytest.mark.parametrize("coulomb", [0.0, 0.0298])
def test_pendulum_matches_an_independent_integration(coulomb):
    """(J N² + m l²) θ̈ = N K_t i_q - m g l sin θ - b N² θ̇ - τ_c N sign θ̇ with i_q the commanded current, held
    over each 1 ms body step as the coupled run holds it: the coupled link follows to < 1 % over 1 s."""
    p = _params(coulomb)
    sim = CoupledSim(pendulum_xml(), {"j": p})
    h = sim.timestep
    t, q = [0.0], [0.0]
    for _ in range(1000):
        sim.set_torque_command("j", _command(sim.t))
        sim.step(h)
        t.append(sim.t)
        q.append(sim.joint_state("j").position)
        assert not sim.outputs("j")["voltage_saturated"]
    N, b = p.gear.gear_ratio, p.motor.viscous_damping
    J = p.motor.rotor_inertia * N * N + M * L * L

    def rhs(tt, y):
        th, w = y
        tau = (_command(math.floor(tt / h + 1e-9) * h) - M * G * L * math.sin(th) - b * N * N * w
               - coulomb * N * np.sign(w))
        return [w, tau / J]

    ref = solve_ivp(rhs, (0.0, 1.0), [0.0, 0.0], t_eval=np.array(t), max_step=2e-4, rtol=1e-9, atol=1e-11).y[0]
    assert np.ptp(ref) > 1.0                                  # it really swings (about 2-4 rad)
    err = np.max(np.abs(np.array(q) - ref)) / np.max(np.abs(ref))
    assert err < 0.01, err
    # and the body carries the actuator's mechanics: rotor inertia through the gear, drag, dry friction
    dof = sim.model.jnt_dofadr[0]
    assert sim.model.dof_armature[dof] == pytest.approx(p.motor.rotor_inertia * N * N, rel=1e-12)
    assert sim.model.dof_damping[dof] == pytest.approx(b * N * N, rel=1e-12)
    assert sim.model.dof_frictionloss[dof] == pytest.approx(coulomb * N, abs=1e-15)


def test_energy_ledger_closes_with_the_bodys_energy():
    """Electrical in = Joule + Δ magnetic + magnetic work (round-off); magnetic work = the body's Δ kinetic +
    Δ potential + damping and friction losses, up to the coupling's and MuJoCo's integration errors, each
    below 0.3 % of the converted work."""
    sim = CoupledSim(pendulum_xml(), {"j": _params()})
    for k in range(1000):
        sim.set_torque_command("j", _command(sim.t))
        sim.step(1e-3)
    e = sim.energy
    assert e.magnetic_work > 3.0 and e.potential > 1.0 and e.passive_work < -0.2   # real work done and lost
    assert abs(e.electrical_residual) < 1e-9 * e.electrical_in
    assert abs(e.coupling) < 3e-3 * e.magnetic_work, e
    assert abs(e.body_residual) < 3e-3 * e.magnetic_work, e
    closure = e.magnetic_work - (e.kinetic + e.potential - e.passive_work + e.load_work)
    assert abs(closure - e.coupling - e.body_residual) < 1e-9


def test_coupling_error_shrinks_with_the_body_step():
    """The ledger's coupling term is the integration error of the scheme, not a constant offset: it falls at
    least 3x when the body step falls 4x."""
    errs = []
    for h in (1e-3, 2.5e-4):
        sim = CoupledSim(pendulum_xml(h), {"j": _params()})
        n = int(round(1e-3 / h))
        for _ in range(500):
            sim.set_torque_command("j", _command(sim.t))
            sim.step_ns(n * int(round(h * 1e9)))
        errs.append(abs(sim.energy.coupling))
    assert errs[1] < errs[0] / 3.0, errs


def test_voltage_limited_speed_is_the_analytic_steady_state():
    """A flywheel under a 3 N·m load and a current command the voltage circle cannot meet settles at the
    speed of steady_speed_analytic (same load, same temperatures)."""
    p = load_preset("ak80_9")
    xml = """<mujoco><option timestep="0.001" gravity="0 0 0"/><worldbody><body name="disc">
    <joint name="j" type="hinge" axis="0 0 1"/><inertial pos="0 0 0" mass="1" diaginertia="0.002 0.002 0.004"/>
    </body></worldbody></mujoco>"""
    sim = CoupledSim(xml, {"j": p})
    sim.set_current_command("j", 20.0)
    sim.set_load_torque("j", 3.0)
    sim.step(1.0)
    out = sim.outputs("j")
    assert out["voltage_saturated"] and out["i_q"] < 10.0       # limited by the voltage, not the command
    w, _ = steady_speed_analytic(p, out["T_winding"], out["T_housing"], 3.0, 20.0)
    assert out["velocity_out"] == pytest.approx(w, rel=1e-5)


def test_bad_joints_are_named():
    with pytest.raises(ValueError, match="no joint named 'knee'"):
        CoupledSim(pendulum_xml(), {"knee": "ak80_9"})
    ball = """<mujoco><worldbody><body><joint name="b" type="ball"/><geom size="0.1"/></body></worldbody></mujoco>"""
    with pytest.raises(ValueError, match="hinge or slide"):
        CoupledSim(ball, {"b": "ak80_9"})
    sim = CoupledSim(pendulum_xml(), {"j": "ak80_9"})
    with pytest.raises(ValueError, match="multiple of the body step"):
        sim.step(1.5e-3)
    with pytest.raises(ValueError, match="no coupled joint 'x'"):
        sim.set_torque_command("x", 1.0)


PRESCRIBED = textwrap.dedent('''
    import json, sys
    from bldc_actuator.model import Actuator, COMPILED
    from bldc_actuator.params import load_preset
    act = Actuator(load_preset("ak80_9").replace(**{"effects.coulomb_friction": 0.03}))
    rows = []
    for k in range(400):
        act.set_current_command(25.0)
        act.prescribe_motion(30.0 + 0.5 * k, 500.0)        # a speed ramp given from outside
        act.step(1e-3)
        s = act.state
        rows.append([s.i_d, s.i_q, s.T_winding, act.impulse_em, act.magnetic_work])
    json.dump({"compiled": COMPILED, "rows": rows}, sys.stdout)
''')


def _prescribed_run(no_numba: bool) -> dict:
    return run_on_kernel_path(PRESCRIBED, no_numba=no_numba)


@pytest.mark.skipif(not kernel.COMPILED, reason="numba not installed (or disabled): only the Python path exists")
def test_prescribed_motion_is_the_same_on_both_kernel_paths():
    fast, slow = _prescribed_run(False), _prescribed_run(True)
    assert fast["compiled"] and not slow["compiled"]
    a, b = np.array(fast["rows"]), np.array(slow["rows"])
    assert np.abs(a[:, 1]).max() > 5.0                     # current flows, and the voltage limit is reached
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_prescribed_motion_holds_the_rotor_where_told():
    """The kernel's own mechanics are off: a locked rotor (ω = 0) carries the commanded current and its full
    torque; at a held speed the back-EMF is K ω (v_q = R i_q + K ω in steady state)."""
    from bldc_actuator.model import Actuator

    p = load_preset("ak80_9")
    act = Actuator(p)
    act.set_current_command(10.0)
    for _ in range(100):
        act.prescribe_motion(0.0, 0.0)
        act.step(1e-3)
    s = act.state
    assert s.omega == 0.0 and s.i_q == pytest.approx(10.0, rel=1e-6)
    imp0 = act.impulse_em
    act.prescribe_motion(100.0, 0.0)
    act.step(0.05)
    s = act.state
    assert s.omega == pytest.approx(100.0, abs=1e-12)
    R = p.motor.phase_resistance * (1 + p.motor.copper_temperature_coefficient * (s.T_winding - 25.0))
    assert s.v_q == pytest.approx(R * s.i_q + p.motor.torque_constant_q * 100.0
                                  + p.motor.pole_pairs * 100.0 * p.motor.q_inductance * s.i_d, rel=1e-3)
    assert (act.impulse_em - imp0) / 0.05 == pytest.approx(p.motor.torque_constant_q * 10.0, rel=1e-3)


def test_rotor_inertia_moves_with_the_body():
    """A light flywheel (0.001 kg·m²) is dominated by the reflected rotor inertia J N² (0.00486 kg·m²): under a
    constant torque its speed ramps at (τ - τ_c N)/(I + J N²), not at the body's own rate."""
    p = _params(viscous=0.0)
    xml = """<mujoco><option timestep="0.001" gravity="0 0 0"/><worldbody><body name="disc">
    <joint name="j" type="hinge" axis="0 0 1"/><inertial pos="0 0 0" mass="1" diaginertia="0.001 0.001 0.001"/>
    </body></worldbody></mujoco>"""
    sim = CoupledSim(xml, {"j": p})
    sim.set_torque_command("j", 3.0)
    sim.step(0.005)                                      # the current loop has settled
    w0, t0 = sim.joint_state("j").velocity, sim.t
    sim.step(0.02)
    N = p.gear.gear_ratio
    rate = (sim.joint_state("j").velocity - w0) / (sim.t - t0)
    expected = (3.0 - p.effects.coulomb_friction * N) / (0.001 + p.motor.rotor_inertia * N * N)
    assert rate == pytest.approx(expected, rel=5e-3)
    assert not sim.outputs("j")["voltage_saturated"]


def test_leg_example_runs_into_the_drive_limits_and_not_past_them():
    """The shipped leg: the PD asks for more than the drives have; the torque the joints receive reaches the
    current limit's torque (K_t N I_lim) and never exceeds it, and the harder-worked winding heats."""
    from bldc_actuator.mujoco.leg_example import run_leg

    run = run_leg(seconds=1.2)
    for j in ("hip", "knee"):
        assert np.max(np.abs(run.command[j])) > 1.3 * run.limit[j][0]
        peak = np.max(np.abs(run.torque[j]))
        assert 0.98 * run.limit[j][0] < peak < 1.005 * run.limit[j][0]
        assert run.T_winding[j][-1] > run.T_winding[j][0]


def test_plant_protocol_members():
    """The names the node's scheduler steps a plant through, on the coupled simulation: a parameter change
    reaches the body (armature) and the drive (current limit), a latched trip is reported and cleared."""
    sim = CoupledSim(pendulum_xml(), {"j": "ak80_9"})
    assert sim.joints == ["j"] and sim.t_ns == 0
    sim.set_pose({"j": 0.5})
    assert sim.outputs("j")["position_out"] == pytest.approx(0.5)
    sim.step_ns(2_000_000)
    assert sim.t_ns == 2_000_000 and len(sim.all_outputs()) == 1
    p = sim.params("j")
    sim.update_params("j", p.replace(**{"motor.rotor_inertia": 2 * p.motor.rotor_inertia,
                                        "drive.current_limit": 5.0}))
    assert sim.model.dof_armature[0] == pytest.approx(2 * p.motor.rotor_inertia * p.gear.gear_ratio ** 2)
    sim.set_current_command("j", 20.0)
    sim.step(0.01)
    assert sim.outputs("j")["i_q_ref"] == pytest.approx(5.0)
    assert sim.reset_fault("j") is False
    sim.set_torque_commands([1.0])
    sim.step(0.002)
    assert sim.outputs("j")["i_q_ref"] == pytest.approx(1.0 / (p.motor.torque_constant_q * p.gear.gear_ratio))
    with pytest.raises(ValueError, match="1 finite output torques"):
        sim.set_torque_commands([1.0, 2.0])
    with pytest.raises(ValueError, match="load.gravity_torque"):
        sim.update_params("j", p.replace(**{"load.gravity_torque": 1.0}))


def test_asymmetric_and_stribeck_friction_reach_the_body():
    """The friction law beyond the joint's symmetric Coulomb part (asymmetry, a wide Stribeck term) is applied to
    the body: the voltage-limited speed under load is again the analytic steady state with that friction."""
    p = load_preset("ak80_9").replace(**{"effects.friction_asymmetry": 0.01, "effects.stribeck_friction": 0.05,
                                         "effects.stribeck_velocity": 300.0})
    xml = """<mujoco><option timestep="0.001" gravity="0 0 0"/><worldbody><body name="disc">
    <joint name="j" type="hinge" axis="0 0 1"/><inertial pos="0 0 0" mass="1" diaginertia="0.002 0.002 0.004"/>
    </body></worldbody></mujoco>"""
    sim = CoupledSim(xml, {"j": p})
    sim.set_current_command("j", 20.0)
    sim.set_load_torque("j", 3.0)
    sim.step(1.0)
    out = sim.outputs("j")
    w, _ = steady_speed_analytic(p, out["T_winding"], out["T_housing"], 3.0, 20.0)
    w_plain, _ = steady_speed_analytic(load_preset("ak80_9"), out["T_winding"], out["T_housing"], 3.0, 20.0)
    assert abs(w - w_plain) > 5e-3 * w_plain              # the extra friction matters at this speed (0.75 %)
    assert out["velocity_out"] == pytest.approx(w, rel=1e-4)


def test_body_state_names_every_coordinate():
    from bldc_actuator.params import config_dir

    sim = CoupledSim(config_dir() / "quadruped12.xml", {"FL_knee": "ak80_9"})
    labels = sim.body_state_labels()
    assert len(labels) == sim.model.nq + sim.model.nv == len(sim.body_state())
    assert labels[:3] == ("qpos.base.x", "qpos.base.y", "qpos.base.z")
    k = labels.index("qpos.FL_knee")
    sim.set_pose({"FL_knee": -1.2})
    assert sim.body_state()[k] == -1.2
