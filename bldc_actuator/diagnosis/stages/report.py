"""Stage 6, report: one finding per accepted effect with its evidence and its held-out before/after in the
metric that suits it, the final model's simulated before/after (short-window replay of the held-out windows,
full-length thermal simulation), aliases, and the :class:`..report.DiagnosisReport` that renders JSON, markdown
and plots. :func:`run` is the entry point; nothing is decided here.
"""

from __future__ import annotations

import time

from .. import candidates as cands
from .. import locate as loc_mod
from .. import refit
from ..report import DiagnosisReport
from ..selection import fit_model
from .data import Judgement, Model, Say, Search
from .search import ee_metrics, rms


def not_checkable(s: Search) -> DiagnosisReport:
    """The report when no model equation can be evaluated."""
    return DiagnosisReport(channels=sorted(s.ctx.have), findings=[], rejected=[], windows=[],
                           data_issues=s.data_issues,
                           not_checkable=[{"effect": n, "reason": "needs current and velocity or position",
                                           "needs": ["current", "velocity|position"]} for n in s.names],
                           aliases=[], verdict="not checkable: no model equation can be evaluated "
                           "(needs current and velocity or position)", notes=s.ctx.notes)


def _strip(r):
    if not r:
        return r
    return {k: v for k, v in r.items() if k not in ("trace", "per_window")}


def _explained(ctx, sel, a) -> float:
    """Fraction of the nominal residual variance (weighted, training) removed by this effect's columns alone."""
    alone = fit_model(ctx, sel.cols, list(ctx.nuisance) + list(a.variant.keys), sel.weights, sel.iterating)
    num = sum(sel.weights[eq] ** 2 * (sel.base_fit.rss[eq] - alone.rss[eq]) for eq in alone.rss)
    den = sum(sel.weights[eq] ** 2 * sel.base_fit.rss[eq] for eq in alone.rss)
    return float(num / den) if den > 0 else 0.0


def _finding(ctx, sel, ff, pars, lib, located, not_sim, a) -> dict:
    """One accepted equation-error effect: parameters, evidence, held-out before/after."""
    cand = lib[a.effect]
    ho = ctx.holdout_dec
    others = [k for k in ff.keys if k not in a.added]
    f_without = fit_model(ctx, sel.cols, others, sel.weights, sel.iterating)
    eqs = [eq for eq in cand.equations if eq in ctx.blocks and any(sel.cols[k].get(eq) is not None for k in a.added)]
    metrics = []
    for eq in eqs:
        B = ctx.blocks[eq]
        rows = B.rows(ho, "holdout")
        metrics.append({"metric": f"{eq} equation-error residual RMS (held-out)", "unit": B.unit,
                        "before": rms(f_without.resid[eq][rows]), "after": rms(sel.final_fit.resid[eq][rows])})
    if a.effect in ("cogging_torque", "electrical_angle_ripple") and "mechanical" in ctx.blocks:
        rows = ctx.blocks["mechanical"].rows(ho, "holdout")
        th = ctx.dsig("theta")[rows]
        o = int(a.variant.hyper["order"])
        b0 = loc_mod.angle_synchronous(th, f_without.resid["mechanical"][rows], o)
        b1 = loc_mod.angle_synchronous(th, sel.final_fit.resid["mechanical"][rows], o)
        metrics.insert(0, {"metric": f"angle-synchronous mechanical residual RMS at order {o} (held-out)",
                           "unit": ctx.blocks["mechanical"].unit, "before": b0["rms"], "after": b1["rms"]})
    p = pars.get(a.effect, {})
    visible = {k: v for k, v in p.items() if not k.startswith("_")}
    finding = {
        "effect": a.effect,
        "description": cand.description,
        "form": a.variant.label,
        "parameters": {k: v["value"] for k, v in visible.items()},
        "uncertainty": {k: v.get("sd") for k, v in visible.items()},
        "units": {k: v.get("unit", "") for k, v in visible.items()},
        "fields": {k: v.get("field") for k, v in visible.items() if v.get("field")},
        "simulated": a.effect not in not_sim,
        "evidence": cands.evidence(a.effect, a.variant, located,
                                   {"explained": _explained(ctx, sel, a), "dbic": a.dbic, "heldout": a.heldout}),
        "held_out": metrics[0] if metrics else {},
        "metrics": metrics,
        "delta_bic": a.dbic,
        "round": a.round,
        "correlations": [c for c in ff.correlations if c["a"] in a.added or c["b"] in a.added],
    }
    if a.effect == "torque_constant_error":
        finding["frame_factor"] = p.get("frame_factor", {}).get("value", "none")
    nl = ff.nonlinear.get(a.effect, {})
    if nl.get("omega_s_corr_amplitude") is not None and abs(nl["omega_s_corr_amplitude"]) > 0.9:
        finding["correlations"].append({"a": "stribeck_velocity", "b": "stribeck_friction",
                                        "correlation": round(nl["omega_s_corr_amplitude"], 3)})
    return finding


