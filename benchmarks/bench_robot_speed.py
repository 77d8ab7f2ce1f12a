"""Speed of the robot route (issue #26): a 12-joint robot log, 60 s at 1 kHz, diagnosed with ``--mujoco-model``.

The rig: ``config/quadruped12.xml`` on a test stand (its free joint removed, so the trunk is welded to the world,
and the floor removed, so the legs swing free), 12 AK80-9 actuators (``--generator mujoco``, the default: MuJoCo
alone with its own motors and joint friction, ``robot_cases.mujoco_native_run``; ``coupled``: ``CoupledSim``) following a computed-torque
controller on three sines per joint (0.3-2.1 Hz, inside each joint's range), logged like ``robot_cases``
(joint encoders after the gear, 2^16 counts/turn; velocity and current with noise; 1 kHz). The diagnosis is timed
as a subprocess: ``bldc-actuator diagnose LOG --params ak80_9 --mujoco-model STAND.xml --joint-map ...``.

    python benchmarks/bench_robot_speed.py [--seconds 60] [--out DIR] [--profile] [--reuse]

Prints: simulate wall, diagnose wall and CPU time (subprocess, user + sys: the figure that survives a shared
machine's load), the load average before/after, and with ``--profile`` the
stages' split (cProfile of the same call in-process: the cumulative time of the route's stages).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for _p in (ROOT, ROOT / "benchmarks"):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

QUADRUPED = ROOT / "config" / "quadruped12.xml"
PRESET = "ak80_9"
RATE_HZ = 1000.0
KP, KD = 60.0, 3.0
NOISE = {"current": 0.05, "velocity": 0.01}
ENCODER_COUNTS = 2 ** 16
FREQS = ((0.3, 0.9, 1.7), (0.4, 1.1, 2.1), (0.35, 0.7, 1.3))


def stand_mjcf(out: Path) -> Path:
    """The quadruped on a test stand: no free joint (the trunk welded to the world), no floor."""
    text = QUADRUPED.read_text()
    text = re.sub(r"\s*<freejoint[^>]*/>", "", text)
    text = re.sub(r"\s*<geom name=\"floor\"[^>]*/>", "", text)
    text = text.replace('<body name="trunk" pos="0 0 0.34">', '<body name="trunk" pos="0 0 1.0">')
    out.write_text(text)
    return out


def simulate(mjcf: Path, seconds: float, seed: int = 4600, generator: str = "mujoco"):
    import mujoco

    from bldc_actuator.diagnosis.body.inverse import BodyModel
    from bldc_actuator.mujoco import CoupledSim
    from bldc_actuator.mujoco.coupling import load_model
    from bldc_actuator.params import load_preset

    p = load_preset(PRESET)
    model = load_model(str(mjcf))
    joints = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
    rng = np.random.default_rng(seed)
    n = int(round(seconds * RATE_HZ))
    t = np.arange(n) / RATE_HZ
    q_ref, qd_ref, qdd_ref = (np.zeros((n, len(joints))) for _ in range(3))
    ramp = np.where(t < 0.5, 0.5 - 0.5 * np.cos(np.pi * np.clip(t / 0.5, 0, 1)), 1.0)
    for k, j in enumerate(joints):
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        lo, hi = model.jnt_range[jid] if model.jnt_limited[jid] else (-1.0, 1.0)
        c, a = 0.5 * (lo + hi), 0.25 * (hi - lo) / 1.6
        for f, amp in zip(FREQS[k % 3], (a, 0.5 * a, 0.2 * a)):
            w, ph = 2 * np.pi * f * rng.uniform(0.9, 1.1), rng.uniform(0, 2 * np.pi)
            q_ref[:, k] += amp * np.sin(w * t + ph)
            qd_ref[:, k] += amp * w * np.cos(w * t + ph)
            qdd_ref[:, k] -= amp * w * w * np.sin(w * t + ph)
        q_ref[:, k] = c + ramp * q_ref[:, k]   # velocity/acceleration of the ramp left out: the PD takes it
        qd_ref[:, k] *= ramp
        qdd_ref[:, k] *= ramp
    quantum = 2 * np.pi / ENCODER_COUNTS
    if generator == "mujoco":
        from robot_cases import mujoco_native_run

        pos, vel, cur, cmd = mujoco_native_run(mjcf, joints, {j: p for j in joints}, p, q_ref, qd_ref, qdd_ref, rng)
        return (joints, t, np.round(pos / quantum) * quantum, vel + rng.normal(0.0, NOISE["velocity"], vel.shape),
                cur, cmd)
    N = p.gear.gear_ratio
    kt_n = p.motor.torque_constant_q * N
    ff = BodyModel(str(mjcf), joints).torques(q_ref, qd_ref, qdd_ref) + p.motor.rotor_inertia * N * N * qdd_ref
    sim = CoupledSim(model, {j: p for j in joints}, timestep=1.0 / RATE_HZ, warn=False)
    sim.set_pose(dict(zip(joints, q_ref[0])))
    m = sim.model
    jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints]
    qadr, dof = m.jnt_qposadr[jid], m.jnt_dofadr[jid]
    pos, vel, cur, cmd = (np.zeros((n, len(joints))) for _ in range(4))
    h_ns = int(round(1e9 / RATE_HZ))
    for k in range(n):
        q, v = sim.data.qpos[qadr].copy(), sim.data.qvel[dof].copy()
        pos[k], vel[k] = q, v
        cur[k] = sim.actuators.field("i").imag
        i_cmd = (ff[k] + KP * (q_ref[k] - q) + KD * (qd_ref[k] - v)) / kt_n
        cmd[k] = i_cmd
        sim.set_torque_commands(i_cmd * kt_n)
        sim.step_ns(h_ns)
    pos = np.round(pos / quantum) * quantum
    vel = vel + rng.normal(0.0, NOISE["velocity"], vel.shape)
    cur = cur + rng.normal(0.0, NOISE["current"], cur.shape)
    return joints, t, pos, vel, cur, cmd


def write_csv(path: Path, t, pos, vel, cur, cmd) -> Path:
    cols = {"time": t}
    for k in range(pos.shape[1]):
        cols[f"Position{k + 1}"], cols[f"Velocity{k + 1}"] = pos[:, k], vel[:, k]
        cols[f"Cur{k + 1}"], cols[f"CurCmd{k + 1}"] = cur[:, k], cmd[:, k]
    names = list(cols)
    np.savetxt(path, np.column_stack([cols[c] for c in names]), delimiter=",", header=",".join(names),
               comments="", fmt="%.9g")
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--out", default="/tmp/bench_robot_speed")
    ap.add_argument("--generator", choices=("mujoco", "coupled"), default="mujoco",
                    help="the log's truth: mujoco = MuJoCo alone (robot_cases.mujoco_native_run, seconds of wall); "
                         "coupled = CoupledSim (12 actuators at 10 kHz: ~26 s wall per logged second on the shared "
                         "2 cores)")
    ap.add_argument("--reuse", action="store_true", help="reuse the log in --out if it is there")
    ap.add_argument("--profile", action="store_true", help="also profile the diagnosis in-process (cProfile)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    mjcf = stand_mjcf(out / "quadruped12_stand.xml")
    csv = out / f"quadruped_{args.seconds:g}s.csv"
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(mjcf))
    joints = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
    jmap = ",".join(f"joint{k + 1}={j}" for k, j in enumerate(joints))
    if not (args.reuse and csv.exists()):
        t0 = time.perf_counter()
        _, t, pos, vel, cur, cmd = simulate(mjcf, args.seconds, generator=args.generator)
        write_csv(csv, t, pos, vel, cur, cmd)
        print(f"simulate ({len(joints)} joints, {args.seconds:g} s at 1 kHz, {args.generator}): {time.perf_counter() - t0:.1f} s")
    cli = [str(Path(sys.executable).parent / "bldc-actuator")]
    cmdline = cli + ["diagnose", str(csv), "--params", PRESET, "--mujoco-model", str(mjcf), "--joint-map", jmap,
                     "--json", str(out / "robot.json")]
    import resource

    load0 = os.getloadavg()
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}   # this checkout's bldc_actuator, not the venv's install
    r = subprocess.run(cmdline, capture_output=True, text=True, cwd=ROOT, env=env)
    wall = time.perf_counter() - t0
    load1 = os.getloadavg()
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    print(f"diagnose --mujoco-model ({len(joints)} joints, {args.seconds:g} s log): wall {wall:.1f} s (CPU {cpu:.1f} s), exit {r.returncode}; "
          f"load average {load0[0]:.1f} before, {load1[0]:.1f} after; {os.cpu_count()} cores")
    if r.returncode not in (0, 1, 2):
        print(r.stderr[-2000:])
    if args.profile:
        import cProfile
        import pstats

        from bldc_actuator.diagnosis.body.joints import parse_joint_map
        from bldc_actuator.diagnosis.body.robot import diagnose_robot_file
        from bldc_actuator.params import load_preset

        prof = cProfile.Profile()
        prof.enable()
        diagnose_robot_file(csv, load_preset(PRESET), mjcf, joint_map=parse_joint_map(jmap))
        prof.disable()
        st = pstats.Stats(prof)
        st.dump_stats(str(out / "robot.prof"))
        st.sort_stats("cumulative").print_stats(40)
    return 0


if __name__ == "__main__":
    sys.exit(main())
