"""Stage 3, search (equation error): where do recording and model differ, and which candidate terms explain it?

:func:`run`: the recording into the model's frame (derivatives, parallel low-pass, decimation, held-out blocks:
:func:`..equation_error.prepare`), the nominal model's equation-error residuals and its short-window replay, the
residual located (speed / current / temperature / headroom bins, change points, angle orders), forward
selection with ΔBIC + held-out gate (:func:`..selection.forward_select`), and the output-error searches of the
thermal network and the drive's voltage limit. Nothing here decides acceptance in the simulator: that is
:mod:`.judge`.
"""

from __future__ import annotations

import time

import numpy as np

from ...params import ActuatorParams
from .. import candidates as cands
from .. import equation_error as ee
from .. import locate as loc_mod
from .. import refit
from ..selection import forward_select
from .data import Say, Search


def rms(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2))) if len(x) else float("nan")


def ee_metrics(ctx: ee.Context, fit: ee.Fit) -> dict[str, dict[str, float]]:
    """Equation-error residual RMS per equation on training and held-out rows."""
    ho = ctx.holdout_dec
    out = {}
    for eq, B in ctx.blocks.items():
        r = fit.resid[eq]
        out[eq] = {"train_rms": rms(r[B.rows(ho, "train")]), "holdout_rms": rms(r[B.rows(ho, "holdout")]),
                   "unit": B.unit}
    return out


def _issue_dict(issue) -> dict:
    if hasattr(issue, "to_dict"):
        return issue.to_dict()
    if isinstance(issue, dict):
        return issue
    return {k: getattr(issue, k, None) for k in ("kind", "channel", "count", "first_time", "detail", "action")}


def run(signals, params: ActuatorParams, options, say: Say) -> Search | None:
    """Search ``signals`` (cleaned) against ``params``; None when no model equation can be evaluated (then the
    caller reports "not checkable")."""
    names = options.validated_effects()
    lib = cands.library()
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    parts = [(signals, False)]
    if options.holdout_signals is not None:
        parts.append((options.holdout_signals, True))
    ctx = ee.prepare(parts, params, fc=options.cutoff_hz, holdout=options.holdout)
    timing["prepare"] = time.perf_counter() - t0
    say(f"1/6 prepare: {len(ctx.t)} samples at {ctx.fs:.4g} Hz, {len(ctx.segments)} segment(s), "
        f"low-pass {ctx.dec.fc:.4g} Hz, decimated x{ctx.dec.q} -> {len(ctx.dec)} samples; "
        f"equations: {', '.join(ctx.blocks) or 'none'} ({timing['prepare']:.2f} s)")
    issues = [_issue_dict(i) for i in getattr(signals, "issues", [])]
    if options.holdout_signals is not None:
        issues += [dict(_issue_dict(i), recording="holdout") for i in getattr(options.holdout_signals, "issues", [])]
    if not ctx.blocks:
        return Search(ctx=ctx, names=names, lib=lib, nominal_fit=None, located={}, windows=[], selection=None,
                      special={"findings": [], "rejected": [], "not_checkable": []}, data_issues=issues,
                      timing=timing)

    # the nominal model: equation error and short-window replay
    t0 = time.perf_counter()
    nominal_cols = {k: ctx.column(k, b) for k, b in ctx.nuisance.items()}
    nominal_fit = ee.fit_columns(ctx, nominal_cols, list(ctx.nuisance), {eq: 1.0 for eq in ctx.blocks})
    replay_nominal, starts_ho = None, []
    if options.replay:
        starts_all = refit.windows(ctx, options.window_s, options.max_windows, "all")
        starts_ho = refit.windows(ctx, options.window_s, options.max_windows, "holdout")
        replay_nominal = refit.replay(ctx, [params], starts_all, options.window_s)[0] if starts_all else None
    timing["compare"] = time.perf_counter() - t0
    msg = ", ".join(f"{eq} RMS {m['train_rms']:.3g}" for eq, m in ee_metrics(ctx, nominal_fit).items())
    if replay_nominal and replay_nominal.get("available"):
        msg += (f"; replay over {replay_nominal['windows']} windows: current RMS {replay_nominal['current_rms']:.3g} A, "
                f"speed RMS {replay_nominal['velocity_rms']:.3g} rad/s")
    say(f"2/6 compare: {msg} ({timing['compare']:.2f} s)")

    # where the residual sits
    t0 = time.perf_counter()
    located = {eq: loc_mod.locate_equation(ctx, eq, nominal_fit.resid[eq]) for eq in ctx.blocks}
    windows = [w for eq in located for w in located[eq]["windows"]]
    timing["locate"] = time.perf_counter() - t0
    peaks = (located.get("mechanical", {}).get("order_spectrum") or {}).get("peaks", [])
    say(f"3/6 locate: {len(windows)} window(s) where the residual level changes; angle-order peaks "
        f"{[p['order'] for p in peaks[:4]]} ({timing['locate']:.2f} s)")

    # which terms explain it
    t0 = time.perf_counter()
    linear = [n for n in names if n not in cands.SPECIAL]
    sel = forward_select(ctx, located, lib, linear, options.gate, progress=lambda m: say(f"4/6 attribute: {m}"))
    special = refit.thermal_select(ctx, [n for n in names if n in cands.THERMAL], lib, options.gate)
    vsat = refit.voltage_saturation_check(ctx, lib, options.gate, "voltage_saturation" in names)
    for k in ("findings", "rejected", "not_checkable"):
        special[k] = special[k] + vsat[k]
    timing["attribute"] = time.perf_counter() - t0
    return Search(ctx=ctx, names=names, lib=lib, nominal_fit=nominal_fit, located=located, windows=windows,
                  selection=sel, special=special, starts_holdout=starts_ho, replay_nominal=replay_nominal,
                  data_issues=issues, timing=timing)
