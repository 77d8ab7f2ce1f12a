"""Ordinary least squares with the estimate's covariance: the small fits of the routes beside the stages (the
torque balance, the voltage-mode route) and of the base-model check share this one."""

from __future__ import annotations

import numpy as np


def ols(X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(coef, cov, residual)`` of ``y ≈ X coef``: the covariance is s² (XᵀX)⁻¹ with s² the residual variance
    on ``len(y) - columns`` degrees of freedom (at least 1); NaN where XᵀX is singular."""
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    s2 = float(r @ r) / max(1, len(y) - X.shape[1])
    try:
        cov = s2 * np.linalg.inv(X.T @ X)
    except np.linalg.LinAlgError:
        cov = np.full((X.shape[1], X.shape[1]), np.nan)
    return coef, cov, r
