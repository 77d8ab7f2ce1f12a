#!/usr/bin/env python3
"""Speed of the physics core: wall time per simulated second at a 10 kHz current loop (physics interval
100 µs), for the compiled kernel (numba) and the pure-Python path of the same source, plus the kernel's
first-start (cold numba cache) and warm-start times. Prints figures (no assertions).

    python benchmarks/bench_model.py [--seconds 1] [--batch 1 4 12 64] [--no-python]

Each figure is the best of 3. Peers (MuJoCo's <dcmotor>, motulator, gym-electric-motor) are timed side by side
in one run by ``benchmarks/bench_physics_peers.py`` (see docs/benchmarks-physics.md) when that script exists.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from bldc_actuator.model import COMPILED, Actuator, BatchActuator  # noqa: E402
from bldc_actuator.params import ActuatorParams, load_preset  # noqa: E402

RICH = {"effects.coulomb_friction": 0.01, "effects.stribeck_friction": 0.005, "effects.cogging_order": 84,
        "effects.cogging_cos": (0.003,), "effects.cogging_sin": (0.001,), "load.gravity_torque": 1.0,
        "motor.resistance_temperature_enabled": True}


def best_of(make, run, repeat=3):
    """Best wall time of ``run(make())`` over ``repeat`` tries; building the actuator is not timed."""
    times = []
    for _ in range(repeat):
        obj = make()
        t0 = time.perf_counter()
        run(obj)
        times.append(time.perf_counter() - t0)
    return min(times)


def single(p, T, dt):
    def make():
        act = Actuator(p)
        act.set_current_command(2.0)
        return act

    def run(act):
        for _ in range(int(round(T / dt))):
            act.step(dt)
    return best_of(make, run) / T


def batch(plist, T, dt):
    n = len(plist)

    def make():
        b = BatchActuator(plist)
        b.set_current_command(np.full(n, 2.0))
        return b

    def run(b):
        for _ in range(int(round(T / dt))):
            b.step(dt)
    return best_of(make, run, repeat=2) / T


def figures(T, batches):
    base, rich = ActuatorParams(), load_preset("ak80_9").replace(**RICH)
    Actuator(base).step(1e-3)   # compile / load the kernel before timing
    out = {}
    for name, p in (("defaults", base), ("ak80_9+friction+cogging+gravity+R(T)", rich)):
        out[f"single {name} step(100us)"] = single(p, T, 1e-4)
        out[f"single {name} step(1ms)"] = single(p, T, 1e-3)
    for n in batches:
        plist = [rich.replace(**{"motor.torque_constant_q": 0.07 + 0.01 * k / max(n, 1)}) for k in range(n)]
        out[f"batch N={n} step(1ms), per actuator"] = batch(plist, T, 1e-3) / n
    return out


def start_times():
    """Import + first step in a fresh process: cold (empty numba cache dir) and warm (cache filled)."""
    code = ("import time; t=time.perf_counter(); from bldc_actuator.model import Actuator, warm_up; "
            "w=warm_up(); a=Actuator(); a.step(1e-3); print(time.perf_counter()-t)")
    env = dict(os.environ)
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    with tempfile.TemporaryDirectory() as cache:
        env["NUMBA_CACHE_DIR"] = cache
        run = lambda: float(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,  # noqa: E731
                                           text=True, check=True).stdout)
        cold = run()
        warm = min(run() for _ in range(3))
    return cold, warm


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=1.0, help="simulated seconds per measurement")
    ap.add_argument("--batch", type=int, nargs="*", default=[1, 4, 12, 64])
    ap.add_argument("--no-python", action="store_true", help="skip the (slow) pure-Python path")
    ap.add_argument("--json", help="also write the figures here")
    ap.add_argument("--_child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args._child:   # pure-Python path, run in a child process with BLDC_ACTUATOR_NO_NUMBA=1
        print(json.dumps(figures(args.seconds, args.batch)))
        return
    print(f"load average before: {os.getloadavg()[0]:.2f} (2 cores); kernel compiled: {COMPILED}")
    fast = figures(args.seconds, args.batch)
    slow = {}
    if not args.no_python:
        env = dict(os.environ, BLDC_ACTUATOR_NO_NUMBA="1")
        env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
        cmd = [sys.executable, __file__, "--_child", "--seconds", str(min(args.seconds, 0.3)), "--batch",
               *[str(n) for n in args.batch if n <= 12]]
        slow = json.loads(subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout)
    print("\n| s per simulated second per actuator, 10 kHz loop | compiled | pure Python | ratio |")
    print("|---|---|---|---|")
    for key, val in fast.items():
        py = slow.get(key)
        print(f"| {key} | {val:.5f} | {py:.4f} | {py / val:.0f}x |" if py else f"| {key} | {val:.5f} | – | – |")
    cold, warm = start_times() if COMPILED else (float("nan"), float("nan"))
    print(f"\nimport + compile + first step: cold numba cache {cold:.2f} s, warm cache {warm:.2f} s")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"compiled": fast, "python": slow, "start_cold_s": cold, "start_warm_s": warm}, f, indent=1)


if __name__ == "__main__":
    main()
