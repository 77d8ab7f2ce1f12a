"""The shipped example: a two-link leg (config/two_link_leg.xml) under a 4 kg trunk, hip and knee on two
presets, squatting and pushing up under a joint-space PD controller whose commands run into the drives' limits.

    python -m bldc_actuator.mujoco.leg_example --plot leg.png [--seconds 6] [--hip tmotor_u8] [--knee ak80_9]

Prints per joint the peak torque against its limit, the time at the limit and the final winding temperature, and
plots joint angles, torques (command, applied, the effective limit) and winding temperatures.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np

from ..params import config_dir
from .coupling import CoupledSim

#: (hip, knee) joint targets [rad]: crouched and extended; the PD switches between them every half period
CROUCH, EXTEND = (0.9, -1.8), (0.25, -0.5)
KP, KD = 150.0, 4.0                 # PD gains [N·m/rad, N·m·s/rad], deliberately beyond the drives' torque


@dataclass(frozen=True)
class LegRun:
    t: np.ndarray                   #: [s]
    angle: dict                     #: joint -> [rad]
    target: dict                    #: joint -> [rad]
    command: dict                   #: joint -> commanded output torque [N·m]
    torque: dict                    #: joint -> applied (mean over each body step) [N·m]
    limit: dict                     #: joint -> the drive's effective current limit as output torque [N·m]
    T_winding: dict                 #: joint -> [°C]
    trunk_z: np.ndarray             #: trunk displacement along its slide [m] (0 = the MJCF pose)


def run_leg(seconds: float = 6.0, hip: str = "tmotor_u8", knee: str = "ak80_9", period: float = 1.0) -> LegRun:
    sim = CoupledSim(config_dir() / "two_link_leg.xml", {"hip": hip, "knee": knee})
    import mujoco

    m, d = sim.model, sim.data
    ids = {j: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in ("hip", "knee")}
    qadr = {j: m.jnt_qposadr[i] for j, i in ids.items()}
    dadr = {j: m.jnt_dofadr[i] for j, i in ids.items()}
    sim.set_pose(dict(zip(("hip", "knee"), CROUCH)))
    Kt_N = {j: sim.params(j).motor.torque_constant_q * sim.params(j).gear.gear_ratio for j in sim.joints}
    rec = {key: {j: [] for j in ("hip", "knee")} for key in ("angle", "target", "command", "torque", "limit", "T")}
    t_rec, z_rec = [], []
    for _ in range(int(round(seconds / sim.timestep))):
        phase = (sim.t % period) < 0.5 * period
        target = dict(zip(("hip", "knee"), CROUCH if phase else EXTEND))
        cmd = {}
        for j in ("hip", "knee"):
            cmd[j] = KP * (target[j] - d.qpos[qadr[j]]) - KD * d.qvel[dadr[j]]
            sim.set_torque_command(j, float(cmd[j]))
        sim.step(sim.timestep)
        t_rec.append(sim.t)
        z_rec.append(float(d.qpos[0]))
        for j in ("hip", "knee"):
            js = sim.joint_state(j)
            rec["angle"][j].append(js.position)
            rec["target"][j].append(target[j])
            rec["command"][j].append(cmd[j])
            rec["torque"][j].append(js.effort)
            rec["limit"][j].append(js.outputs["current_limit_effective"] * Kt_N[j])
            rec["T"][j].append(js.outputs["T_winding"])
    arr = {key: {j: np.array(v) for j, v in val.items()} for key, val in rec.items()}
    return LegRun(t=np.array(t_rec), angle=arr["angle"], target=arr["target"], command=arr["command"],
                  torque=arr["torque"], limit=arr["limit"], T_winding=arr["T"], trunk_z=np.array(z_rec))


def summary(run: LegRun) -> str:
    lines = []
    for j in ("hip", "knee"):
        at_limit = np.mean(np.abs(run.torque[j]) >= 0.98 * run.limit[j])
        lines.append(f"{j}: peak |torque| {np.max(np.abs(run.torque[j])):.2f} N*m (limit {run.limit[j][0]:.2f}), "
                     f"at the limit {100 * at_limit:.0f} % of the time, winding {run.T_winding[j][0]:.1f} -> "
                     f"{run.T_winding[j][-1]:.1f} degC")
    lines.append(f"trunk moved {run.trunk_z.min():+.3f} .. {run.trunk_z.max():+.3f} m along its slide")
    return "\n".join(lines)


def plot(run: LegRun, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for j, c in (("hip", "C0"), ("knee", "C1")):
        ax[0].plot(run.t, run.angle[j], c, label=f"{j}")
        ax[0].plot(run.t, run.target[j], c + ":", lw=0.8)
        ax[1].plot(run.t, np.clip(run.command[j], -1.5 * run.limit[j], 1.5 * run.limit[j]), c + ":", lw=0.8)
        ax[1].plot(run.t, run.torque[j], c, label=f"{j} applied")
        ax[1].plot(run.t, run.limit[j], c + "--", lw=0.8)
        ax[1].plot(run.t, -run.limit[j], c + "--", lw=0.8)
        ax[2].plot(run.t, run.T_winding[j], c, label=j)
    ax[0].set_ylabel("joint angle [rad]\n(dotted: PD target)")
    ax[1].set_ylabel("torque [N·m]\n(dotted: command, dashed: limit)")
    ax[2].set_ylabel("winding [°C]")
    ax[2].set_xlabel("t [s]")
    for a in ax:
        a.legend(fontsize=8, loc="upper right")
    fig.suptitle("two-link leg (config/two_link_leg.xml), MuJoCo bodies + bldc_actuator drives")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--hip", default="tmotor_u8", help="preset or parameter file of the hip actuator")
    ap.add_argument("--knee", default="ak80_9", help="preset or parameter file of the knee actuator")
    ap.add_argument("--plot", help="write the figure here (PNG)")
    args = ap.parse_args(argv)
    run = run_leg(args.seconds, args.hip, args.knee)
    print(summary(run))
    if args.plot:
        plot(run, args.plot)
        print(f"leg_example: wrote {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
