"""The kit an effect module builds its regressor forms from (issue #24: adding an effect is one file).

An effect searched by the linear selection (``Route.LINEAR``) holds, beside ``EFFECT``, ``FORMS = Forms(...)``:
its forms (:class:`Variant` s, or :class:`Single` for one fixed set of columns), its excitation test, how its
fitted coefficients map onto the parameter file, and its own reason when the held-out gate cannot decide it.
:func:`..frame.candidates.library` joins the two. A column builder takes the equation-error context ``ctx``
(:class:`..frame.equation_error.Context`: ``ctx.sig``, ``ctx.dsig(name)``, ``ctx.params``, ...) and returns
``{equation: raw-rate array}``; its coefficient is the *change* of a parameter (sign conventions:
:mod:`..frame.candidates`).

Like the rest of this package it imports nothing of the diagnosis (``test/test_import_graph.py``): what a form
needs of the frame it reads from ``ctx``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np


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
