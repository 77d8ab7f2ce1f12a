"""Steady-state operating points: torque constant, friction and the frame factor from a torque map.

For tables of operating points (dynamometer maps, quasi-static velocity steps) the time-series pipeline
does not apply (no derivatives, no dynamics). At a steady point the torque balance is algebraic, motor
side, SI (the same terms as :mod:`bldc_actuator.model`, built with :mod:`bldc_actuator.effects`):

    τ_sensor / N = K_t · i_q − τ_c · s(ω) − τ_a · |s(ω)| − b · ω            (s = sign ω)

``τ_sensor`` [N·m] at the output (gear ratio N), ``i_q`` [A] as the drive reports it (its own frame),
ω [rad/s] motor side. The friction columns are :func:`effects.friction_basis` (Coulomb, asymmetry) and
:func:`effects.viscous_basis` (ω); ``τ_a`` is only fitted when the data move in both directions (with one
direction it is the same column as ``τ_c``). Linear least squares; uncertainties from the residual
variance and (XᵀX)⁻¹. Held-out: grouped k-fold over blocks (speed set-points or files) — every block is
predicted by a fit that did not see it; "before" is the nominal model (K_t_q of the parameter file,
no friction), "after" the fitted one.

The fitted K_t divided by a reference K_t (the preset's power-invariant K_t_q, or one from Kv) is
matched to the frame factors of :data:`.candidates.FRAME_FACTORS` (√(3/2), 2/√3 …).

The voltage equation at steady speed ``v_q = R i_q + K_b ω`` is fitted the same way (:func:`fit_voltage_map`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg

from .. import effects
from .frame.candidates import FRAME_FACTORS, match_frame_factor


@dataclass
class LinearFit:
    """A linear steady-state fit: coefficients ± standard error, in-sample and held-out RMS."""

    names: list[str]
    coef: np.ndarray
    sd: np.ndarray
    n: int
    rms_train: float
    heldout_before: float          #: held-out RMS of the nominal model [unit]
    heldout_after: float           #: held-out RMS of the fitted model (grouped k-fold) [unit]
    unit: str
    n_blocks: int
    notes: list[str] = field(default_factory=list)

    def value(self, name: str) -> float:
        return float(self.coef[self.names.index(name)])

    def stderr(self, name: str) -> float:
        return float(self.sd[self.names.index(name)])

    def to_dict(self) -> dict:
        return {"parameters": {k: float(v) for k, v in zip(self.names, self.coef)},
                "uncertainty": {k: float(v) for k, v in zip(self.names, self.sd)},
                "n": self.n, "rms_train": self.rms_train, "unit": self.unit,
                "held_out": {"metric": f"grouped {self.n_blocks}-fold held-out RMS", "unit": self.unit,
                             "before": self.heldout_before, "after": self.heldout_after},
                "notes": list(self.notes)}


def _lstsq(X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    coef, *_ = linalg.lstsq(X, y)
    r = y - X @ coef
    dof = max(len(y) - X.shape[1], 1)
    s2 = float(r @ r) / dof
    cov = s2 * linalg.pinv(X.T @ X)
    return coef, np.sqrt(np.maximum(np.diag(cov), 0.0)), math.sqrt(float(np.mean(r ** 2)))


def speed_blocks(omega: np.ndarray, n_blocks: int = 5) -> np.ndarray:
    """Block label per point: ``n_blocks`` contiguous ranges of |ω| with equal counts (held-out by speed)."""
    order = np.argsort(np.abs(omega), kind="stable")
    labels = np.empty(len(omega), int)
    for k, idx in enumerate(np.array_split(order, n_blocks)):
        labels[idx] = k
    return labels


def _grouped_cv(X, y, y_nominal_resid, groups) -> tuple[float, float]:
    """RMS of held-out residuals: nominal model (given) and the fit trained without each group."""
    res = np.empty_like(y)
    for g in np.unique(groups):
        te = groups == g
        c, *_ = linalg.lstsq(X[~te], y[~te])
        res[te] = y[te] - X[te] @ c
    return math.sqrt(float(np.mean(y_nominal_resid ** 2))), math.sqrt(float(np.mean(res ** 2)))


def fit_torque_map(tau_out, i_q, omega, *, kt_nominal: float, gear_ratio: float = 1.0, groups=None,
                   n_blocks: int = 5, viscous: bool = True, min_speed: float = 0.0) -> LinearFit:
    """Fit ``τ/N = K_t i_q − τ_c s − [τ_a |s|] − b ω`` on steady points (see module doc).

    tau_out [N·m, output], i_q [A, drive frame], omega [rad/s, motor side]; ``kt_nominal`` [N·m/A] the
    model's constant used for "before"; ``groups`` block labels for the held-out folds (default: speed
    blocks); points with |ω| ≤ ``min_speed`` or any NaN are left out (counted in ``notes``).
    """
    tau_out, i_q, omega = (np.asarray(a, float) for a in (tau_out, i_q, omega))
    ok = np.isfinite(tau_out) & np.isfinite(i_q) & np.isfinite(omega) & (np.abs(omega) > min_speed)
    notes = []
    if (~ok).sum():
        notes.append(f"{int((~ok).sum())} point(s) left out (masked or |ω| ≤ {min_speed:g} rad/s)")
    y = tau_out[ok] / gear_ratio
    w, i = omega[ok], i_q[ok]
    fb = effects.friction_basis(w, 1.0)           # columns s, |s|, Stribeck (unused here)
    cols, names = [i, -fb[:, 0]], ["torque_constant", "coulomb_friction"]
    if (w > 0).any() and (w < 0).any() and min((w > 0).mean(), (w < 0).mean()) > 0.05:
        cols.append(-fb[:, 1])
        names.append("friction_asymmetry")
    else:
        notes.append("one direction of motion only: Coulomb friction and a constant torque offset are the "
                     "same column (asymmetry not identifiable)")
    if viscous:
        cols.append(-effects.viscous_basis(w)[:, 0])
        names.append("viscous_damping")
    X = np.column_stack(cols)
    coef, sd, rms = _lstsq(X, y)
    groups = speed_blocks(w, n_blocks) if groups is None else np.asarray(groups)[ok]
    before, after = _grouped_cv(X, y, y - kt_nominal * i, groups)
    return LinearFit(names, coef, sd, int(ok.sum()), rms, before, after, "N*m (motor side)",
                     len(np.unique(groups)), notes)


def fit_voltage_map(v_q, i_q, omega, *, r_nominal: float, kb_nominal: float, groups=None,
                    n_blocks: int = 5) -> LinearFit:
    """Fit ``v_q = R i_q + K_b ω`` on steady points [V]; "before" uses the nominal R and K_b."""
    v_q, i_q, omega = (np.asarray(a, float) for a in (v_q, i_q, omega))
    ok = np.isfinite(v_q) & np.isfinite(i_q) & np.isfinite(omega)
    X = np.column_stack([i_q[ok], omega[ok]])
    y = v_q[ok]
    coef, sd, rms = _lstsq(X, y)
    groups = speed_blocks(omega[ok], n_blocks) if groups is None else np.asarray(groups)[ok]
    before, after = _grouped_cv(X, y, y - r_nominal * i_q[ok] - kb_nominal * omega[ok], groups)
    return LinearFit(["phase_resistance", "back_emf_constant"], coef, sd, int(ok.sum()), rms, before, after,
                     "V (q-axis)", len(np.unique(groups)))


def frame_factor(k_fit: float, k_sd: float, k_reference: float) -> dict:
    """Ratio fitted / reference constant, the frame factor it matches (within max(2 %, 2σ)) and the
    nearest named factor with its deviation (so a near miss is visible)."""
    ratio = k_fit / k_reference
    sigma = k_sd / k_reference
    factors = {"1": 1.0, **FRAME_FACTORS}
    nearest = min(factors.items(), key=lambda kv: abs(math.log(ratio / kv[1])))
    match = "1" if abs(ratio - 1.0) <= max(0.02, 2.0 * sigma) else match_frame_factor(ratio, sigma)
    return {"ratio": ratio, "ratio_sd": sigma, "match": match,
            "nearest": nearest[0], "nearest_value": nearest[1],
            "deviation_from_nearest": ratio / nearest[1] - 1.0}
