"""Issue #24, symptoms 5 and 6: two fitted parameters whose estimates correlate beyond 0.99 are reported as the
one combination the data pin (value, sd, which parameters), not as two values, and written back defensibly (the
first carries the combination, the second keeps its nominal value): one implementation
(:mod:`bldc_actuator.diagnosis.frame.combination`) behind the voltage equation's core check
(:mod:`..fit.base_model`, R and K_t under a viscous brake: ``test_issue24_base_model.py``) and the linear
selection's final fit (:mod:`..frame.writeback`)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from bldc_actuator.diagnosis.effects.forms import Variant, flat, params_generic
from bldc_actuator.diagnosis.fit import base_model
from bldc_actuator.diagnosis.frame import combination, writeback
from bldc_actuator.diagnosis.frame.least_squares import ols
from bldc_actuator.diagnosis.frame.selection import Accepted, SelectionResult
from bldc_actuator.params import ActuatorParams

B_P, B_Q, SLOPE = 0.2, 0.1, 1.5


def _collinear_fit(n=20000, eps=2e-3, sigma=0.05, seed=0):
    """Columns X_q = SLOPE X_p + eps noise: the data pin b_p + SLOPE b_q; its sd is sigma / |X_p| (the
    least-squares sd of one column's coefficient), far below either coefficient's own."""
    rng = np.random.default_rng(seed)
    xp = np.sign(np.sin(np.linspace(0, 40 * math.pi, n))) + 0.1 * rng.standard_normal(n)
    xq = SLOPE * xp + eps * rng.standard_normal(n)
    X = np.column_stack([xp, xq])
    y = X @ np.array([B_P, B_Q]) + sigma * rng.standard_normal(n)
    coef, cov, _ = ols(X, y)
    return X, coef, cov, sigma / math.sqrt(float(xp @ xp))


def test_two_collinear_coefficients_give_one_combination_with_its_analytic_value_and_sd():
    X, coef, cov, sd_expected = _collinear_fit()
    (c,) = combination.collinear(["p", "q"], coef, cov, X)
    assert c.parameters == ("p", "q")
    assert abs(c.correlation) > combination.COLLINEAR
    assert c.a == pytest.approx(SLOPE, rel=1e-3)
    assert c.sd == pytest.approx(sd_expected, rel=0.05)
    assert abs(c.value - (B_P + SLOPE * B_Q)) < 3 * c.sd
    # each coefficient alone is hardly determined; the combination is
    assert math.sqrt(cov[0, 0]) > 20 * c.sd and math.sqrt(cov[1, 1]) > 20 * c.sd
    # a well-separated pair is no combination
    rng = np.random.default_rng(1)
    X2 = rng.standard_normal((5000, 2))
    coef2, cov2, _ = ols(X2, X2 @ np.array([1.0, 2.0]) + 0.1 * rng.standard_normal(5000))
    assert combination.collinear(["p", "q"], coef2, cov2, X2) == []


def test_base_model_reports_its_collinear_pair_through_the_same_implementation():
    assert base_model.COLLINEAR is combination.COLLINEAR
    assert base_model.collinear is combination.collinear


def test_the_final_fit_writes_a_collinear_pair_back_as_its_combination_and_reports_it_once():
    """Two accepted effects (here a viscous and a Coulomb column, made collinear) in a final fit: the report
    carries ONE combination naming both parameters, its value and sd; the written-back first parameter carries
    the combination (nominal + b_p + a b_q), the second keeps its nominal value."""
    X, coef, cov, _ = _collinear_fit()
    nominal = ActuatorParams().replace(**{"motor.viscous_damping": 1e-5, "effects.coulomb_friction": 0.002})
    ctx = SimpleNamespace(params=nominal)
    m_visc = params_generic({"visc": ("viscous_damping", "N*m*s/rad", "motor.viscous_damping",
                                      flat("motor.viscous_damping"))})
    m_coul = params_generic({"coul": ("coulomb_friction", "N*m", "effects.coulomb_friction",
                                      flat("effects.coulomb_friction"))})
    lib = {"viscous_friction": SimpleNamespace(to_params=m_visc, equations=("mechanical",)),
           "coulomb_friction": SimpleNamespace(to_params=m_coul, equations=("mechanical",))}
    acc = [Accepted("viscous_friction", Variant("viscous_friction", "v", {"visc": None}), ["visc"], 1, 50.0, {}),
           Accepted("coulomb_friction", Variant("coulomb_friction", "c", {"coul": None}), ["coul"], 2, 20.0, {})]
    sel = SelectionResult(acc, None, None, {}, {}, [], [], [], [], [])
    keys = ["visc", "coul"]
    ff = writeback.FinalFit(None, keys, coef, cov, combinations=combination.collinear(keys, coef, cov, X))
    pars = writeback.effect_parameters(ctx, sel, ff, lib)
    (rep,) = ff.combined
    assert rep["parameters"] == ["viscous_friction.viscous_damping", "coulomb_friction.coulomb_friction"]
    assert rep["a"] == pytest.approx(SLOPE, rel=1e-3)
    expected = (1e-5 + B_P) + SLOPE * 0.002 + SLOPE * B_Q            # (nominal + change) of p + a x of q
    assert abs(rep["value"] - expected) < 3 * rep["sd"]
    assert "not separable" in rep["message"] and "kept at its nominal" in rep["written_back"]
    v, c = pars["viscous_friction"]["viscous_damping"], pars["coulomb_friction"]["coulomb_friction"]
    assert c["value"] == pytest.approx(0.002, abs=1e-15) and c["held_at_nominal"]
    assert v["value"] + rep["a"] * c["value"] == pytest.approx(rep["value"], rel=1e-9)
    assert v["sd"] == pytest.approx(ff.combinations[0].sd, rel=1e-9)
