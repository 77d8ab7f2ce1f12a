"""Speed of the coupled simulation (issue #17): a 12-joint quadruped (config/quadruped12.xml) with an actuator
on every joint, 1 kHz body step, 10 kHz current loop, standing under a joint-space PD controller at 1 kHz, in
one process. Prints the real-time factor of the coupled run and, for scale, of MuJoCo alone with the same PD
torques applied directly (no actuator model).

    python benchmarks/bench_mujoco.py [--seconds 5] [--preset ak80_9]
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

from bldc_actuator.kernel import COMPILED, warm_up
from bldc_actuator.mujoco import CoupledSim
from bldc_actuator.params import config_dir

LEGS = ("FL", "FR", "RL", "RR")
JOINTS = [f"{leg}_{j}" for leg in LEGS for j in ("abduct", "hip", "knee")]
STAND = {"abduct": 0.0, "hip": 0.8, "knee": -1.6}     # joint angles [rad] of the standing pose
KP, KD = 60.0, 1.5                                     # PD gains [N·m/rad, N·m·s/rad]


def _pose(model, data) -> None:
    for name in JOINTS:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        data.qpos[model.jnt_qposadr[jid]] = STAND[name.split("_")[1]]
    mujoco.mj_forward(model, data)


def run_coupled(seconds: float, preset: str) -> tuple[float, float]:
    sim = CoupledSim(config_dir() / "quadruped12.xml", {j: preset for j in JOINTS})
    sim.set_pose({j: STAND[j.split("_")[1]] for j in JOINTS})
    target = np.array([STAND[j.split("_")[1]] for j in JOINTS])
    qadr = [sim.model.jnt_qposadr[mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_JOINT, j)] for j in JOINTS]
    dadr = [sim.model.jnt_dofadr[mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_JOINT, j)] for j in JOINTS]
    n = int(round(seconds / sim.timestep))
    t0 = time.perf_counter()
    for _ in range(n):
        sim.set_torque_commands(KP * (target - sim.data.qpos[qadr]) - KD * sim.data.qvel[dadr])
        sim.step(sim.timestep)
    wall = time.perf_counter() - t0
    return seconds / wall, float(sim.data.qpos[2])


def run_bare(seconds: float) -> float:
    model = mujoco.MjModel.from_xml_path(str(config_dir() / "quadruped12.xml"))
    data = mujoco.MjData(model)
    _pose(model, data)
    target = np.array([STAND[j.split("_")[1]] for j in JOINTS])
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in JOINTS]
    qadr, dadr = model.jnt_qposadr[ids], model.jnt_dofadr[ids]
    n = int(round(seconds / model.opt.timestep))
    t0 = time.perf_counter()
    for _ in range(n):
        data.qfrc_applied[dadr] = KP * (target - data.qpos[qadr]) - KD * data.qvel[dadr]
        mujoco.mj_step(model, data)
    return seconds / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="simulated time per run [s]")
    ap.add_argument("--preset", default="ak80_9", help="actuator preset on every joint")
    args = ap.parse_args()
    warm_up()
    print(f"kernel compiled: {COMPILED}; mujoco {mujoco.__version__}; {len(JOINTS)} joints, "
          f"{args.seconds:g} s simulated, 1 kHz body / 10 kHz current loop ({args.preset})")
    rt, z = run_coupled(args.seconds, args.preset)
    print(f"coupled (MuJoCo + 12 actuators + PD): {rt:.1f}x real time; trunk height at the end {z:.3f} m")
    print(f"MuJoCo alone (same PD torques, no actuator model): {run_bare(args.seconds):.1f}x real time")


if __name__ == "__main__":
    main()
