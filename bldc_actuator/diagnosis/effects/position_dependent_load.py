"""A load at the output: a constant force or torque, a spring, a gravity-like sinusoid of the output angle.

The record and its regressor forms (``FORMS``). The forms offered are the ones the recording can identify
(issue #24, symptom 5: a constant force on a linear axis came out as two cancelling sinusoid terms, "gravity
375 N·m" on a horizontal slide):

* a constant load alone (a weight on an incline, a counterbalance, a process force);
* a constant plus a spring (a load linear in the output coordinate);
* a gravity-like sinusoid ``τ_g sin(θ_out + φ)`` plus a constant (and plus a spring) only on a joint that can
  carry one: never where ``gear.output_motion`` is ``linear`` (a slide's weight is the constant), always where it
  is ``rotary`` (a hinge), and where it is ``unspecified`` only if the output angle spans enough of a period for
  the sinusoid and the constant to separate: every pair of the form's fitted coefficients, from the columns'
  own geometry over the recording, correlates below :data:`..frame.combination.COLLINEAR` (the same limit beyond
  which two fitted parameters are reported as their combination). The output travel of a slide (0.2 m read as
  0.2 rad) spans a thirtieth of a period: there ``sin``, ``cos`` and the constant are one column.

On a linear axis the parameters are output-side forces: ``load_torque`` [N], ``spring_stiffness`` [N/m]
(:meth:`bldc_actuator.params.GearParams.output_unit`)."""

from __future__ import annotations

import math

import numpy as np

from .forms import Forms, Variant, sd
from .record import Effect, Param, Story

#: |correlation| of two fitted coefficients of one form beyond which the form is not offered (its parameters are
#: not separately identifiable over the recording's angles); the limit of :mod:`..frame.combination`
SEPARABLE = 0.99

EFFECT = Effect(
    name="position_dependent_load", rank=70,
    description="a load at the output: a constant force or torque, a spring, or a gravity-like sinusoid of the "
                "output angle",
    equations=("mechanical",), needs=("current", "position"), simulated=True,
    confusable={"asymmetric_friction": "while the axis moves a constant load and a friction asymmetry are the same "
                "equation (a constant torque whichever the direction), and standing still too while the load is "
                "below the dry friction; a load above it needs a holding current at standstill and drifts with the "
                "current off, friction never does. Below it: change the load (unload the axis or turn it over: a "
                "force reverses or vanishes, friction does not), measure the force, or, for a gravity load, hold "
                "still at several angles"},
    params=(Param("gravity_torque", "N*m", "load.gravity_torque"), Param("gravity_phase", "rad", "load.gravity_phase"),
            Param("spring_stiffness", "N*m/rad", "load.spring_stiffness"),
            Param("load_torque", "N*m", "load.load_torque")),
    story=Story.VELOCITY, external_load=True,
)


def col_load(kind):
    """The load's column at the output, referred to the rotor (divided by the gear ratio): ``sin``, ``cos`` of
    the output angle, ``lin`` (the output coordinate), ``const``."""
    def build(ctx):
        N = ctx.params.gear.gear_ratio
        th_out = ctx.sig["theta"] / N
        f = {"sin": np.sin(th_out), "cos": np.cos(th_out), "lin": th_out, "const": np.ones_like(th_out)}[kind]
        return {"mechanical": f / N}
    return build


def _output_angle(ctx) -> np.ndarray:
    th = np.asarray(ctx.dsig("theta"), float) / ctx.params.gear.gear_ratio
    return th[np.isfinite(th)]


def coefficient_correlation(columns: list[np.ndarray]) -> float:
    """The largest |correlation| between two least-squares coefficients of these columns under white noise
    (the normalised inverse Gram matrix): how far the recording can tell them apart, whatever the noise level."""
    X = np.column_stack(columns)
    scale = np.sqrt((X ** 2).sum(axis=0))
    if X.shape[1] < 2:
        return 0.0
    if np.any(scale == 0):
        return 1.0
    G = (X / scale).T @ (X / scale)
    try:
        C = np.linalg.inv(G)
    except np.linalg.LinAlgError:
        return 1.0
    d = np.sqrt(np.clip(np.diag(C), 1e-300, None))
    R = C / np.outer(d, d)
    np.fill_diagonal(R, 0.0)
    worst = float(np.max(np.abs(R)))
    return worst if math.isfinite(worst) else 1.0


_SHAPES = {"sin": np.sin, "cos": np.cos, "lin": lambda t: t, "const": np.ones_like}


def separable(ctx, kinds) -> tuple[bool, float]:
    """(the form's coefficients separate over this recording's output angles, their largest |correlation|)."""
    th = _output_angle(ctx)
    if th.size < 10:
        return False, 1.0
    rho = coefficient_correlation([_SHAPES[k](th) for k in kinds])
    return rho < SEPARABLE, rho


