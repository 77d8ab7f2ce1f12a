"""Base model first (issue #7): before naming effects, check whether the nominal core parameters are far off.

A recording of a different motor than the nominal parameters describe (the demo's default motor diagnosed
against ``--params ak80_9``) must not come out as one tidy effect. From the voltage equation alone —
``v_q = R i_q + L di_q/dt + K ω`` (the d-axis coupling is small at the speeds where this is fitted) — a free
least-squares fit gives R, L and K without any effect terms. When two or more of them differ from nominal by
more than ``limit`` (default 15 %), the report says so, shows the re-identified core, and asks for it to be used
as the nominal before attributing effects. One entry point, :func:`check`; plain data out.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def check(ctx, limit: float = 0.15) -> dict[str, Any] | None:
    """None when the voltage equation is not available or the core agrees; else
    ``{"far_off": [...], "identified": {name: value}, "nominal": {...}, "message": str}``."""
    S = ctx.sig
    if not all(k in S for k in ("v_q", "i_q", "di_dt", "omega")):
        return None
    X = np.column_stack([S["i_q"], S["di_dt"], S["omega"]])
    y = np.asarray(S["v_q"], dtype=float)
    good = np.all(np.isfinite(X), axis=1) & np.isfinite(y)
    X, y = X[good], y[good]
    if len(y) < 50 or np.std(X[:, 2]) == 0 or np.std(X[:, 0]) == 0:
        return None
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    if coef[0] <= 0 or coef[2] <= 0:
        return None   # R or K not positive: current and speed too alike in this data to separate them
    m = ctx.params.motor
    nominal = {"phase_resistance": m.phase_resistance, "torque_constant_q": m.torque_constant_q}
    identified = {"phase_resistance": float(coef[0]), "torque_constant_q": float(coef[2])}
    # the inductance is only checked where the recording resolves it
    if not getattr(ctx, "nuisance", None):
        nominal["q_inductance"] = m.q_inductance
        identified["q_inductance"] = float(coef[1])
    far = [k for k in nominal if nominal[k] > 0 and abs(identified[k] / nominal[k] - 1.0) > limit]
    if len(far) < 2:
        return None
    parts = ", ".join(f"{k} {identified[k]:.4g} (nominal {nominal[k]:.4g}, x{identified[k] / nominal[k]:.2f})"
                      for k in far)
    return {"far_off": far, "identified": identified, "nominal": nominal, "limit": limit,
            "message": f"base model far off: the voltage equation alone gives {parts}; these are not effects "
                       f"to attribute — re-identify the core (or pick the right motor's parameters) and diagnose "
                       f"again against it"}
