#!/usr/bin/env python3
"""When does this project's own logged voltage act, and what does reading it right do to the resistance?

1. The kernel, stepped at 1 µs: the centre of the interval over which it held the q voltage it logs at each 1 kHz
   sample, minus the sample instant, for computation delays 0-100 µs (10 kHz loop), against what the writers declare
   (:func:`bldc_actuator.voltage_timing.applied_offset`).
2. The resistance by the search's equation-error column (nuisance columns included; true and nominal R 0.17 Ω) on
   the tests' closed-loop recording of the kernel (``test_issue14_judge_helpers.closed_loop_recording``: PD joint at
   1 kHz, triangle then sines, 16 s, log noise 0.03 A / 0.02 V) and on ``bldc-actuator simulate``'s CSV written and
   loaded again (free rotor, multisine current, 8 s, noise-free): read at the sample (nothing declared: what
   ``--voltage-timing auto`` did before the writers declared) and as the writers declare it (``applied``).

    .venv/bin/python benchmarks/voltage_timing_check.py
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "test"))

from bldc_actuator import profiles  # noqa: E402
from bldc_actuator import voltage_timing as vt  # noqa: E402
from bldc_actuator.diagnosis.frame import candidates as cands  # noqa: E402
from bldc_actuator.diagnosis.frame import equation_error as ee  # noqa: E402
from bldc_actuator.diagnosis.io.csvio import load_csv  # noqa: E402
from bldc_actuator.diagnosis.io.mapping import Mapping  # noqa: E402
from bldc_actuator.params import ActuatorParams  # noqa: E402
from bldc_actuator.simulate import simulate_profile, write_csv  # noqa: E402
from test_issue14_judge_helpers import closed_loop_recording, triangle_then_sines  # noqa: E402
from test_voltage_timing import held_interval_centres  # noqa: E402

P = ActuatorParams()


def held_centre(delay_s: float, log_ns: int = 1_000_000, fine_ns: int = 1_000, n_log: int = 12) -> float:
    """[s] mean centre of the held interval of the logged q voltage after its sample (see the module docstring;
    measured by the test's :func:`held_interval_centres`)."""
    p = P.replace(**{"drive.current_loop_delay": delay_s})
    return float(np.mean(held_interval_centres(p, log_ns, n_log=n_log, fine_ns=fine_ns)))


def resistance(sig, timing: str = "auto") -> tuple[float, float]:
    ctx = ee.prepare([(sig, False)], P, holdout=0.3, voltage_timing=timing)
    cols = {k: ctx.column(k, b) for k, b in ctx.nuisance.items()}
    cols["r_err"] = ctx.column("r_err", cands.col_r_err)
    fit = ee.fit_columns(ctx, cols, list(cols), {"electrical": 1.0}, blocks=["electrical"])
    return P.motor.phase_resistance + float(fit.beta[-1]), float(math.sqrt(fit.cov[-1, -1]))


def main() -> int:
    print("1. kernel: where the q voltage logged at a 1 kHz sample acts (10 kHz loop)")
    for d_us in (0, 20, 50, 80, 100):
        measured = held_centre(d_us * 1e-6)
        declared = vt.applied_offset(1_000_000, 100_000, d_us * 1000)
        print(f"   current_loop_delay {d_us:3d} us: held centred {1e6 * measured:+6.1f} us after the sample "
              f"(declared {1e6 * declared:+6.1f} us)")
    m = P.motor
    bias = -m.torque_constant_q ** 2 * 0.5e-4 / m.rotor_inertia
    print(f"\n2. resistance, true 0.17 ohm (read at the sample, predicted -K^2 (T/2)/J = {bias:+.4f} ohm)")
    for seed in (0, 1, 2):
        sig = closed_loop_recording(P, P, triangle_then_sines, duration=16.0, seed=seed)
        decl = sig.meta["voltage_timing"]           # the kernel's, as the project's writers declare it
        r1, s1 = resistance(sig)
        sig.meta["voltage_timing"] = None
        r0, s0 = resistance(sig)
        print(f"   closed_loop_recording seed {seed}: at the sample {r0:.4f} +- {s0:.4f}; "
              f"declared applied {r1:.4f} +- {s1:.4f}")
    rng = np.random.default_rng(0)
    t = np.arange(8000) / 1000.0
    f = np.array([0.7, 1.9, 3.1, 5.3, 8.9])
    cmd = (0.8 * np.sin(2 * np.pi * f[None] * t[:, None] + rng.uniform(0, 2 * np.pi, len(f)))).sum(axis=1)
    mapping = Mapping.parse(["time=t [s]", "current=i_q [A]", "current_d=i_d [A]", "voltage_q=v_q [V]",
                             "voltage_d=v_d [V]", "position=theta [rad]", "velocity=omega [rad/s]",
                             "current_command=i_q_ref [A]"])
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.csv"
        write_csv(simulate_profile(P, profiles.Profile(t, cmd, "current"), rate=1000.0), path)
        sig = load_csv(path, mapping=mapping, only_mapped=True)
        r1, s1 = resistance(sig)
        sig.meta["voltage_timing"] = None
        r0, s0 = resistance(sig)
    print(f"   simulate CSV (written, loaded): at the sample {r0:.4f} +- {s0:.4f}; "
          f"as declared ({decl.convention}) {r1:.4f} +- {s1:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
