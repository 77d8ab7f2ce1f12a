#!/usr/bin/env python3
"""Physics speed side by side with peers, all figures from ONE run: wall seconds per simulated second for one
actuator with a 10 kHz current loop (100 µs physics step).

    bash benchmarks/peers/setup.sh                      # separate venv .venv-peers (peers are never dependencies)
    .venv-peers/bin/python benchmarks/bench_physics_peers.py [--seconds 1] [--json out.json]

Scenarios (same motor numbers where the peer takes them: ak80_9 q-axis R, L, K_t, J; a 5 Hz sinusoidal torque
command; thermal model and friction on where the peer has them):

* bldc_actuator ``Actuator`` (compiled kernel; d/q PI current loop at 10 kHz, exact-interval electrical and
  thermal solution, stick/slip friction, R(T)): ``step(1e-4)`` per call, and ``step(1e-3)`` (ten ticks per
  call, as the node steps); ``BatchActuator`` N = 12 and 64 (per actuator);
* MuJoCo ``<dcmotor>`` (C): resistance, motorconst, inductance (electrical state), thermal (one node, R(T)),
  LuGre friction, ``input="ff"`` through its torque controller with a voltage clamp; ``mj_step`` per 100 µs and
  ``mj_step(nstep=10)``. A DC-motor (one-phase equivalent) model with an algebraic torque-to-voltage
  controller, not a d/q PI loop;
* gym-electric-motor ``Cont-CC-PMSM-v0`` (its own PMSM, converter and ODE solver; tau = 100 µs; no thermal);
* motulator ``drive`` (SynchronousMachine with the ak80_9 numbers, CurrentVectorControl at T_s = 100 µs,
  its own continuous-time solver; no thermal, no friction).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def best(fn, repeat=3):
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out)


def ours(T):
    from bldc_actuator.model import COMPILED, Actuator, BatchActuator
    from bldc_actuator.params import load_preset

    p = load_preset("ak80_9").replace(**{"motor.resistance_temperature_enabled": True})
    Actuator(p).step(1e-3)   # compile / load the cached kernel first

    # the actuators are built before the clock starts (as MuJoCo's model is compiled before it)
    def single(dt):
        acts = iter([Actuator(p) for _ in range(3)])

        def run():
            a = next(acts)
            for k in range(int(round(T / dt))):
                a.set_torque_command(0.2 * math.sin(2 * math.pi * 5 * k * dt))
                a.step(dt)
        return best(run) / T

    def batch(n):
        batches = iter([BatchActuator([p] * n) for _ in range(2)])

        def run():
            b = next(batches)
            for k in range(int(round(T / 1e-3))):
                b.set_torque_command(0.2 * math.sin(2 * math.pi * 5 * k * 1e-3))
                b.step(1e-3)
        return best(run, 2) / T / n
    tag = "compiled" if COMPILED else "pure Python"
    return {f"bldc_actuator Actuator ({tag}), step(100 us)": single(1e-4),
            f"bldc_actuator Actuator ({tag}), step(1 ms) = 10 ticks per call": single(1e-3),
            f"bldc_actuator BatchActuator N=12 ({tag}), per actuator": batch(12),
            f"bldc_actuator BatchActuator N=64 ({tag}), per actuator": batch(64)}


def mujoco_dcmotor(T):
    import mujoco

    from bldc_actuator.frames import voltage_limit_q
    from bldc_actuator.params import load_preset

    p = load_preset("ak80_9")
    m_, th = p.motor, p.thermal
    xml = f"""<mujoco><option timestep="1e-4" gravity="0 0 0"/>
    <worldbody><body><joint name="j" type="hinge" armature="{m_.rotor_inertia}" damping="{m_.viscous_damping}"/>
    <geom type="sphere" size="0.001" mass="1e-6"/></body></worldbody>
    <actuator><dcmotor joint="j" resistance="{m_.phase_resistance}" motorconst="{m_.torque_constant_q} {m_.torque_constant_q}"
     inductance="{m_.q_inductance} 0" thermal="{th.winding_to_housing_resistance + th.housing_to_ambient_resistance}
     {th.winding_heat_capacity + th.housing_heat_capacity} 0 0.00393 25 25" lugre="100 0.1 0.03 0.04 2.0"
     input="ff" controller="0 0 0 0 0 {voltage_limit_q(p.drive.bus_voltage, m_.winding)}"/></actuator></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)

    def per_step():
        mujoco.mj_resetData(model, data)
        for k in range(int(round(T / 1e-4))):
            data.ctrl[0] = 0.2 * math.sin(2 * math.pi * 5 * k * 1e-4)
            mujoco.mj_step(model, data)

    def ten():
        mujoco.mj_resetData(model, data)
        for k in range(int(round(T / 1e-3))):
            data.ctrl[0] = 0.2 * math.sin(2 * math.pi * 5 * k * 1e-3)
            mujoco.mj_step(model, data, nstep=10)
    return {f"MuJoCo {mujoco.__version__} <dcmotor> (C), mj_step per 100 us": best(per_step) / T,
            f"MuJoCo {mujoco.__version__} <dcmotor> (C), mj_step(nstep=10)": best(ten) / T}


