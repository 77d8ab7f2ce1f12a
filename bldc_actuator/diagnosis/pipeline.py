"""``diagnose()``: locate where a recording and the model differ, name the missing physics, fit it,
and show the fit improve on data it did not fit.

Stages (one progress line each on stderr when ``options.progress``):

1. prepare  — channels into the model's frame, derivatives, parallel low-pass + decimation
              (:mod:`.equation_error`); held-out part chosen (:func:`.equation_error.holdout_mask`).
2. compare  — equation-error residuals of the nominal model per equation; short-window replay of the
              recorded commands through the simulator (multiple shooting, :func:`.refit.replay`).
3. locate   — residual by speed / current / temperature / voltage headroom, change points, angle orders.
4. attribute— forward selection with ΔBIC + held-out gate (:mod:`.selection`), aliases, not-checkable.
5. model    — final fit ± uncertainty, updated parameter file (:mod:`.refit`).
6. show     — before/after on held-out data with the metric that suits each effect.

Usage::

    from bldc_actuator.diagnosis.pipeline import diagnose, DiagnoseOptions
    report = diagnose(signals, params, options=DiagnoseOptions(holdout=0.3))
    report.to_dict()          # JSON-ready
    report.updated_params     # ActuatorParams with the accepted effects switched on and fitted
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..params import ActuatorParams
from . import candidates as cands
from . import equation_error as ee
from . import locate as loc_mod
from . import base_model, judge, output_error, refit, significance
from .threads import SingleThreadedBLAS
from .report import DiagnosisReport
from .selection import GateConfig, fit_model, forward_select


@dataclass
class DiagnoseOptions:
    """Knobs of :func:`diagnose` (defaults suit a 1 kHz robot-joint recording)."""

    effects: list[str] | None = None          #: candidate effects to test (default: all of EFFECT_NAMES)
    holdout: float = 0.3                      #: fraction of the recording held out (interleaved time blocks)
    holdout_signals: Any = None               #: a separate recording used as the held-out data instead
    cutoff_hz: float | None = None            #: parallel low-pass cut-off (default min(0.1 fs, 100 Hz))
    window_s: float = 0.1                     #: replay (multiple-shooting) window length [s]
    max_windows: int = 120                    #: replay windows per set (evenly thinned)
    replay: bool = True                       #: run the short-window simulation comparison
    gate: GateConfig = field(default_factory=GateConfig)
    simulation_gate: bool = True              #: accept only findings the held-out simulation confirms
    tolerance: float = 0.05                   #: a parameter-change finding must move its parameter by more
    max_relative_uncertainty: float = 0.5     #: every accepted value must be identified this well (sd/|value|)
    progress: bool | Callable[[str], None] = False   #: True: one line per stage on stderr

    def validated_effects(self) -> list[str]:
        names = list(cands.EFFECT_NAMES)
        if self.effects is None:
            return names
        bad = [e for e in self.effects if e not in names]
        if bad:
            raise ValueError(f"effects: unknown effect(s) {', '.join(bad)} (known: {', '.join(names)})")
        return list(dict.fromkeys(self.effects))


_SingleThreadedBLAS = SingleThreadedBLAS   # the name other modules imported


def _progress(options: DiagnoseOptions) -> Callable[[str], None]:
    if callable(options.progress):
        return options.progress
    if options.progress:
        return lambda msg: print(f"[diagnose] {msg}", file=sys.stderr, flush=True)
    return lambda msg: None


def _rms(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2))) if len(x) else float("nan")


def _ee_metrics(ctx: ee.Context, fit: ee.Fit) -> dict[str, dict[str, float]]:
    ho = ctx.holdout_dec
    out = {}
    for eq, B in ctx.blocks.items():
        r = fit.resid[eq]
        out[eq] = {"train_rms": _rms(r[B.rows(ho, "train")]), "holdout_rms": _rms(r[B.rows(ho, "holdout")]),
                   "unit": B.unit}
    return out


def diagnose(signals, params: ActuatorParams, *, options: DiagnoseOptions | None = None) -> DiagnosisReport:
    """Diagnose ``signals`` (a :class:`~bldc_actuator.diagnosis.signals.Signals`, cleaned) against the
    nominal ``params``. See the module docstring for the stages and :class:`DiagnosisReport` for the result."""
    with _SingleThreadedBLAS():
        return _diagnose(signals, params, options or DiagnoseOptions())


def _diagnose(signals, params: ActuatorParams, options: DiagnoseOptions) -> DiagnosisReport:
    say = _progress(options)
    names = options.validated_effects()
    lib = cands.library()
    timing: dict[str, float] = {}
    t_all = time.perf_counter()

    # 1. prepare ------------------------------------------------------------------------------
    t0 = time.perf_counter()
    parts = [(signals, False)]
    if options.holdout_signals is not None:
        parts.append((options.holdout_signals, True))
    ctx = ee.prepare(parts, params, fc=options.cutoff_hz, holdout=options.holdout)
    channels = sorted(ctx.have)
    timing["prepare"] = time.perf_counter() - t0
    say(f"1/6 prepare: {len(ctx.t)} samples at {ctx.fs:.4g} Hz, {len(ctx.segments)} segment(s), "
        f"low-pass {ctx.dec.fc:.4g} Hz, decimated x{ctx.dec.q} -> {len(ctx.dec)} samples; "
        f"equations: {', '.join(ctx.blocks) or 'none'} ({timing['prepare']:.2f} s)")
    data_issues = [_issue_dict(i) for i in getattr(signals, "issues", [])]
    if options.holdout_signals is not None:
        data_issues += [dict(_issue_dict(i), recording="holdout") for i in getattr(options.holdout_signals, "issues", [])]

    # 2. compare: nominal equation error + replay -------------------------------------------------
    t0 = time.perf_counter()
    if not ctx.blocks:
        report = DiagnosisReport(channels=channels, findings=[], rejected=[], windows=[], data_issues=data_issues,
                                 not_checkable=[{"effect": n, "reason": "needs current and velocity or position",
                                                 "needs": ["current", "velocity|position"]} for n in names],
                                 aliases=[], verdict="not checkable: no model equation can be evaluated "
                                 "(needs current and velocity or position)", notes=ctx.notes)
        return report
    nominal_cols = {k: ctx.column(k, b) for k, b in ctx.nuisance.items()}
    w1 = {eq: 1.0 for eq in ctx.blocks}
    nominal_fit = ee.fit_columns(ctx, nominal_cols, list(ctx.nuisance), w1)
    replay_nominal = None
    starts_ho: list[int] = []
    if options.replay:
        starts_all = refit.windows(ctx, options.window_s, options.max_windows, "all")
        starts_ho = refit.windows(ctx, options.window_s, options.max_windows, "holdout")
        replay_nominal = refit.replay(ctx, [params], starts_all, options.window_s)[0] if starts_all else None
    timing["compare"] = time.perf_counter() - t0
    msg = ", ".join(f"{eq} RMS {m['train_rms']:.3g}" for eq, m in _ee_metrics(ctx, nominal_fit).items())
    if replay_nominal and replay_nominal.get("available"):
        msg += (f"; replay over {replay_nominal['windows']} windows: current RMS {replay_nominal['current_rms']:.3g} A, "
                f"speed RMS {replay_nominal['velocity_rms']:.3g} rad/s")
    say(f"2/6 compare: {msg} ({timing['compare']:.2f} s)")

    # 3. locate --------------------------------------------------------------------------------
    t0 = time.perf_counter()
    located = {eq: loc_mod.locate_equation(ctx, eq, nominal_fit.resid[eq]) for eq in ctx.blocks}
    windows = [w for eq in located for w in located[eq]["windows"]]
    timing["locate"] = time.perf_counter() - t0
    peaks = (located.get("mechanical", {}).get("order_spectrum") or {}).get("peaks", [])
    say(f"3/6 locate: {len(windows)} window(s) where the residual level changes; angle-order peaks "
        f"{[p['order'] for p in peaks[:4]]} ({timing['locate']:.2f} s)")

    # 4. attribute -----------------------------------------------------------------------------
    t0 = time.perf_counter()
    linear = [n for n in names if n not in cands.SPECIAL]
    sel = forward_select(ctx, located, lib, linear, options.gate, progress=lambda m: say(f"4/6 attribute: {m}"))
    alias_records: list[dict] = []
    if options.simulation_gate and options.replay and starts_ho and sel.aliases:
        # aliased forms: the held-out simulation decides (the simpler one when it cannot tell them apart)
        sel, alias_records = judge.arbitrate_aliases(
            ctx, sel, lambda out: forward_select(ctx, located, lib, [n for n in linear if n not in out], options.gate),
            lib, starts_ho, options.window_s, progress=lambda m: say(f"4/6 attribute: {m}"))
    thermal = refit.thermal_select(ctx, [n for n in names if n in cands.THERMAL], lib, options.gate)
    vsat = refit.voltage_saturation_check(ctx, lib, options.gate, "voltage_saturation" in names)
    for k in ("findings", "rejected", "not_checkable"):
        thermal[k] = thermal[k] + vsat[k]
    timing["attribute"] = time.perf_counter() - t0
    say(f"4/6 attribute: accepted {[a.effect for a in sel.accepted] + [f['effect'] for f in thermal['findings']] or 'nothing'}; "
        f"{len(sel.not_checkable) + len(thermal['not_checkable'])} not checkable ({timing['attribute']:.2f} s)")

    # 5. model ---------------------------------------------------------------------------------
    t0 = time.perf_counter()
    ff = refit.final_fit(ctx, sel)
    pars = refit.effect_parameters(ctx, sel, ff, lib)
    # practical significance and identifiability: drop before the final fit and the parameter file
    candidates_pars = dict(pars)
    for f in thermal["findings"]:
        candidates_pars[f["effect"]] = {k: {"value": v, "sd": f["uncertainty"].get(k), "field": f["fields"].get(k)}
                                        for k, v in f["parameters"].items()}
    experiments = {n: next(iter(c.confusable.values()), "") for n, c in lib.items() if c.confusable}
    verdicts = significance.judge(candidates_pars, ctx.params, tolerance=options.tolerance,
                                  max_relative_uncertainty=options.max_relative_uncertainty, experiments=experiments)
    dropped = {v.effect for v in verdicts}
    if dropped:
        if any(a.effect in dropped for a in sel.accepted):
            sel.accepted = [a for a in sel.accepted if a.effect not in dropped]
            ff = refit.final_fit(ctx, sel)
            sel.final_fit = ff.fit
            pars = refit.effect_parameters(ctx, sel, ff, lib)
        thermal["findings"] = [f for f in thermal["findings"] if f["effect"] not in dropped]
        for v in verdicts:
            say(f"5/6 model: {v.message}")
    # the simulator as judge: each finding's held-out simulated error with and without it (leave one out)
    sim_verdicts = judge.simulate_findings(ctx, sel, pars, lib, starts_ho, options.window_s,
                                           tolerance=options.tolerance) \
        if options.replay and starts_ho else {}
    if options.simulation_gate:
        refused = {e for e, v in sim_verdicts.items()
                   if v["verdict"] not in ("confirmed", "not simulated", "not checkable in simulation")}
        if refused:
            for e in sorted(refused):
                v = sim_verdicts[e]
                verdicts.append(significance.Verdict(e, "not_confirmed_in_simulation",
                                                     f"{e}: {v['verdict']} (held-out simulated {v['channel']} error "
                                                     f"{v['without']:.3g} -> {v['with']:.3g}, noise floor "
                                                     f"{v['noise_floor']:.2g})"))
                say(f"5/6 model: {verdicts[-1].message}")
            sel.accepted = [a for a in sel.accepted if a.effect not in refused]
            ff = refit.final_fit(ctx, sel)
            sel.final_fit = ff.fit
            pars = refit.effect_parameters(ctx, sel, ff, lib)
    new_params, param_notes, not_sim = refit.updated_params(ctx, sel, pars, lib)
    # output-error refit: the accepted effects' simulator parameters and the core jointly, by multiple shooting
    oe = None
    if options.replay and sel.accepted and starts_ho:
        starts_tr = refit.windows(ctx, options.window_s, options.max_windows, "train")
        oe = output_error.refit(ctx, ctx.params, new_params, starts_tr, starts_ho, options.window_s)
        if oe.get("kept"):
            new_params = oe["params"]
            param_notes.append("output-error refit kept (multiple shooting): " + ", ".join(
                f"{k} {v['equation_error']:.4g} -> {v['output_error']:.4g}" for k, v in oe["fields"].items()))
        if oe.get("available"):
            say(f"5/6 model: output-error refit {'kept' if oe['kept'] else 'not kept'} ({oe['evaluations']} "
                f"evaluations; held-out speed RMS {oe['holdout']['equation_error']['velocity_rms']:.3g} -> "
                f"{oe['holdout']['output_error']['velocity_rms']:.3g} rad/s)")
    base = base_model.check(ctx)   # several core values far off: say so before any effect
    # thermal-network findings judged by the full-length thermal simulation of the final model (leave one out)
    thermal_verdicts = judge.judge_thermal(ctx, new_params, thermal) if thermal["findings"] else {}
    sim_verdicts.update(thermal_verdicts)
    if options.simulation_gate:
        refused = {e for e, v in thermal_verdicts.items() if v["verdict"] != "confirmed"}
        for e in sorted(refused):
            v = thermal_verdicts[e]
            verdicts.append(significance.Verdict(e, "not_confirmed_in_simulation",
                                                 f"{e}: {v['verdict']} (held-out simulated temperature error "
                                                 f"{v['without']:.3g} -> {v['with']:.3g} K, needs a gain above "
                                                 f"{v['noise_floor']:.2g} K)"))
        thermal["findings"] = [f for f in thermal["findings"] if f["effect"] not in refused]
    # the drive's voltage limit: the held-out windows replayed with the fitted limit and with the nominal one
    vs = next((f for f in thermal["findings"] if f["effect"] == "voltage_saturation"), None)
    if vs is not None and options.replay:
        v = judge.judge_voltage_limit(ctx, refit.apply_thermal(new_params, {"findings": [vs]})[0], vs, starts_ho,
                                      options.window_s, tolerance=options.tolerance)
        sim_verdicts["voltage_saturation"] = v
        if options.simulation_gate and v["verdict"] not in ("confirmed", "not checkable in simulation"):
            verdicts.append(significance.Verdict("voltage_saturation", "not_confirmed_in_simulation",
                                                 f"voltage_saturation: {v['verdict']} (held-out simulated current "
                                                 f"error {v['without']:.3g} -> {v['with']:.3g} A, noise floor "
                                                 f"{v['noise_floor']:.2g} A)"))
            thermal["findings"] = [f for f in thermal["findings"] if f is not vs]
    if not any(f["effect"] == "iron_loss" for f in thermal["findings"]):
        thermal["extra_heat"] = None      # iron-loss heat only with an accepted iron_loss finding
    if thermal["findings"]:
        new_params, tnotes, tns = refit.apply_thermal(new_params, thermal)
        param_notes += tnotes
        not_sim += tns
    timing["model"] = time.perf_counter() - t0
    say(f"5/6 model: {len(ff.keys)} fitted coefficient(s); not yet simulated: {not_sim or 'none'} "
        f"({timing['model']:.2f} s)")

    # 6. show ----------------------------------------------------------------------------------
    t0 = time.perf_counter()
    findings = _findings(ctx, sel, ff, pars, lib, located, not_sim)
    for f in findings:
        if f["effect"] in sim_verdicts:
            f["simulation"] = sim_verdicts[f["effect"]]
    for f in thermal["findings"]:
        if f["effect"] in sim_verdicts:
            f["simulation"] = sim_verdicts[f["effect"]]
    findings += thermal["findings"]
    replay_ho = None
    if options.replay and starts_ho:
        before, after = refit.replay(ctx, [params, new_params], starts_ho, options.window_s)
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
        ta = refit.thermal_error(ctx, new_params, extra_heat=thermal.get("extra_heat"))
        thermal_cmp = {"before": {k: v for k, v in tb.items() if k != "sim"},
                       "after": {k: v for k, v in ta.items() if k != "sim"}}
    timing["show"] = time.perf_counter() - t0
    timing["total"] = time.perf_counter() - t_all
    accepted_names = [f["effect"] for f in findings]
    if accepted_names:
        verdict = "missing physics found: " + ", ".join(accepted_names)
    else:
        verdict = "nothing missing: no candidate effect passed both the ΔBIC and the held-out gate"
    unreproduced = sorted({v.effect for v in verdicts if "does not reproduce" in v.message})
    if unreproduced:
        why = next(sim_verdicts[e]["verdict"].split(": ", 1)[1] for e in unreproduced
                   if "does not reproduce" in sim_verdicts.get(e, {}).get("verdict", ""))
        msg = (f"equation error alone suggests {', '.join(unreproduced)}, but {why}: check the logging rate against "
               f"the control loops' bandwidth and the drive model")
        verdict = f"{verdict}; not shown in simulation: {msg}" if accepted_names else f"nothing shown in simulation: {msg}"
    aliases = []
    for a in sel.aliases:
        A, B = a["effects"]
        exp = lib[A].confusable.get(B) or lib[B].confusable.get(A) or "record data that excites them differently"
        aliases.append({"effects": [A, B], "chosen": a["chosen"], "correlation": a["correlation"],
                        "message": f"cannot tell {A} from {B} with this data (their fitted contributions "
                                   f"correlate {a['correlation']:.2f}); "
                                   + (f"{a['chosen']} was kept" if a["chosen"] else
                                      "neither was kept: together they fit implausible values")
                                   + (f" ({a['decided_by']})" if a.get("decided_by") else ""),
                        "experiment": exp})
    final_metrics = _ee_metrics(ctx, sel.final_fit)
    compare = {"equation_error": {eq: {"nominal": _ee_metrics(ctx, sel.base_fit)[eq], "updated": final_metrics[eq]}
                                  for eq in ctx.blocks},
               "replay": {"all_windows_nominal": _strip(replay_nominal),
                          "holdout": {k: _strip(v) for k, v in replay_ho.items()} if replay_ho else None},
               "thermal": thermal_cmp,
               "output_error_refit": {k: v for k, v in oe.items() if k != "params"} if oe else None,
               "alias_simulation": alias_records or None}
    say(f"6/6 show: {verdict} ({timing['show']:.2f} s; total {timing['total']:.2f} s)")
    report = DiagnosisReport(
        channels=channels, findings=findings, windows=windows,
        rejected=sel.rejected + thermal["rejected"] + [{"effect": v.effect, "form": "practical significance",
                                                         "verdict": v.kind, "reason": v.message} for v in verdicts],
        data_issues=data_issues, not_checkable=sel.not_checkable + thermal["not_checkable"], aliases=aliases,
        verdict=(base["message"] + "; " + verdict) if base else verdict,
        notes=ctx.notes + param_notes + ([base["message"]] if base else []), compare=compare, locate=located,
        rounds=sel.rounds, correlations=ff.correlations, not_simulated=not_sim, timing=timing,
        updated_params=new_params, nominal_params=params,
        setup={"rate_hz": ctx.fs, "cutoff_hz": ctx.dec.fc, "decimation": ctx.dec.q, "samples": int(len(ctx.t)),
               "decimated_samples": int(len(ctx.dec)), "holdout": "separate recording" if options.holdout_signals
               is not None else f"{options.holdout:g} of the time (interleaved blocks)",
               "gate": vars(options.gate), "effects_tested": names,
               "source": getattr(signals, "source", "")})
    report._internals = {"ctx": ctx, "sel": sel, "ff": ff, "nominal_fit": sel.base_fit, "replay_ho": replay_ho,
                         "thermal": thermal}
    return report


def _strip(r):
    if not r:
        return r
    return {k: v for k, v in r.items() if k not in ("trace", "per_window")}


def _issue_dict(issue) -> dict:
    if hasattr(issue, "to_dict"):
        return issue.to_dict()
    if isinstance(issue, dict):
        return issue
    return {k: getattr(issue, k, None) for k in ("kind", "channel", "count", "first_time", "detail", "action")}


def _findings(ctx, sel, ff, pars, lib, located, not_sim) -> list[dict]:
    """One finding per accepted effect with its held-out before/after in the metric that suits it."""
    out = []
    ho = ctx.holdout_dec
    weights = sel.weights
    for a in sel.accepted:
        cand = lib[a.effect]
        others = [k for k in ff.keys if k not in a.added]
        f_without = fit_model(ctx, sel.cols, others, weights, sel.iterating)
        eqs = [eq for eq in cand.equations if eq in ctx.blocks and any(sel.cols[k].get(eq) is not None for k in a.added)]
        metrics = []
        for eq in eqs:
            B = ctx.blocks[eq]
            rows = B.rows(ho, "holdout")
            metrics.append({"metric": f"{eq} equation-error residual RMS (held-out)", "unit": B.unit,
                            "before": _rms(f_without.resid[eq][rows]), "after": _rms(sel.final_fit.resid[eq][rows])})
        if a.effect in ("cogging_torque", "electrical_angle_ripple") and "mechanical" in ctx.blocks:
            rows = ctx.blocks["mechanical"].rows(ho, "holdout")
            th = ctx.dsig("theta")[rows]
            o = int(a.variant.hyper["order"])
            b0 = loc_mod.angle_synchronous(th, f_without.resid["mechanical"][rows], o)
            b1 = loc_mod.angle_synchronous(th, sel.final_fit.resid["mechanical"][rows], o)
            metrics.insert(0, {"metric": f"angle-synchronous mechanical residual RMS at order {o} (held-out)",
                               "unit": ctx.blocks["mechanical"].unit, "before": b0["rms"], "after": b1["rms"]})
        # share of the nominal residual its columns explain (training)
        explained = _explained(ctx, sel, a)
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
                                       {"explained": explained, "dbic": a.dbic, "heldout": a.heldout}),
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
        out.append(finding)
    return out


def _explained(ctx, sel, a) -> float:
    """Fraction of the nominal residual variance (weighted, training) removed by this effect's columns alone."""
    alone = fit_model(ctx, sel.cols, list(ctx.nuisance) + list(a.variant.keys), sel.weights, sel.iterating)
    num = sum(sel.weights[eq] ** 2 * (sel.base_fit.rss[eq] - alone.rss[eq]) for eq in alone.rss)
    den = sum(sel.weights[eq] ** 2 * sel.base_fit.rss[eq] for eq in alone.rss)
    return float(num / den) if den > 0 else 0.0