def gravity_offered(ctx) -> tuple[bool, str]:
    """Whether the sinusoid of the output angle is a form of this joint, and why (the report's words)."""
    motion = ctx.params.gear.output_motion
    if motion == "linear":
        return False, "gear.output_motion is linear: a slide's weight is a constant force, not a sinusoid"
    if motion == "rotary":
        return True, "gear.output_motion is rotary (a hinge)"
    ok, rho = separable(ctx, ("sin", "cos", "const"))
    th = _output_angle(ctx)
    span = float(np.max(th) - np.min(th)) if th.size else 0.0
    if ok:
        return True, f"the output angle spans {span:.3g} rad: sin, cos and a constant separate (|rho| {rho:.3f})"
    return False, (f"the output angle spans {span:.3g} rad only ({span / (2 * math.pi):.2g} of a period): a "
                   f"sinusoid and a constant do not separate (|rho| {rho:.4f} > {SEPARABLE}); set "
                   f"gear.output_motion: rotary to fit a hinge's gravity anyway")


def variants(ctx, loc):
    cols = {"load_const": col_load("const")}
    out = [Variant(EFFECT.name, "a constant load (force on a linear axis)" if _linear(ctx) else "a constant load",
                   dict(cols))]
    th = _output_angle(ctx)
    small = th.size > 0 and float(np.max(th) - np.min(th)) < 4 * math.pi
    if small and separable(ctx, ("lin", "const"))[0]:
        out.append(Variant(EFFECT.name, "spring + constant", {"load_lin": col_load("lin"), **cols}))
    ok, why = gravity_offered(ctx)
    if ok:
        grav = {"load_sin": col_load("sin"), "load_cos": col_load("cos"), **cols}
        out.append(Variant(EFFECT.name, "gravity-like sin/cos of the output angle + constant", dict(grav),
                           hyper={"gravity": why}))
        if small:
            out.append(Variant(EFFECT.name, "gravity + spring + constant", {**grav, "load_lin": col_load("lin")},
                               hyper={"gravity": why}))
    return out


def _linear(ctx) -> bool:
    return ctx.params.gear.output_motion == "linear"


def excited(ctx):
    """A constant load needs no motion to be identified (held still it is the holding current); the angle forms
    are offered only where the recording's angles identify them (:func:`variants`)."""
    if float(ctx.sig["theta_known"]) <= 0:
        return "needs the rotor angle (position channel)"
    return None


def to_params(coef, cov, keys, variant, ctx):
    ld = ctx.params.load
    unit = ctx.params.gear.output_unit
    c = dict(zip(keys, coef))
    out = {}
    if "load_sin" in c:
        # nominal gravity as sin/cos components: τ_g sin(θ + φ) = τ_g cos φ sin θ + τ_g sin φ cos θ
        a_s = ld.gravity_torque * math.cos(ld.gravity_phase) + c["load_sin"]
        a_c = ld.gravity_torque * math.sin(ld.gravity_phase) + c["load_cos"]
        g = math.hypot(a_s, a_c)
        phi = math.atan2(a_c, a_s)
        i_s, i_c = keys.index("load_sin"), keys.index("load_cos")
        sd_g = math.sqrt(max(0.0, (a_s ** 2 * cov[i_s, i_s] + a_c ** 2 * cov[i_c, i_c]
                                   + 2 * a_s * a_c * cov[i_s, i_c]) / max(g * g, 1e-300)))
        sd_phi = math.sqrt(max(0.0, (a_c ** 2 * cov[i_s, i_s] + a_s ** 2 * cov[i_c, i_c]
                                     - 2 * a_s * a_c * cov[i_s, i_c]) / max(g ** 4, 1e-300)))
        out["gravity_torque"] = {"value": g, "sd": sd_g, "unit": unit("N*m"), "field": "load.gravity_torque"}
        out["gravity_phase"] = {"value": phi, "sd": sd_phi, "unit": "rad", "field": "load.gravity_phase"}
    k0 = keys.index("load_const")
    const = ld.load_torque + c["load_const"]
    if "load_lin" in c:
        k = ld.spring_stiffness + c["load_lin"]
        kl = keys.index("load_lin")
        out["spring_stiffness"] = {"value": k, "sd": sd(cov, kl), "unit": unit("N*m/rad"),
                                   "field": "load.spring_stiffness", "delta": float(c["load_lin"])}
        # spring zero kept; its constant part moves into load_torque
        const = const + ld.spring_stiffness * ld.spring_zero - k * ld.spring_zero
    out["load_torque"] = {"value": const, "sd": sd(cov, k0), "unit": unit("N*m"), "field": "load.load_torque",
                          "delta": float(const - ld.load_torque)}
    return out


FORMS = Forms(variants=variants, excited=excited, to_params=to_params)
