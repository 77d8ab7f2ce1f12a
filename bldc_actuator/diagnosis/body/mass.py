"""Body effects as candidates: a body's mass error, fitted jointly over every joint (one Δm, many equations).

Each joint's mechanical equation with the nominal body's torque as its known load (:mod:`.motion`) leaves the
residual ``r_j = i_j - P_j / K_j`` [A]. A body b that is Δm heavier than the MJCF adds ``Δm · c_bj / (N_j K_j)``
to it, ``c_bj`` the change of joint j's inverse-dynamics torque per kg (:meth:`.inverse.BodyModel.mass_column`).
The fit stacks every joint's equation (each weighted by its own noise level) with per-joint nuisance columns of
the actuator's own effects that could otherwise lend a body's torque to a wrong parameter or the other way round
(Coulomb friction, viscous drag, rotor inertia, the torque constant, a constant load: the frame's columns,
:mod:`..frame.candidates`), and one column per candidate body shared by all joints.

A body is named when its column lowers the BIC by the gate's threshold, improves the held-out equation error by
the gate's gain, is identified (relative uncertainty below ``max_relative_uncertainty``), moves the mass by more
than ``tolerance`` of nominal, AND explains the data better (BIC) than per-joint gravity loads (a sinusoid of each
joint's own angle and a constant, the single-joint route's load form) would: the finding is a mass, not a per-joint
load. Bodies are added greedily (the best first), so two wrong masses are two findings.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..effects import Route, registry
from ..effects.coulomb_friction import col_fric_sign
from ..effects.position_dependent_load import col_load
from ..effects.viscous_friction import col_viscous
from ..frame import equation_error as ee
from ..frame.selection import GateConfig
from .inverse import BodyMass, BodyModel
from .motion import JointMotion

EFFECT = registry.one(lambda e: e.route is Route.BODY)
#: the single-joint route's load form a body's mass would be taken for there
PER_JOINT_LOAD = registry.by_field("load.gravity_torque")[0]

#: always fitted on every joint (cheap, never aliased with a body's mass)
_NUISANCE = (("coulomb", col_fric_sign), ("viscous", col_viscous), ("const", col_load("const")))


def _scale_columns(ctx, qdd_s: np.ndarray, tau_raw: np.ndarray, tau_s: np.ndarray) -> dict[str, np.ndarray]:
    """A joint's own scale terms, which could take a body's torque on that one joint and so compete with the bodies
    in the same selection: its torque constant (the column ``-P``, :func:`..frame.candidates.col_kt`) and its rotor
    inertia (``ω'``), both [N·m at the motor] with the acceleration of the smoothed motion: ``P`` itself holds the
    twice-differenced encoder noise that is also in the residual, and a column sharing the residual's noise fits
    that noise (the frame's instruments answer the same problem for its own columns)."""
    S = ctx.sig
    N = ctx.params.gear.gear_ratio
    J = ctx.params.motor.rotor_inertia
    a_s = N * qdd_s
    P_s = S["P"] - J * (S["omega_dot"] - a_s) - (tau_raw - tau_s) / N
    return {"kt": -P_s, "inertia": a_s}
_LOADS = (("sin", col_load("sin")), ("cos", col_load("cos")))


@dataclass(frozen=True)
class BodyFinding:
    """One body's mass error: the finding "body X is Δm kg heavier than the model"."""

    body: str
    mass_nominal: float           #: [kg] the MJCF's
    delta_mass: float             #: [kg] fitted (positive: heavier than the model)
    delta_mass_sd: float          #: [kg] one standard deviation
    delta_bic: float              #: against the model without it (every earlier finding kept)
    held_out: dict                #: equation-error RMS on held-out data without/with it (weighted, relative units)
    per_joint_load: dict          #: the per-joint gravity loads in its place: their ΔBIC and held-out after
    joints: tuple[str, ...]       #: the recorded joints whose torque it moves
    accepted: bool = True
    reason: str = ""
    effect: str = EFFECT.name

    @property
    def mass(self) -> float:
        return self.mass_nominal + self.delta_mass

    def sentence(self) -> str:
        word = "heavier" if self.delta_mass > 0 else "lighter"
        ho = self.held_out
        return (f"body {self.body!r} is {abs(self.delta_mass):.4g} ± {self.delta_mass_sd:.2g} kg {word} than the model "
                f"({self.mass_nominal:.4g} -> {self.mass:.4g} kg; ΔBIC {self.delta_bic:.1f}; held-out equation error "
                f"{ho['before']:.4g} -> {ho['after']:.4g} ({100 * ho['change']:+.1f} %); per-joint gravity loads in its "
                f"place: ΔBIC {self.per_joint_load['delta_bic']:.1f}, held-out {100 * self.per_joint_load['change']:+.1f} %)")

    def to_dict(self) -> dict[str, Any]:
        return {"effect": self.effect, "body": self.body, "parameters": {"delta_mass": self.delta_mass,
                                                                         "mass": self.mass},
                "uncertainty": {"delta_mass": self.delta_mass_sd, "mass": self.delta_mass_sd},
                "units": {"delta_mass": "kg", "mass": "kg"}, "mass_nominal": self.mass_nominal,
                "delta_bic": self.delta_bic, "held_out": dict(self.held_out),
                "per_joint_load": dict(self.per_joint_load), "joints": list(self.joints),
                "accepted": self.accepted, "reason": self.reason, "sentence": self.sentence()}


@dataclass
class BodyDiagnosis:
    """The body's findings (accepted), the candidates tried and not accepted, and notes."""

    findings: list[BodyFinding] = field(default_factory=list)
    rejected: list[BodyFinding] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    joints_used: tuple[str, ...] = ()

    @property
    def changes(self) -> dict[str, float]:
        return {f.body: f.delta_mass for f in self.findings}

    def to_dict(self) -> dict[str, Any]:
        return {"findings": [f.to_dict() for f in self.findings], "rejected": [f.to_dict() for f in self.rejected],
                "notes": list(self.notes), "joints_used": list(self.joints_used)}


@dataclass
class _Joint:
    name: str
    ctx: Any
    y: np.ndarray                  #: decimated nominal residual [A]
    train: np.ndarray
    hold: np.ndarray
    w: float = 1.0


def _stack(parts: list[_Joint], per_joint: dict[str, list[np.ndarray]], shared: list[list[np.ndarray]], which: str):
    """Rows of every joint (``which``: train | hold), columns: each joint's own block, then the shared ones."""
    widths = [len(per_joint[p.name]) for p in parts]
    n_own = sum(widths)
    Xs, ys, owner = [], [], []
    off = 0
    for j, p in enumerate(parts):
        rows = p.train if which == "train" else p.hold
        X = np.zeros((int(rows.sum()), n_own + len(shared)))
        for c, col in enumerate(per_joint[p.name]):
            X[:, off + c] = col[rows]
        for s, cols in enumerate(shared):
            X[:, n_own + s] = cols[j][rows]
        off += widths[j]
        Xs.append(p.w * X)
        ys.append(p.w * p.y[rows])
        owner.append(np.full(int(rows.sum()), j))
    return np.vstack(Xs), np.concatenate(ys), np.concatenate(owner)


@dataclass
class _Fit:
    beta: np.ndarray
    cov: np.ndarray
    rss: np.ndarray              #: per joint, training
    n_eff: np.ndarray            #: per joint
    ho_rms: float                #: weighted held-out RMS
    k: int


def _fit(parts, per_joint, shared) -> _Fit:
    X, y, owner = _stack(parts, per_joint, shared, "train")
    scale = np.sqrt((X ** 2).sum(axis=0))
    scale[scale == 0] = 1.0
    bn, *_ = np.linalg.lstsq(X / scale, y, rcond=1e-10)
    beta = bn / scale
    r = y - X @ beta
    rss = np.array([float(r[owner == j] @ r[owner == j]) for j in range(len(parts))])
    taus = np.array([ee.integrated_autocorrelation_time(r[owner == j]) for j in range(len(parts))])
    n = np.array([float((owner == j).sum()) for j in range(len(parts))])
    s2 = float(r @ r) / max(len(y) - X.shape[1], 1)
    cov = np.linalg.pinv((X / scale).T @ (X / scale)) * s2 * float(np.mean(taus)) / np.outer(scale, scale)
    Xh, yh, _ = _stack(parts, per_joint, shared, "hold")
    rh = yh - Xh @ beta
    return _Fit(beta, cov, rss, n / taus, float(np.sqrt(np.mean(rh ** 2))) if len(rh) else float("nan"), X.shape[1])


def _dbic(base: _Fit, new: _Fit) -> float:
    gain = float(np.sum(new.n_eff * np.log(np.maximum(base.rss, 1e-300) / np.maximum(new.rss, 1e-300))))
    return gain - (new.k - base.k) * math.log(max(2.0, float(np.sum(new.n_eff))))


#: the mass columns' motion is low-passed here [Hz] (at least; :func:`_smoothed`)
MASS_COLUMN_BAND_HZ = 20.0


def _smoothed(motion: JointMotion, ctx) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The motion the mass columns are built from: positions, speeds and accelerations low-passed (zero phase) at
    ``max(MASS_COLUMN_BAND_HZ, fc/5)``. The acceleration from two differences of an encoder angle is mostly
    noise at the equation's cut-off; a regressor that noisy is biased toward zero (errors in variables: -13 % on
    a 0.2 kg payload at 1 kHz), while the joint's motion and the body's torque it moves lie far below this band."""
    fc = max(MASS_COLUMN_BAND_HZ, ctx.dec.fc / 5.0)
    return tuple(ctx.dec.lowpass(x, fc) for x in (motion.q, motion.qd, motion.qdd))


def fit_masses(contexts: dict, body: BodyModel, motion: JointMotion, *, gate: GateConfig | None = None,
               tolerance: float = 0.05, max_relative_uncertainty: float = 0.5, max_bodies: int = 3,
               tau: np.ndarray | None = None) -> BodyDiagnosis:
    """The body's mass errors from the joints' prepared equations (``contexts``: recorded joint ->
    :class:`..frame.equation_error.Context` built with the nominal body's torque as its known load; ``tau``: that
    torque, (n, k) in ``motion.joints`` order, computed when not given)."""
    gate = gate or GateConfig()
    out = BodyDiagnosis()
    parts: list[_Joint] = []
    for name in motion.joints:
        ctx = contexts.get(name)
        if ctx is None or "mechanical" not in ctx.blocks:
            out.notes.append(f"joint {name}: no mechanical equation (current and motion): not used for the body")
            continue
        if "torque" in ctx.have:
            out.notes.append(f"joint {name}: a torque sensor supplies its load; its equation does not see the "
                             "body's model, so it does not enter the body's fit (the sensor against the body's "
                             "inverse dynamics is not yet a body equation)")
            continue
        B = ctx.blocks["mechanical"]
        parts.append(_Joint(name, ctx, B.target, B.rows(ctx.holdout_dec, "train"), B.rows(ctx.holdout_dec, "holdout")))
    out.joints_used = tuple(p.name for p in parts)
    if not parts:
        out.notes.append("no joint's mechanical equation can be used: no body effect can be tested")
        return out
    per_joint = {p.name: [p.ctx.column(("body nuisance", key), b)["mechanical"] for key, b in _NUISANCE]
                 for p in parts}
    # each joint weighted by its own noise after its nuisance fit, so a noisy joint does not outvote the others
    for p in parts:
        X = np.column_stack(per_joint[p.name])[p.train]
        r = p.y[p.train] - X @ np.linalg.lstsq(X, p.y[p.train], rcond=None)[0]
        p.w = 1.0 / ee.robust_std(r)
    base = _fit(parts, per_joint, [])
    loads = {p.name: per_joint[p.name] + [p.ctx.column(("body load", key), b)["mechanical"] for key, b in _LOADS]
             for p in parts}
    k_of = {name: i for i, name in enumerate(motion.joints)}
    columns = {}
    smooth = _smoothed(motion, parts[0].ctx)
    tau_s = body.torques(*smooth)
    for cand in body.candidates():
        dtau = body.mass_column(cand, *smooth, base=tau_s)
        cols = []
        for p in parts:
            j = k_of[p.name]
            n_gear = p.ctx.params.gear.gear_ratio
            cols.append(p.ctx.column(("body mass", cand.name), lambda c, x=dtau[:, j] / n_gear: {"mechanical": x})
                        ["mechanical"])
        if any(np.any(c) for c in cols):
            columns[f"body:{cand.name}"] = (cand, cols)
    tau_raw = body.torques(motion.q, motion.qd, motion.qdd) if tau is None else tau
    for j, p in enumerate(parts):   # each joint's own scale terms, zero on every other joint
        k = k_of[p.name]
        for key, col in _scale_columns(p.ctx, smooth[2][:, k], tau_raw[:, k], tau_s[:, k]).items():
            c = p.ctx.column(("body scale", key), lambda c_, x=col: {"mechanical": x})["mechanical"]
            columns[f"{p.name}:{key}"] = (None, [c if i == j else np.zeros(len(q.y)) for i, q in enumerate(parts)])
    chosen: list[tuple[BodyMass | None, list]] = []
    taken: set[str] = set()
    current = base
    for _ in range(max_bodies + 2 * len(parts)):
        best = None
        for name, (cand, cols) in columns.items():
            if name in taken:
                continue
            f = _fit(parts, per_joint, [c[1] for c in chosen] + [cols])
            d = _dbic(current, f)
            if best is None or d > best[1]:
                best = (name, d, cand, cols, f)
        if best is None:
            break
        name, d, cand, cols, f = best
        if cand is None:             # a joint's own scale term: kept in the body's fit when it earns its place
            if d < gate.bic_threshold:
                break
            out.notes.append(f"fitted beside the bodies: {name} (ΔBIC {d:.1f}; the joint's own diagnosis names it)")
            chosen.append((None, cols))
            taken.add(name)
            current = f
            continue
        dm = float(f.beta[-1])
        sd = float(math.sqrt(max(f.cov[-1, -1], 0.0)))
        change = (f.ho_rms - current.ho_rms) / current.ho_rms if current.ho_rms > 0 else 0.0
        alt = _fit(parts, {p.name: loads[p.name] for p in parts}, [c[1] for c in chosen])
        alt_d = _dbic(current, alt)
        alt_change = (alt.ho_rms - current.ho_rms) / current.ho_rms if current.ho_rms > 0 else 0.0
        reasons = []
        if d < gate.bic_threshold:
            reasons.append(f"ΔBIC {d:.1f} below {gate.bic_threshold:g}")
        if -change < gate.min_heldout_gain:
            reasons.append(f"held-out equation error {100 * change:+.1f} % (needs -{100 * gate.min_heldout_gain:g} %)")
        if not sd < max_relative_uncertainty * abs(dm):
            reasons.append(f"not identified: ±{sd:.2g} kg for {dm:.3g} kg")
        if abs(dm) <= tolerance * cand.mass:
            reasons.append(f"{dm:+.3g} kg is within {100 * tolerance:g} % of the nominal {cand.mass:g} kg")
        if not cand.mass + dm > 0.0:
            reasons.append(f"not physical: {cand.mass:g} {dm:+.3g} kg leaves no mass")
        if alt_d > d:
            reasons.append(f"per-joint gravity loads ({PER_JOINT_LOAD.name}) explain it better (ΔBIC {alt_d:.1f} vs {d:.1f})")
        finding = BodyFinding(cand.name, cand.mass, dm, sd, float(d),
                              {"before": current.ho_rms, "after": f.ho_rms, "change": change,
                               "metric": "weighted RMS of the joints' mechanical equation error (held out)"},
                              {"effect": PER_JOINT_LOAD.name, "delta_bic": float(alt_d), "change": alt_change,
                               "parameters": 2 * len(parts)},
                              cand.joints, accepted=not reasons, reason="; ".join(reasons))
        if reasons:
            out.rejected.append(finding)
            break
        out.findings.append(finding)
        chosen.append((cand, cols))
        taken.add(name)
        current = f
        if len(out.findings) >= max_bodies:
            break
    if out.findings:   # every value from the final model (a term chosen later, a joint's K_t, moves an earlier mass)
        final = _fit(parts, per_joint, [c[1] for c in chosen])
        n_own = sum(len(per_joint[p.name]) for p in parts)
        at = {c[0].name: n_own + i for i, c in enumerate(chosen) if c[0] is not None}
        out.findings = [dataclasses.replace(f, delta_mass=float(final.beta[at[f.body]]),
                                            delta_mass_sd=float(math.sqrt(max(final.cov[at[f.body], at[f.body]], 0.0))))
                        for f in out.findings]
    return out
