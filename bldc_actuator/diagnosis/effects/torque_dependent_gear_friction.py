"""Torque-dependent gear friction: a friction that grows with the torque the gear transmits.

Form (Rhoban's BAM, "Extended Friction Models for the Physics Simulation of Servo Actuators", Duclusaud,
Passault, Padois, Ly 2024, arXiv:2410.08650, model M3 "load-dependent"; bam.readthedocs.io theory/models)::

    |τ_f| = τ_c + μ |τ_gear|  (+ K_v |ω|, the viscous part)        applied as a friction budget (stick/slip)

μ dimensionless. Published identifications of geared hobby/Dynamixel servos need it beside Coulomb + viscous
(μ ≈ 0.27-0.43 for a 288:1 servo, issue #24 symptom 2).

Which torque is "transmitted". BAM writes ``|τ_e - τ_m|`` with τ_m the motor's torque and τ_e the external
(gravity) torque, both at the joint. Here the gear's torque is the motor's electromagnetic torque
``τ_m = K i_q`` (motor side; μ is the same number at the output side, both torques scale by N):

* it is what the motor pushes into the gear's input, known from the logged current (or, without a current
  sensor, from the voltage, i = (v - K ω)/R, :mod:`..voltage_mode`) before any load is identified — τ_e is an
  unknown of the diagnosis (a load is itself a candidate effect), so a column in it could not be built;
* in steady motion and while holding, the mesh carries exactly τ_m less the motor-side drag; accelerating, the
  rotor's own inertia torque J_rotor ω' is not transmitted (only the load's share of the inertia sits behind the
  gear), so the form over-counts by μ |J_rotor ω'|: second order where the motion is slow against the torque, as
  on a position servo holding a load;
* back-driven by a load with no motor torque it gives τ_c alone (BAM's form would grow with |τ_e|): a gear that
  self-locks against its load is not this form;
* while holding a pendulum BAM's |τ_e - τ_m| = 2 |τ_m|, so a BAM fit's K_l is about μ/2 on holding-dominated
  data and μ on free acceleration.

The simulator's term: :func:`bldc_actuator.effects.gear_load_friction` added to the kinetic and the static
friction level in :func:`bldc_actuator.kernel.friction` (the breakaway level grows with the torque at rest, a
drive against no load breaks away beyond τ_s/(1 - μ)), parameter ``effects.gear_load_friction``.

Its column: ``sign(ω) |K i_q|`` (the sign smoothed like the Coulomb column's, tanh(ω/ω_ε)), coefficient the
change of μ. Excited where the torque level varies at similar speed (Coulomb is one level at every torque) AND
the motor brakes as well as drives: while motoring sign(ω)|τ_m| = τ_m, the torque-constant column (a K_t error
× (1 - μ)); only where the torque opposes the motion does gear friction keep opposing the motion while a K_t
error follows the torque.
"""

from __future__ import annotations

import numpy as np

from .forms import Forms, Single, sd, smooth_sign
from .record import Bounds, Effect, Param, Story

EFFECT = Effect(
    name="torque_dependent_gear_friction", rank=35,
    description="torque-dependent gear friction: dry friction growing with the torque the gear transmits, "
                "tau_c + mu |K i_q| (BAM's load-dependent model)",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={
        "coulomb_friction": "move at similar speeds under different torques (two controller gains, a load "
                            "lifted and lowered): Coulomb friction is one level at every torque, gear friction "
                            "grows with |K i_q|",
        "magnetic_saturation": "brake as well as drive at high current: saturation lowers the torque per amp in "
                               "the torque's direction (and grows as i^2), gear friction opposes the motion and "
                               "grows as |i|",
        "torque_constant_error": "brake as well as drive (decelerate, lower a load): while motoring mu|K i| is a "
                                 "torque-constant error x(1 - mu); a K_t error follows the torque's sign, gear "
                                 "friction the speed's"},
    params=(Param("gear_load_friction", "1", "effects.gear_load_friction", (Bounds(lo=0.0, lo_sd=3.0),)),),
    story=Story.CURRENT_TREND,
)

#: the torque must vary at similar speed: median over speed bins of std(|i|)/mean(|i|) at least this
MIN_TORQUE_SPREAD = 0.15
#: share of moving samples where the motor brakes (torque against the motion): below it the column is the
#: torque-constant column but for a handful of samples (the selection's statistics decide above it)
MIN_BRAKING = 0.005
SPEED_BINS = 6


def transmitted_torque(ctx) -> np.ndarray:
    """The gear's torque [N*m, motor side]: the motor's electromagnetic torque K i_q (the regressor's current,
    ``i_col``: the measured current or its instrument)."""
    return ctx.sig["K"] * ctx.sig["i_col"]


def col_gear(ctx):
    return {"mechanical": smooth_sign(ctx.sig["omega_s"], ctx.omega_eps) * np.abs(transmitted_torque(ctx))}


def excited(ctx):
    w = ctx.dsig("omega_s")
    i = ctx.dsig("i_q")
    moving = np.abs(w) > 2 * ctx.omega_eps
    if moving.mean() < 0.05:
        return "needs the rotor to move (it is at rest)"
    wm, im = np.abs(w[moving]), i[moving]
    edges = np.unique(np.percentile(wm, np.linspace(0, 100, SPEED_BINS + 1)))
    spreads = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = np.abs(im[(wm >= lo) & (wm <= hi)])
        if sel.size >= 10 and sel.mean() > 0:
            spreads.append(float(np.std(sel) / sel.mean()))
    spread = float(np.median(spreads)) if spreads else 0.0
    if spread < MIN_TORQUE_SPREAD:
        return (f"needs different torque levels at similar speeds (|i_q| spread {100 * spread:.0f} % of its mean "
                f"within speed bins, < {100 * MIN_TORQUE_SPREAD:.0f} %)")
    braking = float(np.mean(np.sign(im) * np.sign(w[moving]) < 0))
    if braking < MIN_BRAKING:
        return (f"needs the motor to brake as well as drive (torque against the motion in {100 * braking:.2f} % of "
                f"moving samples, < {100 * MIN_BRAKING:g} %): while motoring it is a torque-constant error")
    return None


def to_params(coef, cov, keys, variant, ctx):
    c = float(coef[0])
    value = ctx.params.effects.gear_load_friction + c
    return {"gear_load_friction": {"value": value, "sd": sd(cov, 0), "unit": "",
                                   "field": "effects.gear_load_friction" if value >= 0 else None, "delta": c}}


FORMS = Forms(variants=Single({"gear_load": col_gear}), excited=excited, to_params=to_params)
