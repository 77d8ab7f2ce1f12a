"""The kit an effect module builds its regressor forms from (issue #24: adding an effect is one file).

An effect searched by the linear selection (``Route.LINEAR``) holds, beside ``EFFECT``, ``FORMS = Forms(...)``:
its forms (:class:`Variant` s, or :class:`Single` for one fixed set of columns), its excitation test, how its
fitted coefficients map onto the parameter file, and its own reason when the held-out gate cannot decide it.
:func:`..frame.candidates.library` joins the two. A column builder takes the equation-error context ``ctx``
(:class:`..frame.equation_error.Context`: ``ctx.sig``, ``ctx.dsig(name)``, ``ctx.params``, ...) and returns
``{equation: raw-rate array}``; its coefficient is the *change* of a parameter (sign conventions:
:mod:`..frame.candidates`).

Like the rest of this package it imports nothing of the diagnosis (``test/test_import_graph.py``): what a form
needs of the frame it reads from ``ctx``, the frame's fitting functions included (``ctx.tools``,
:class:`..frame.equation_error.FrameTools`). The shared simulator terms (:mod:`bldc_actuator.effects`, imported
here as ``terms``), ``kernel`` and ``frames`` sit outside the diagnosis and may be imported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ... import effects as terms


@dataclass
class Variant:
    """One concrete form of a candidate: its column keys, builders and fixed hyper-parameters."""

    effect: str
    label: str
    columns: dict[str, Callable]                  #: key -> builder(ctx) -> {eq: raw array}
    hyper: dict[str, Any] = field(default_factory=dict)
    #: continuous hyper-parameter refined in the final fit: name -> (value, lo, hi, rebuild(ctx, value) -> columns)
    nonlinear: dict[str, tuple] = field(default_factory=dict)
    additive: bool = False                        #: other variants of the same effect may join later
    #: columns that depend on their own coefficient (fixed-point): (ctx, coef of the first key) -> {key: builder}
    iterate: Callable | None = None

    @property
    def keys(self) -> list[str]:
        return list(self.columns)


@dataclass(frozen=True)
class Single:
    """The effect's one form: these columns (made into :func:`v_single` of the effect's own name by
    :func:`..frame.candidates.library`)."""

    columns: dict[str, Callable]


@dataclass(frozen=True)
class Forms:
    """What the linear selection needs of one effect besides its record."""

    #: Single(columns), or (ctx, located residuals) -> list[Variant]
    variants: Single | Callable
    #: (ctx) -> None | why the recording does not excite it (None: no excitation test)
    excited: Callable | None
    #: (coef, cov, keys, variant, ctx) -> {parameter: {"value", "sd", "unit", "field", "delta"}}
    to_params: Callable
    #: (ctx) -> None | (why, what to do): its own reason when the held-out gate cannot decide it
    undecided_why: Callable | None = None
    #: (parameters, ctx) -> None | why: a plausibility check beyond its Params' bounds, for a range that depends on
    #: the recording (``parameters`` as ``to_params`` returns them)
    implausible: Callable | None = None


def v_single(effect, cols, label="", **kw):
    return lambda ctx, loc: [Variant(effect, label or effect, cols, **kw)]


def smooth_sign(x, eps):
    return np.tanh(x / eps) if eps > 0 else np.sign(x)


def mech(f):
    return lambda ctx: {"mechanical": f(ctx)}


def elec(f):
    return lambda ctx: {"electrical": f(ctx)}


def sd(cov, i):
    v = cov[i, i] if cov.size else float("nan")
    return float(math.sqrt(v)) if v >= 0 and math.isfinite(v) else float("nan")


def params_generic(names_units_fields):
    """Map each column key (in order) to (name, unit, field, offset_from_nominal: callable(params)->nominal)."""
    def f(coef, cov, keys, variant, ctx):
        out = {}
        for i, k in enumerate(keys):
            name, unit, fld, nominal = names_units_fields[k] if k in names_units_fields else (k, "", None, None)
            base = nominal(ctx.params) if nominal else 0.0
            out[name] = {"value": base + float(coef[i]), "sd": sd(cov, i), "unit": unit, "field": fld,
                         "delta": float(coef[i])}
        return out
    return f


def flat(field_name):
    """The nominal value of a dotted parameter field (``"motor.rotor_inertia"``), as params_generic's offset."""
    return lambda p: p.to_flat()[field_name]


def frac(x) -> float:
    """The share of samples where the boolean array ``x`` holds (0 for an empty one)."""
    return float(np.mean(x)) if np.size(x) else 0.0


def resolvable(ctx, order) -> np.ndarray:
    """Weight in [0, 1]: 1 where an angle harmonic of ``order`` (cycles per revolution) at the current speed
    lies well inside the low-pass (f < fc/2), falling smoothly to 0 at f = fc. Above that the measured
    signals cannot show it (and the raw-rate regressor would alias), so the column is switched off there."""
    f = np.abs(ctx.sig["omega_s"]) * order / (2 * math.pi)
    fc = ctx.dec.fc
    x = np.clip((f - 0.5 * fc) / (0.5 * fc), 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(math.pi * x))


def col_harmonic(order, k, which, current_weighted=False):
    """Mechanical column of the ``k``-th harmonic (``which`` = "cos" | "sin") of an angle order (cycles per
    revolution), switched off where the low-pass cannot show it (:func:`resolvable`)."""
    def build(ctx):
        b = terms.angle_harmonic_basis(ctx.sig["theta"], order, k)[:, 2 * (k - 1) + (0 if which == "cos" else 1)]
        b = b * resolvable(ctx, k * order)
        if current_weighted:
            b = b * ctx.sig["i_col"]
        return {"mechanical": b}
    return build


def friction_columns(ctx, omega_s) -> np.ndarray:
    """The shared friction basis (sign, |sign|, Stribeck at ``omega_s``) at the smoothed speed, smoothed at the
    velocity noise (:func:`bldc_actuator.effects.friction_basis`)."""
    return terms.friction_basis(ctx.sig["omega_s"], omega_s, ctx.omega_eps)


def excite_angle(order):
    """Excitation test of an angle-locked form: ``order`` cycles per revolution, or a callable(params) -> order."""
    def check(ctx):
        o = order(ctx.params) if callable(order) else order
        if float(ctx.sig["theta_known"]) <= 0:
            return "needs the rotor angle (position channel)"
        th = ctx.dsig("theta")
        span = float(np.nanmax(th) - np.nanmin(th)) * o / (2 * math.pi)
        return None if span >= 2.0 else f"needs the rotor to sweep at least two periods of order {o}"
    return check


def excite_temperature(ctx):
    """Excitation test of a temperature-driven parameter change: a temperature channel spanning a few K."""
    have = [c for c in ("winding_temperature", "housing_temperature") if c in ctx.have]
    if not have:
        return "needs winding_temperature or housing_temperature"
    T = ctx.dsig("T_w")
    span = float(np.nanmax(T) - np.nanmin(T))
    return None if span >= 3.0 else f"needs a temperature change of a few K (recorded span {span:.1f} K)"
