#!/usr/bin/env python3
"""Speed of the physics core: wall time per simulated second at 10 kHz physics (current loop 10 kHz).

Prints figures (no assertions). Reference points on this machine kind, from the issue: motulator ≈ 6.5 s,
gym-electric-motor ≈ 2 s, MuJoCo's C <dcmotor> 0.047 s at 0.1 ms steps, a plain-Python prototype 0.037 s.

    python benchmarks/bench_model.py [--seconds 2] [--batch 1 10 100 1000]
"""

import argparse
import os
import time

import numpy as np

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from bldc_actuator import profiles  # noqa: E402
from bldc_actuator.model import Actuator, BatchActuator  # noqa: E402
from bldc_actuator.params import ActuatorParams, load_preset  # noqa: E402


def best_of(fn, repeat=3):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=1.0, help="simulated seconds per measurement")
    ap.add_argument("--batch", type=int, nargs="*", default=[1, 10, 100, 1000])
    args = ap.parse_args()
    T = args.seconds
    print(f"load average before: {os.getloadavg()[0]:.2f} (2 cores; figures are best of 3)")
    base = ActuatorParams()
    rich = load_preset("ak80_9").replace(**{
        "effects.coulomb_friction": 0.01, "effects.stribeck_friction": 0.005, "effects.cogging_order": 84,
        "effects.cogging_cos": (0.003,), "effects.cogging_sin": (0.001,), "load.gravity_torque": 1.0})

    for name, p in (("defaults", base), ("ak80_9 + friction + cogging + gravity", rich)):
        def loop():
            act = Actuator(p)
            act.set_current_command(2.0)
            for _ in range(int(round(T * 1e4))):
                act.step(1e-4)

        def run():
            Actuator(p).run(profiles.chirp(5.0, 1.0, 50.0, duration=T, rate=1000.0))

        t_loop = best_of(loop) / T
        t_run = best_of(run) / T
        print(f"Actuator [{name}]: step(100 us) loop {t_loop:.4f} s per simulated s "
              f"({t_loop / 1e4 * 1e6:.2f} us/step); run(chirp, 1 kHz outputs) {t_run:.4f} s per simulated s")

    for n in args.batch:
        plist = [base.replace(**{"motor.torque_constant_q": 0.08 + 0.02 * k / max(n, 1)}) for k in range(n)]

        def batch():
            b = BatchActuator(plist)
            b.set_current_command(np.full(n, 2.0))
            for _ in range(int(round(T * 1e4))):
                b.step(1e-4)

        t_b = best_of(batch, repeat=2) / T
        print(f"BatchActuator N={n:5d}: {t_b:.4f} s per simulated s for all, {t_b / n:.6f} s per actuator-second")


if __name__ == "__main__":
    main()
