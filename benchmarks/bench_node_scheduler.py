#!/usr/bin/env python3
"""The node's per-period Python work without ROS (a script, not a test): prints figures.

    .venv/bin/python benchmarks/bench_node_scheduler.py [--joints 12] [--periods 5000] [--repeats 7]

A :class:`~bldc_actuator.scheduler.Scheduler` over ``--joints`` ak80_9 joints in lock-step, each period
preceded by one ``~/commands`` array (a +-0.5 N*m square wave at 2 Hz, as bench_node_floor's controller sends),
defaults otherwise (diagnostics at 10 Hz, no detail subscribers): what ``actuator_node`` does per period on top
of publishing JointState (the floor's cost). Two plants, alternated ``--repeats`` times in the same process:

* ``cheap``: the default :class:`~bldc_actuator.plant.ActuatorPlant` (``joint_states()`` through
  :meth:`bldc_actuator.model.Actuator.joint_state` on periods without diagnostics);
* ``full``: the same plant without the optional ``joint_states()``: ``all_outputs()`` (12 ``outputs()`` dicts)
  every period, as before the cheap read existed.

Wall time per period [us] (median and range over the repeats); the load average is printed (a shared machine).
"""

from __future__ import annotations

import argparse
import logging
import os
import statistics
import time

from bldc_actuator.params import load_preset
from bldc_actuator.plant import ActuatorPlant
from bldc_actuator.scheduler import Scheduler, SchedulerConfig


class FullReadPlant(ActuatorPlant):
    joint_states = None   # no cheap read: the scheduler reads all_outputs() every period


def per_period_us(plant_cls, joints: int, periods: int) -> float:
    plant = plant_cls({f"j{k}": load_preset("ak80_9") for k in range(joints)})
    sched = Scheduler(plant, SchedulerConfig(lock_step=True, name_joints=joints > 1),
                      log=logging.getLogger("bench_node_scheduler"))
    sched.detail_wanted = False
    high, low = [0.5] * joints, [-0.5] * joints
    t0 = time.perf_counter()
    for k in range(periods):
        sched.commands(high if (k // 250) % 2 else low, "~/commands")
        sched.lock_step_period()
    return (time.perf_counter() - t0) / periods * 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--joints", type=int, default=12)
    ap.add_argument("--periods", type=int, default=5000)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    per_period_us(ActuatorPlant, args.joints, 100)   # compile / load the kernel first
    load0 = os.getloadavg()
    res = {"cheap": [], "full": []}
    for _ in range(args.repeats):
        for name, cls in (("cheap", ActuatorPlant), ("full", FullReadPlant)):
            res[name].append(per_period_us(cls, args.joints, args.periods))
    load1 = os.getloadavg()
    print(f"bench_node_scheduler: {args.joints} joints (ak80_9), lock-step, one ~/commands array per period, "
          f"{args.periods} periods x {args.repeats} repeats alternated; load average {load0[0]:.2f} -> {load1[0]:.2f}")
    for name, xs in res.items():
        print(f"  {name:<5} {statistics.median(xs):7.1f} us per period (range {min(xs):.1f}-{max(xs):.1f})")
    ratio = [c / f for c, f in zip(res["cheap"], res["full"])]
    print(f"  cheap/full per repeat: median {statistics.median(ratio):.2f} (range {min(ratio):.2f}-{max(ratio):.2f}); "
          f"at 1 kHz the difference is {(statistics.median(res['full']) - statistics.median(res['cheap'])) / 10:.1f} "
          "% of a core")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
