"""The library of named candidate effects: each effect's registry record (:mod:`..effects`) joined with its
regressor forms, which the effect's own module holds (``FORMS``, :mod:`..effects.forms`): its columns, excitation
check, how its fitted coefficients map onto the parameter file; and the report's words (:func:`evidence`) and the
plausibility check (:func:`implausible`, each parameter against its record's ``Param.bounds``).

A column is ``key -> {equation: raw-rate array}``; its coefficient is the *change* of a parameter
(the equation-error residual of :mod:`.equation_error` is ``Σ column · Δparameter``). Sign conventions::

    mechanical r_m = K i_q - J ω' - b ω - τ_f - τ_cog - τ_ext/N    (true - nominal opposing torques)
    electrical r_e = v_q - R i_q - L i_q' - K ω - p ω L i_d

Variants: a candidate may offer several forms (cogging order, Stribeck velocity, which equations a
torque-constant error enters...); selection tries each and keeps the best.

One effect still holds its forms here (:func:`_forms`: the position-dependent load, whose forms are being
rewritten); every other linear effect's are in its module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..effects import Effect, Route, Story, registry
from ..effects.forms import Forms, Single, Variant, v_single  # noqa: F401 - Forms, Variant: the library's vocabulary
from ..effects.forms import sd as _sd

# re-exported: the names tests and benchmarks import from the library (each owned by its effect module)
from ..effects.current_loop_delay import col_delay, params_delay  # noqa: F401
from ..effects.dead_time import dead_time_in_band, dead_time_q_factor  # noqa: F401
from ..effects.inertia_error import col_inertia  # noqa: F401
from ..effects.resistance_error import col_r_err  # noqa: F401
from ..effects.torque_constant_error import FRAME_FACTORS, match_frame_factor  # noqa: F401
from ..effects.transmission_compliance import col_compliance, compliance_filter  # noqa: F401


@dataclass
class Candidate:
    name: str
    equations: tuple[str, ...]
    needs: tuple[str, ...]                        #: channels ("a|b" = either)
    description: str                              #: plain words: what physics this is
    simulated: bool                               #: has parameters in the schema
    confusable: dict[str, str] = field(default_factory=dict)   #: other effect -> experiment separating them
    variants: Callable = None                     #: (ctx, locate) -> list[Variant]
    excited: Callable = None                      #: (ctx) -> None | reason it is not identifiable here
    to_params: Callable = None                    #: (coef, cov, keys, variant, ctx) -> Finding parameters
    #: a candidate that is never fitted on its own but may hide behind these accepted effects (checked as an
    #: alias only for them, :func:`..selection.unexcited_aliases`); None: behind any effect sharing an equation
    hides_behind: tuple[str, ...] | None = None
    #: (ctx) -> None | (why, what to do): the candidate's own reason when the held-out gate cannot decide it
    #: (:func:`..selection._gate`), in place of "held-out too short" where the data, not its length, are at fault
    undecided_why: Callable | None = None
    #: the effect's registry record (every facet the stages ask about)
    record: Effect | None = None


# ---------------------------------------------------------------------------------------- builders


def col_load(kind):
    def build(ctx):
        N = ctx.params.gear.gear_ratio
        th_out = ctx.sig["theta"] / N
        f = {"sin": np.sin(th_out), "cos": np.cos(th_out), "lin": th_out, "const": np.ones_like(th_out)}[kind]
        return {"mechanical": f / N}
    return build


def excite_load(ctx):
    if float(ctx.sig["theta_known"]) <= 0:
        return "needs the rotor angle (position channel)"
    N = ctx.params.gear.gear_ratio
    th = ctx.dsig("theta") / N
    span = float(np.nanmax(th) - np.nanmin(th))
    return None if span >= 0.5 else f"needs output motion over a larger angle (swept {span:.2f} rad)"


def v_load(ctx, loc):
    cols = {"load_sin": col_load("sin"), "load_cos": col_load("cos"), "load_const": col_load("const")}
    out = [Variant("position_dependent_load", "gravity-like sin/cos of the output angle + constant", dict(cols))]
    N = ctx.params.gear.gear_ratio
    th = ctx.dsig("theta") / N
    if float(np.nanmax(th) - np.nanmin(th)) < 4 * math.pi:
        c2 = dict(cols)
        c2["load_lin"] = col_load("lin")
        out.append(Variant("position_dependent_load", "gravity + spring + constant", c2))
    return out


# ------------------------------------------------------------------------------ parameter mapping

def params_load(coef, cov, keys, variant, ctx):
    ld = ctx.params.load
    c = dict(zip(keys, coef))
    # nominal gravity as sin/cos components: τ_g sin(θ + φ) = τ_g cos φ sin θ + τ_g sin φ cos θ
    a_s = ld.gravity_torque * math.cos(ld.gravity_phase) + c.get("load_sin", 0.0)
    a_c = ld.gravity_torque * math.sin(ld.gravity_phase) + c.get("load_cos", 0.0)
    g = math.hypot(a_s, a_c)
    phi = math.atan2(a_c, a_s)
    i_s, i_c = keys.index("load_sin"), keys.index("load_cos")
    sd_g = math.sqrt(max(0.0, (a_s ** 2 * cov[i_s, i_s] + a_c ** 2 * cov[i_c, i_c] + 2 * a_s * a_c * cov[i_s, i_c])
                         / max(g * g, 1e-300)))
    sd_phi = math.sqrt(max(0.0, (a_c ** 2 * cov[i_s, i_s] + a_s ** 2 * cov[i_c, i_c] - 2 * a_s * a_c * cov[i_s, i_c])
                           / max(g ** 4, 1e-300)))
    out = {"gravity_torque": {"value": g, "sd": sd_g, "unit": "N*m", "field": "load.gravity_torque"},
           "gravity_phase": {"value": phi, "sd": sd_phi, "unit": "rad", "field": "load.gravity_phase"}}
    k0 = keys.index("load_const")
    const = ld.load_torque + c["load_const"]
    if "load_lin" in c:
        k = ld.spring_stiffness + c["load_lin"]
        kl = keys.index("load_lin")
        out["spring_stiffness"] = {"value": k, "sd": _sd(cov, kl), "unit": "N*m/rad", "field": "load.spring_stiffness"}
        # spring zero kept; its constant part moves into load_torque
        const = const + ld.spring_stiffness * ld.spring_zero - k * ld.spring_zero
    out["load_torque"] = {"value": const, "sd": _sd(cov, k0), "unit": "N*m", "field": "load.load_torque"}
    return out


# ------------------------------------------------------------------------------------------ library

def _forms() -> dict[str, tuple]:
    """Each effect's code on the frame's side: (variants, excitation test, parameter mapping, undecided reason);
    everything else about it is its registry record (:mod:`..effects`)."""
    return {
        "position_dependent_load": (v_load, excite_load, params_load, None),
    }


def library() -> dict[str, Candidate]:
    """Every candidate effect by its identifier (the names used in the JSON report), in the registry's order:
    its record (:mod:`..effects.registry`) and its forms (:func:`_forms`)."""
    forms = _forms()
    out = {}
    for e in registry.candidates():
        own = registry.forms(e.name)
        if own is not None:
            variants, excited, to_params, undecided = own.variants, own.excited, own.to_params, own.undecided_why
        else:
            variants, excited, to_params, undecided = forms.get(e.name, (None, None, None, None))
        if isinstance(variants, Single):
            variants = v_single(e.name, variants.columns)
        out[e.name] = Candidate(e.name, e.equations, e.needs, e.description, e.simulated, dict(e.confusable),
                                variants, excited, to_params, hides_behind=e.hides_behind, undecided_why=undecided,
                                record=e)
    return out


EFFECT_NAMES = registry.names(registry.candidates())
#: found by the thermal network's output error, not the linear selection
THERMAL = registry.names(registry.by_route(Route.THERMAL))
#: checked by output-error routines and the simulation, not the linear selection
SPECIAL = registry.names(registry.where(lambda e: e.special and e.candidate))


# ------------------------------------------------------------------------------------------ evidence

def _bins(loc, eq, view):
    return ((loc.get(eq) or {}).get("bins") or {}).get(view) or []


def _fmt(x, unit):
    return f"{x:+.3g} {unit.split(' ')[0]}"


def _velocity_story(loc, eq="mechanical") -> str | None:
    bins = _bins(loc, eq, "velocity")
    if not bins:
        return None
    unit = loc[eq]["unit"]
    pos = [b for b in bins if b["lo"] >= 0 and b["count"] > 0 and b["label"] != "|ω|≈0"]
    neg = [b for b in bins if b["hi"] <= 0 and b["count"] > 0 and b["label"] != "|ω|≈0"]
    zero = [b for b in bins if b["label"] == "|ω|≈0" and b["count"] > 0]
    if not pos or not neg:
        return None
    mp = np.average([b["mean"] for b in pos], weights=[b["count"] for b in pos])
    mn = np.average([b["mean"] for b in neg], weights=[b["count"] for b in neg])
    zmax = max(abs(b["z"]) for b in pos + neg)
    s = (f"{eq} residual by speed: mean {_fmt(mp, unit)} for ω>0, {_fmt(mn, unit)} for ω<0 "
         f"(|z| up to {zmax:.0f})")
    if mp * mn < 0:
        s += "; it changes sign with the direction of motion (a step at zero speed)"
        if abs(abs(mp) - abs(mn)) > 0.2 * max(abs(mp), abs(mn)):
            s += ", with different size per direction"
    elif abs(mp - mn) < 0.3 * max(abs(mp), abs(mn)):
        s += "; same sign in both directions (an offset, not friction)"
    slow = [b for b in pos + neg if "slow" in b["label"]]
    fast = [b for b in pos + neg if "fast" in b["label"]]
    if slow and fast:
        ms = np.mean([abs(b["mean"]) for b in slow])
        mf = np.mean([abs(b["mean"]) for b in fast])
        s += f"; |mean| {ms:.3g} at low speed vs {mf:.3g} at high speed"
    if zero:
        s += f"; near-zero-speed bin {_fmt(zero[0]['mean'], unit)} ({zero[0]['count']} samples)"
    return s


def _trend_story(loc, eq, view, what) -> str | None:
    bins = [b for b in _bins(loc, eq, view) if b["count"] > 0]
    if len(bins) < 2:
        return None
    unit = loc[eq]["unit"]
    first, last = bins[0], bins[-1]
    return (f"{eq} residual by {what}: RMS {first['rms']:.3g} in {first['label']} vs {last['rms']:.3g} in "
            f"{last['label']} (mean {_fmt(first['mean'], unit)} -> {_fmt(last['mean'], unit)})")


def _spectrum_story(loc, order, eq="mechanical") -> str | None:
    spec = (loc.get(eq) or {}).get("order_spectrum") or {}
    if not spec.get("orders"):
        return None
    o = np.array(spec["orders"])
    a = np.array(spec["amplitude"])
    i = np.flatnonzero(o == order)
    if not len(i):
        return None
    med = float(np.median(a[(o >= order / 2) & (o <= 2 * order)])) if len(a) else float("nan")
    rank = int((a > a[i[0]]).sum()) + 1
    marks = {v: k for k, v in spec.get("marks", {}).items()}
    tag = f" (= {marks[order]})" if order in marks else ""
    return (f"angle-order spectrum of the {eq} residual: order {order}{tag} has amplitude {a[i[0]]:.3g} "
            f"= {a[i[0]] / med:.1f}x the local median (rank {rank} of {len(a)} orders)")


def evidence(effect: str, variant: Variant, loc: dict, extra: dict) -> list[str]:
    """Plain-word pointers from the locate results to this effect (its fingerprint), plus the selection
    numbers. ``extra``: ``explained`` (share of the nominal residual variance its columns explain),
    ``dbic``, ``heldout``."""
    out: list[str] = []
    record = registry.get(effect) if registry.known(effect) else None
    story = record.story if record is not None else Story.NONE
    if story is Story.VELOCITY:
        s = _velocity_story(loc)
        if s:
            out.append(s)
    elif story is Story.ANGLE_SPECTRUM:
        s = _spectrum_story(loc, int(variant.hyper["order"]))
        if s:
            out.append(s)
    elif story is Story.CURRENT_TREND:
        for eq in ("mechanical", "electrical"):
            s = _trend_story(loc, eq, "current", "|current|")
            if s:
                out.append(s)
    elif story is Story.TEMPERATURE_TREND:
        for eq in ("electrical", "mechanical"):
            s = _trend_story(loc, eq, "temperature", "temperature")
            if s:
                out.append(s)
    elif story is Story.HEADROOM:
        s = _trend_story(loc, "electrical", "headroom", "voltage headroom |v|/v_max")
        if s:
            out.append(s)
    elif story is Story.ELECTRICAL_CURRENT_TREND:
        s = _trend_story(loc, "electrical", "current", "|current|")
        if s:
            out.append(s)
    for eq in ("mechanical", "electrical"):
        wins = (loc.get(eq) or {}).get("windows") or []
        if wins and record is not None and record.level_windows:
            w = max(wins, key=lambda x: x["ratio_to_quietest"])
            out.append(f"{eq} residual changes level at t = {w['start']:.1f}-{w['stop']:.1f} s "
                       f"({w['ratio_to_quietest']:.1f}x the quietest segment)")
    if "explained" in extra:
        out.append(f"its regressors explain {100 * extra['explained']:.1f}% of the nominal equation-error "
                   f"variance (training data)")
    if "dbic" in extra:
        ho = extra.get("heldout", {})
        out.append(f"selection: ΔBIC {extra['dbic']:.1f}; held-out residual RMS -{100 * ho.get('rel', 0):.1f}% "
                   f"(t = {ho.get('t', 0):.1f})")
    return out


# ------------------------------------------------------------------------------------- plausibility

def implausible(cand: Candidate, coef, cov, keys, variant: Variant, ctx) -> str | None:
    """A reason when the fitted parameters are physically implausible (a fit that makes the torque constant
    vanish or the resistance negative explains noise, not physics), else None: each of the effect's parameters
    against its own plausible range (``Param.bounds`` in its record)."""
    try:
        pars = cand.to_params(np.asarray(coef), np.asarray(cov), keys, variant, ctx)
    except Exception:  # noqa: BLE001 - a mapping that cannot even be evaluated is not plausible
        return "its parameters cannot be evaluated"

    for prm in cand.record.params if cand.record is not None else ():
        x = pars.get(prm.name)
        if x is None or x.get("value") is None:
            continue
        for bound in prm.bounds:
            why = bound.violation(prm, x["value"], x.get("sd", 0.0), ctx.params)
            if why:
                return f"implausible fitted value: {why}"
    own = registry.forms(cand.name) if registry.known(cand.name) else None
    why = own.implausible(pars, ctx) if own is not None and own.implausible is not None else None
    if why:
        return f"implausible fitted value: {why}"
    return None
