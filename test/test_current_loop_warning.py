"""The unstable complex-vector current loop is said once where a user must notice it: ``simulate --params FILE``
printed it three times (the file's reader, the Actuator built from it, and a second Actuator built only for the
energy ledger's initial values), and a ``BatchActuator`` said nothing where an ``Actuator`` of the same parameters
warns. Counted under the "always" filter, so that Python's own once-per-line filter cannot hide a repeat."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from bldc_actuator import params as P
from bldc_actuator.cli import main
from bldc_actuator.model import Actuator, BatchActuator
from bldc_actuator.simulate import simulate_profile
from bldc_actuator import profiles

#: the third-party benchmark's joint on a 24 V bus: the complex-vector loop is unstable above 183 rad/s, the motor
#: reaches 228 rad/s at no load (test_current_loop_stability.py)
JOINT = P.ActuatorParams().replace(**{
    "motor.winding": "wye", "motor.pole_pairs": 21, "motor.phase_resistance": 0.13, "motor.q_inductance": 8.0e-5,
    "motor.torque_constant_q": 0.0743, "drive.bus_voltage": 24.0, "drive.current_loop_rate": 1.0e4,
    "drive.current_loop_bandwidth": 500.0, "drive.current_loop_delay": 1.0e-4, "drive.decoupling_enabled": False,
    "drive.current_controller": "complex_vector"})
#: the same drive at a slower loop bandwidth: still unstable within the motor's range, at another speed
SLOWER = JOINT.replace(**{"drive.current_loop_bandwidth": 400.0})
STABLE = JOINT.replace(**{"drive.bus_voltage": 18.0})


def _loop_warnings(fn):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn()
    return [w for w in caught if issubclass(w.category, P.ParameterWarning)
            and "complex_vector is unstable" in str(w.message)], out


def test_simulate_cli_says_it_once_with_the_file_name(tmp_path, capsys):
    path = tmp_path / "joint.yaml"
    P.dump_yaml(JOINT, path)
    ws, rc = _loop_warnings(lambda: main(["simulate", "--params", str(path), "--duration", "0.02", "--no-plot",
                                          "--out", str(tmp_path / "sim")]))
    assert rc == 0
    assert len(ws) == 1 and str(ws[0].message).startswith(f"{path}: ")
    assert P.current_loop_limit(JOINT).unstable_above() in str(ws[0].message)
    # the energy line still balances (its initial ledger is the actuator's own before the run, not a second one)
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("energy:"))
    assert abs(float(line.split("residual ")[1].split(" J")[0])) < 1e-5


def test_simulate_profile_says_it_once_whether_given_a_file_or_parameters(tmp_path):
    path = tmp_path / "joint.yaml"
    P.dump_yaml(JOINT, path)
    prof = profiles.step(0.5, 0.01, t_step=0.001, rate=1000.0, kind="current")
    for given in (path, JOINT):
        ws, _ = _loop_warnings(lambda: simulate_profile(given, prof))
        assert len(ws) == 1, given


def test_a_batch_warns_as_the_actuator_does_once_per_distinct_warning():
    (single,), _ = _loop_warnings(lambda: Actuator(JOINT))
    ws, b = _loop_warnings(lambda: BatchActuator([JOINT] * 40 + [STABLE] * 10 + [SLOWER] * 30 + [JOINT] * 5))
    assert [str(w.message) for w in ws] == [P.current_loop_warning(JOINT), P.current_loop_warning(SLOWER)]
    assert str(ws[0].message) == str(single.message) and P.current_loop_warning(STABLE) is None
    assert ws[0].filename == single.filename == __file__          # both point at the caller's line
    # equal sets that are different objects say it once too
    ws, _ = _loop_warnings(lambda: BatchActuator([JOINT.replace(**{"load.load_torque": 0.0}) for _ in range(20)]))
    assert len(ws) == 1
    # told not to (a caller that said it already, or checks the speeds it simulates): silent
    ws, _ = _loop_warnings(lambda: BatchActuator([JOINT] * 10, warn=False))
    assert ws == []
    ws, _ = _loop_warnings(lambda: Actuator(JOINT, warn=False))
    assert ws == []
    # a parameter update warns for the sets whose drive or motor changed, as Actuator.update_params does
    b = BatchActuator([STABLE] * 4)
    ws, _ = _loop_warnings(lambda: b.update_params([STABLE, SLOWER, SLOWER, STABLE]))
    assert [str(w.message) for w in ws] == [P.current_loop_warning(SLOWER)]
    ws, _ = _loop_warnings(lambda: b.update_params([STABLE, SLOWER, SLOWER.replace(**{"load.load_torque": 0.1}),
                                                     STABLE]))
    assert ws == []
    b.step(1e-3)
    assert np.all(np.isfinite(b.field("omega")))


def test_the_node_plants_warn_like_the_actuator_or_leave_it_to_the_node():
    """The node logs each joint's warning itself: its plants are built with ``warn=False``; built directly they
    warn once per distinct set, the MuJoCo coupling only for joints given as parameters (a preset was said where
    it was read)."""
    from bldc_actuator.plant import ActuatorPlant

    ws, _ = _loop_warnings(lambda: ActuatorPlant({"hip": JOINT, "knee": STABLE}))
    assert [str(w.message) for w in ws] == [P.current_loop_warning(JOINT)]
    ws, _ = _loop_warnings(lambda: ActuatorPlant({"hip": JOINT, "knee": JOINT}, warn=False))
    assert ws == []
    pytest.importorskip("mujoco")
    from pathlib import Path

    from bldc_actuator.mujoco.coupling import CoupledSim

    leg = Path(__file__).resolve().parents[1] / "config" / "two_link_leg.xml"
    joint = JOINT.replace(**{"load.gravity_torque": 0.0, "load.spring_stiffness": 0.0})
    ws, _ = _loop_warnings(lambda: CoupledSim(leg, {"hip": joint, "knee": joint}))
    assert len(ws) == 1 and ws[0].filename == __file__
    ws, _ = _loop_warnings(lambda: CoupledSim(leg, {"hip": joint, "knee": joint}, warn=False))
    assert ws == []
