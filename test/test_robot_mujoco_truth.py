"""The robot route on a truth this project did not write (issue #26): the 3-link arm integrated by MuJoCo alone
(its own ``<motor>`` actuators, joint ``frictionloss``/``damping``/``armature``; ``robot_cases.mujoco_native_run``),
and the body's stage run with single-threaded BLAS."""

from __future__ import annotations

import ctypes
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import robot_cases as rc  # noqa: E402

from bldc_actuator.diagnosis.body import robot  # noqa: E402
from bldc_actuator.diagnosis.threads import SingleThreadedBLAS  # noqa: E402

SECONDS = 6.0


@pytest.fixture(scope="module")
def mj_logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("arm_mj")
    return {case: rc.simulate_mujoco(case, SECONDS).write_csv(d / f"{case}.csv") for case in ("null", "payload")}


def test_mujoco_parameters_are_the_motor_side_values_reflected_through_the_gear():
    p = rc._nominal()
    n = p.gear.gear_ratio
    mp = rc.mujoco_native_parameters(p)
    assert mp["frictionloss"] == pytest.approx(n * p.effects.coulomb_friction)      # N·m at the output
    assert mp["damping"] == pytest.approx(n * n * p.motor.viscous_damping)
    assert mp["armature"] == pytest.approx(n * n * p.motor.rotor_inertia)


def test_the_mujoco_native_arm_holds_still_against_gravity_on_its_feed_forward():
    """The truth's own physics: the commanded current times K_t N equals the nominal inverse dynamics plus the
    reflected rotor inertia (computed torque), so the tracking error stays small on the nominal arm."""
    t = np.arange(int(2.0 * rc.RATE_HZ)) / rc.RATE_HZ
    q, qd, qdd = rc.reference(t, np.random.default_rng(1))
    p = rc._nominal()
    pos, _, _, _ = rc.mujoco_native_run(rc.MJCF, rc.MODEL_JOINTS, {j: p for j in rc.MODEL_JOINTS}, p, q, qd, qdd,
                                        np.random.default_rng(2))
    assert np.max(np.abs(pos - q)) < 0.05            # rad: friction is the only unmodelled torque


def test_a_payload_on_the_mujoco_native_truth_is_named_within_10_percent(mj_logs):
    report = robot.diagnose_robot_file(mj_logs["payload"], rc._nominal(), rc.MJCF, joint_map=rc.JOINT_MAP,
                                       joints_diagnosed=False)
    (found,) = report.body.findings
    assert found.body == "payload"
    assert found.delta_mass == pytest.approx(rc.truth("payload").body_mass["payload"], rel=0.10)


def _openblas_threads() -> int | None:
    with open("/proc/self/maps") as fh:
        libs = {line.split()[-1] for line in fh if "openblas" in line.lower() and "/" in line}
    for path in libs:
        lib = ctypes.CDLL(path)
        for get, _ in SingleThreadedBLAS.NAMES:
            if hasattr(lib, get):
                return int(getattr(lib, get)())
    return None


def test_the_body_stage_runs_on_single_threaded_blas(mj_logs, monkeypatch):
    """The joint-stacked mass fits are small products; OpenBLAS's pool only contends on a busy machine."""
    if _openblas_threads() is None:
        pytest.skip("no OpenBLAS found in this process")
    seen = []
    real = robot.fit_masses

    def spy(*a, **k):
        seen.append(_openblas_threads())
        return real(*a, **k)

    monkeypatch.setattr(robot, "fit_masses", spy)
    report = robot.diagnose_robot_file(mj_logs["null"], rc._nominal(), rc.MJCF, joint_map=rc.JOINT_MAP,
                                       joints_diagnosed=False)
    assert seen == [1]
    assert report.body.findings == []
