"""Rigid reference trajectories: the scenarios whose outputs the kernel before the transmission (commit d770331)
wrote to ``test/data/rigid_reference_d770331.npz`` (``python test/rigid_reference.py OUT.npz``, once per path:
compiled and ``BLDC_ACTUATOR_NO_NUMBA=1``; the two files merged into one with the keys ``compiled:<run>`` /
``python:<run>`` and ``meta`` = numba version, numpy version, machine, commit). test_transmission.py re-runs them
with today's kernel: a rigid transmission (``gear.transmission_stiffness = 0``) must give the same numbers, bit for
bit."""
import math
import sys
import numpy as np
from bldc_actuator.model import Actuator, BatchActuator, COMPILED
from bldc_actuator.params import load_preset, ActuatorParams

def scenarios():
    base = load_preset("ak80_9")
    fric = base.replace(**{"effects.coulomb_friction": 0.03, "effects.friction_asymmetry": 0.005,
        "effects.stribeck_friction": 0.02, "effects.stribeck_velocity": 2.0, "effects.cogging_order": 42,
        "effects.cogging_cos": (0.01, 0.002), "effects.cogging_sin": (0.004, 0.0), "load.gravity_torque": 1.5,
        "load.spring_stiffness": 0.3, "motor.resistance_temperature_enabled": True})
    return {"default": ActuatorParams(), "ak80_9": base, "effects": fric}

def run(p, kind):
    act = Actuator(p)
    rows = []
    for k in range(1500):
        t = k * 1e-3
        if kind == "chirp":
            act.set_current_command(20.0 * math.sin(2 * math.pi * (0.5 + 6.0 * t) * t))
        else:
            act.set_torque_command(3.0 if (k // 200) % 2 == 0 else -2.0)
            act.set_load_torque(0.5 * math.sin(3 * t))
        act.step(1e-3 if k % 7 else 3.7e-4)
        s = act.state
        rows.append([s.t_ns, s.i_d, s.i_q, s.omega, s.theta, s.T_winding, s.T_housing, s.v_d, s.v_q])
    e = act.energy
    o = act.outputs()
    rows.append([e.electrical_in, e.joule, e.friction, e.load, e.viscous, e.kinetic, o["position_out"],
                 o["velocity_out"], o["effort_out"]])
    rows = np.array(rows, dtype=float)
    return np.vstack([rows[:-1][::25], rows[-2:]])   # every 25th step, the last step and the energies

def all_runs():
    out = {}
    for name, p in scenarios().items():
        for kind in ("chirp", "steps"):
            out[f"{name}/{kind}"] = run(p, kind)
    b = BatchActuator(list(scenarios().values()))
    b.set_current_command([4.0, -6.0, 8.0])
    b.step(0.25)
    o = b.outputs()
    out["batch"] = np.array([o["i_q"], o["omega"], o["theta"], o["T_winding"], o["position_out"]])
    return out

if __name__ == "__main__":
    runs = all_runs()
    tag = "compiled" if COMPILED else "python"
    np.savez_compressed(sys.argv[1], **{f"{tag}:{k}": v for k, v in runs.items()})
    print(tag, len(runs))