def gym_electric_motor(T):
    import gym_electric_motor as gem

    env = gem.make("Cont-CC-PMSM-v0", visualization=None)
    tau = env.unwrapped.physical_system.tau
    n = int(round(min(T, 0.3) / tau))

    def run():
        env.reset()
        for _ in range(n):
            out = env.step(np.array([0.0, 0.3, 0.0]))
            if out[2] or (len(out) > 4 and out[3]):
                env.reset()
    return {f"gym-electric-motor {getattr(gem, '__version__', '')} Cont-CC-PMSM-v0 (tau {tau * 1e6:g} us)":
            best(run, 2) / (n * tau)}


def motulator_drive(T):
    from motulator.drive import model, utils
    import motulator.drive.control.sm as sm

    from bldc_actuator.params import load_preset

    p = load_preset("ak80_9").motor
    # motulator's psi_f is the amplitude-invariant flux linkage: K_t_q = sqrt(3/2) p psi_f
    par = utils.SynchronousMachinePars(n_p=p.pole_pairs, R_s=p.phase_resistance, L_d=p.q_inductance,
                                       L_q=p.q_inductance, psi_f=p.torque_constant_q / (math.sqrt(1.5) * p.pole_pairs))
    t_sim = min(T, 0.2)

    def run():
        mdl = model.Drive(model.VoltageSourceConverter(u_dc=24.0), model.SynchronousMachine(par),
                          model.StiffMechanicalSystem(J=p.rotor_inertia))
        ctrl = sm.CurrentVectorControl(par, sm.CurrentReferenceCfg(par, max_i_s=20.0, nom_w_m=200.0), T_s=1e-4,
                                       sensorless=False)
        ctrl.ref.tau_M = lambda t: 0.2 * math.sin(2 * math.pi * 5 * t)
        model.Simulation(mdl, ctrl).simulate(t_stop=t_sim)
    return {"motulator drive (SynchronousMachine + CurrentVectorControl, T_s 100 us)": best(run, 2) / t_sim}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--json")
    args = ap.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f} (2 cores); best of 3 (2 for the slow peers)")
    rows: dict[str, float] = {}
    for fn in (ours, mujoco_dcmotor, gym_electric_motor, motulator_drive):
        try:
            rows.update(fn(args.seconds))
        except Exception as exc:  # noqa: BLE001 - a peer that is missing or changed its API: say so
            rows[f"{fn.__name__}: not run ({type(exc).__name__}: {exc})"] = float("nan")
    ref = next(v for k, v in rows.items() if "dcmotor" in k and "nstep" in k) if any("nstep" in k for k in rows) else None
    print("\n| s per simulated second, one actuator, 10 kHz | value | vs MuJoCo <dcmotor> nstep=10 |")
    print("|---|---|---|")
    for k, v in rows.items():
        print(f"| {k} | {v:.4g} | {v / ref:.2f}x |" if ref and math.isfinite(v) else f"| {k} | {v:.4g} | – |")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