def _aliases(sel, lib) -> list[dict]:
    out = []
    for a in sel.aliases:
        A, B = a["effects"]
        exp = lib[A].confusable.get(B) or lib[B].confusable.get(A) or "record data that excites them differently"
        out.append({"effects": [A, B], "chosen": a["chosen"], "correlation": a["correlation"],
                    "message": f"cannot tell {A} from {B} with this data (their fitted contributions "
                               f"correlate {a['correlation']:.2f}); "
                               + (f"{a['chosen']} was kept" if a["chosen"] else
                                  "neither was kept: together they fit implausible values")
                               + (f" ({a['decided_by']})" if a.get("decided_by") else ""),
                    "experiment": exp})
    return out


def run(signals, params, s: Search, j: Judgement, m: Model, options, say: Say, t_start: float) -> DiagnosisReport:
    t0 = time.perf_counter()
    ctx, sel, lib = s.ctx, j.selection, s.lib
    findings = [_finding(ctx, sel, j.final, j.parameters, lib, s.located, m.not_simulated, a) for a in sel.accepted]
    findings += j.special["findings"]
    for f in findings:
        if f["effect"] in j.simulation:
            f["simulation"] = j.simulation[f["effect"]]
    replay_ho = None
    if options.replay and s.starts_holdout:
        before, after = refit.replay(ctx, [params, m.params], s.starts_holdout, options.window_s)
        replay_ho = {"before": before, "after": after}
        for f in findings:
            if f["effect"] in ("thermal_parameters", "iron_loss"):
                continue
            f["metrics"].append({"metric": f"short-window simulation speed error RMS (held-out, "
                                           f"{options.window_s:g} s windows, all accepted effects)",
                                 "unit": "rad/s", "before": before["velocity_rms"], "after": after["velocity_rms"]})
            f["metrics"].append({"metric": "short-window simulation current error RMS (held-out)", "unit": "A",
                                 "before": before["current_rms"], "after": after["current_rms"]})
    thermal_cmp = None
    if any(c in ctx.have for c in ("winding_temperature", "housing_temperature")) and "i_q" in ctx.sig:
        tb = refit.thermal_error(ctx, params)
        ta = refit.thermal_error(ctx, m.params, extra_heat=j.special.get("extra_heat"))
        thermal_cmp = {"before": {k: v for k, v in tb.items() if k != "sim"},
                       "after": {k: v for k, v in ta.items() if k != "sim"}}
    timing = {**s.timing, **m.timing, "show": time.perf_counter() - t0}
    timing["total"] = time.perf_counter() - t_start
    names = [f["effect"] for f in findings]
    verdict = ("missing physics found: " + ", ".join(names)) if names else \
        "nothing missing: no candidate effect passed both the ΔBIC and the held-out gate"
    unreproduced = sorted({v.effect for v in j.verdicts if "does not reproduce" in v.message})
    why = next((j.simulation[e]["verdict"].split(": ", 1)[1] for e in unreproduced
                if "does not reproduce" in j.simulation.get(e, {}).get("verdict", "")), None)
    if why:
        msg = (f"equation error alone suggests {', '.join(unreproduced)}, but {why}: check the logging rate against "
               f"the control loops' bandwidth and the drive model")
        verdict = f"{verdict}; not shown in simulation: {msg}" if names else f"nothing shown in simulation: {msg}"
    nominal_m, final_m = ee_metrics(ctx, sel.base_fit), ee_metrics(ctx, sel.final_fit)
    oe = m.output_error
    compare = {"equation_error": {eq: {"nominal": nominal_m[eq], "updated": final_m[eq]} for eq in ctx.blocks},
               "replay": {"all_windows_nominal": _strip(s.replay_nominal),
                          "holdout": {k: _strip(v) for k, v in replay_ho.items()} if replay_ho else None},
               "thermal": thermal_cmp,
               "output_error_refit": {k: v for k, v in oe.items() if k != "params"} if oe else None,
               "alias_simulation": j.alias_simulation or None}
    say(f"6/6 show: {verdict} ({timing['show']:.2f} s; total {timing['total']:.2f} s)")
    rejected = sel.rejected + j.special["rejected"] + [
        {"effect": v.effect, "form": "practical significance", "verdict": v.kind, "reason": v.message}
        for v in j.verdicts]
    base = m.base
    report = DiagnosisReport(
        channels=sorted(ctx.have), findings=findings, windows=s.windows, rejected=rejected,
        data_issues=s.data_issues, not_checkable=sel.not_checkable + j.special["not_checkable"],
        aliases=_aliases(sel, lib), verdict=(base["message"] + "; " + verdict) if base else verdict,
        notes=ctx.notes + m.notes + ([base["message"]] if base else []), compare=compare, locate=s.located,
        rounds=sel.rounds, correlations=j.final.correlations, not_simulated=m.not_simulated, timing=timing,
        updated_params=m.params, nominal_params=params,
        setup={"rate_hz": ctx.fs, "cutoff_hz": ctx.dec.fc, "decimation": ctx.dec.q, "samples": int(len(ctx.t)),
               "decimated_samples": int(len(ctx.dec)), "holdout": "separate recording" if options.holdout_signals
               is not None else f"{options.holdout:g} of the time (interleaved blocks)",
               "gate": vars(options.gate), "effects_tested": s.names,
               "source": getattr(signals, "source", "")})
    report._internals = {"ctx": ctx, "sel": sel, "ff": j.final, "nominal_fit": sel.base_fit, "replay_ho": replay_ho,
                         "thermal": j.special}
    return report
