#!/usr/bin/env python3
"""Physics figures quoted in the README: energy closure, step-size agreement, bus-limited no-load speed.

    python benchmarks/physics_figures.py
The same checks run as assertions in test/test_model.py; this script prints the measured numbers.
"""

import math
import sys
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))
from test_model import rich_params, step_size_errors  # noqa: E402  (the exact scenarios the tests use)

from bldc_actuator import frames, profiles  # noqa: E402
from bldc_actuator.model import Actuator  # noqa: E402
from bldc_actuator.params import ActuatorParams  # noqa: E402


def energy():
    act = Actuator(rich_params())
    e0 = act.energy
    act.run(profiles.chirp(12.0, 0.2, 20.0, duration=10.0, rate=1000.0))
    e = act.energy
    print(f"energy closure, 10 s chirp, every optional term on, saturating: electrical in {e.electrical_in:.4f} J, "
          f"|residual| {abs(e.residual(e0)):.2e} J = {abs(e.residual(e0)) / e.electrical_in:.1e} relative "
          f"(integrator's own term {e.discretization:.2e} J); thermal {abs(e.thermal_residual()) / e.joule:.1e}")


def step_size():
    for rate, bw in ((10000.0, 1000.0), (20000.0, 2000.0)):
        p = rich_params(**{"drive.current_loop_rate": rate, "drive.current_loop_bandwidth": bw,
                           "load.gravity_torque": 0.3})
        for dt, errs in step_size_errors(p).items():
            text = ", ".join(f"{k} {v * 100:.3f} %" for k, v in errs.items())
            print(f"step size {dt * 1e6:.0f} us vs 10 us (loop {rate / 1e3:.0f} kHz): max error / range: {text}")


def no_load_speed():
    for winding in ("wye", "delta"):
        p = ActuatorParams().replace(**{"motor.winding": winding, "motor.viscous_damping": 1e-8,
                                        "motor.resistance_temperature_enabled": False,
                                        "drive.bus_voltage": 12.0, "drive.current_limit": 10.0})
        act = Actuator(p)
        act.set_current_command(10.0)
        act.step(3.0)
        paper = {"wye": math.sqrt(0.5), "delta": math.sqrt(1.5)}[winding] * 12.0 / p.motor.torque_constant_q
        print(f"no-load speed at 12 V ({winding}): simulated {act.state.omega:.4f} rad/s, paper formula "
              f"{paper:.4f} rad/s ({(act.state.omega / paper - 1) * 100:+.3f} %), "
              f"frames.no_load_speed_max {frames.no_load_speed_max(12.0, p.motor.torque_constant_q, winding):.4f}")


if __name__ == "__main__":
    energy()
    no_load_speed()
    step_size()
