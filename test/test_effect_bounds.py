"""Each fitted parameter's plausible range is a facet of its effect's record (``Param.bounds``, issue #24), and
``candidates.implausible`` refuses a fit outside it: a torque constant scaled to a tenth, a rotor inertia 25 x its
nominal, a friction significantly negative, a load behind a spring heavier than the rotor it sits on."""

from __future__ import annotations

import math

import pytest

from bldc_actuator.diagnosis.effects import Bounds, Param, registry
from bldc_actuator.diagnosis.frame.candidates import implausible, library
from bldc_actuator.params import ActuatorParams

P = ActuatorParams()


def _param(effect: str, name: str) -> Param:
    return next(p for p in registry.get(effect).params if p.name == name)


def _why(effect: str, name: str, value: float, sd: float = 0.0) -> str | None:
    p = _param(effect, name)
    return next((w for b in p.bounds if (w := b.violation(p, value, sd, P))), None)


def test_relative_bounds_scale_with_the_nominal_value():
    J = P.motor.rotor_inertia
    assert _why("inertia_error", "rotor_inertia", 2.0 * J) is None
    assert "x nominal" in _why("inertia_error", "rotor_inertia", 25.0 * J)
    assert _why("inertia_error", "rotor_inertia", 0.05 * J) is not None
    assert _why("resistance_error", "phase_resistance", -0.1) is not None


def test_a_friction_may_be_negative_only_within_three_standard_deviations():
    assert _why("viscous_friction", "viscous_damping", -1e-5, sd=1e-5) is None
    assert "< 0" in _why("viscous_friction", "viscous_damping", -4e-5, sd=1e-5)
    for effect in ("coulomb_friction", "asymmetric_friction"):
        assert _why(effect, "coulomb_friction", -0.01, sd=0.001) is not None


def test_a_reflected_load_must_clear_zero_and_leave_the_rotor_some_inertia():
    J = P.motor.rotor_inertia
    assert _why("transmission_compliance", "load_inertia_reflected", 0.5 * J, sd=0.01 * J) is None
    assert "not above 0" in _why("transmission_compliance", "load_inertia_reflected", 0.5 * J, sd=0.2 * J)
    assert _why("transmission_compliance", "load_inertia_reflected", 0.5 * J, sd=math.nan) is not None
    assert "above 0.95 x nominal" in _why("transmission_compliance", "load_inertia_reflected", 0.99 * J, sd=0.0)


def test_a_non_numeric_value_is_not_bounded():
    assert Bounds(0.2, 5.0).violation(Param("frame_factor", ""), "sqrt(3/2)", 0.0, P) is None


def test_implausible_checks_the_candidates_own_record():
    """The torque-constant candidate's fitted ratio of 0.1 (its coefficient κ - 1 = -0.9) is refused by the bound on
    its record's ``ratio_to_nominal``; 1.22 (a frame factor) is not."""
    cand = library()["torque_constant_error"]

    class Ctx:
        params = P

    assert "torque constant ratio" in implausible(cand, [-0.9], [[1e-6]], ["kt_mech"], None, Ctx())
    assert implausible(cand, [math.sqrt(1.5) - 1.0], [[1e-6]], ["kt_mech"], None, Ctx()) is None
    assert pytest.approx(0.2) == _param("torque_constant_error", "ratio_to_nominal").bounds[0].lo
