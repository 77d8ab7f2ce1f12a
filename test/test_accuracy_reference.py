"""The kernel against an independent fine-step reference (benchmarks/accuracy_reference.py: RK4 at 0.5 µs of
the continuous plant under the same discrete current controller): errors are small and fall with the SQUARE
of the loop period (second order), below and at the voltage limit."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

SPEC = importlib.util.spec_from_file_location(
    "accuracy_reference", Path(__file__).resolve().parents[1] / "benchmarks" / "accuracy_reference.py")
ref = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(ref)


@pytest.fixture(scope="module")
def base():
    from bldc_actuator.params import load_preset

    return load_preset("ak80_9").replace(**{
        "effects.coulomb_friction": 0.0, "effects.friction_asymmetry": 0.0, "effects.stribeck_friction": 0.0,
        "effects.cogging_order": 0, "effects.cogging_cos": (), "effects.cogging_sin": (),
        "load.load_torque": 0.0, "load.gravity_torque": 0.0, "load.spring_stiffness": 0.0,
        "motor.resistance_temperature_enabled": False, "motor.magnet_temperature_enabled": False,
        "drive.current_loop_bandwidth": 500.0})


def test_kernel_matches_the_fine_step_reference_with_second_order_convergence(base):
    errs = []
    for rate in (10000.0, 20000.0):
        p = base.replace(**{"drive.current_loop_rate": rate})
        sc = list(ref.scenarios(p, 0.15).values())
        errs.append([ref.compare(p, cmd, 0.5e-6) for cmd in sc])
    chirp10, limit10 = errs[0]
    assert chirp10["i_q_max"] < 1e-3 * chirp10["i_q_range"]            # 1.5e-4 A of ~6 A
    assert limit10["i_q_max"] < 2e-3 * limit10["i_q_range"]            # at the voltage limit
    assert limit10["omega_max"] < 1e-4 * max(limit10["omega_range"], 1.0)
    for k in range(2):   # halving the loop period divides the error by ~4
        order = math.log2(errs[0][k]["i_q_max"] / errs[1][k]["i_q_max"])
        assert 1.7 < order < 2.6, (k, order)


@pytest.mark.parametrize("delay_ticks", [0.5, 1.0])
def test_current_loop_delay_matches_the_reference_with_the_same_delay(base, delay_ticks):
    """drive.current_loop_delay: the voltage computed at a tick reaches the plant that much later. The kernel
    (which splits the interval at the switch) agrees with the independent reference delaying its zero-order
    hold by the same time, and the delay visibly changes the response (it is not a no-op)."""
    p = base.replace(**{"drive.current_loop_rate": 10000.0, "drive.current_loop_delay": delay_ticks * 1e-4})
    cmd = list(ref.scenarios(p, 0.1).values())[0]
    r = ref.compare(p, cmd, 0.5e-6)
    assert r["i_q_max"] < 1e-3 * r["i_q_range"]
    undelayed = ref.kernel(base.replace(**{"drive.current_loop_rate": 10000.0}), cmd)
    delayed = ref.kernel(p, cmd)
    assert np.max(np.abs(delayed[:, 0] - undelayed[:, 0])) > 20 * r["i_q_max"]
