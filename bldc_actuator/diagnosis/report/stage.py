"""Stage 6, report: one finding per accepted effect with its evidence and its held-out before/after in the
metric that suits it, the final model's simulated before/after (short-window replay of the held-out windows,
full-length thermal simulation), aliases, and the :class:`.document.DiagnosisReport` that renders JSON, markdown
and plots. :func:`run` is the entry point; nothing is decided here.
"""

from __future__ import annotations

import dataclasses

import time

import numpy as np

from ..frame import candidates as cands
from ..effects import Route, registry
from . import decidability, residual_structure
from ..frame import locate as loc_mod
from ..frame import simulate
from ..frame import thermal as thermal_net
from ..frame.equation_error import ee_metrics, rms
from .document import DiagnosisReport
from .. import drive_feedforward
from ..results import Undecidable, decide
from ..frame.selection import fit_model, nested_aliases
from ..records import Judgement, Model, Say, Search


def not_checkable(s: Search) -> DiagnosisReport:
    """The report when no model equation can be evaluated."""
    rec = decide([], [Undecidable("no_equation", "no model equation can be evaluated (needs current and velocity "
                                                 "or position)", "log the motor current and the speed or angle")])
    return DiagnosisReport(channels=sorted(s.ctx.have), findings=[], rejected=[], windows=[],
                           data_issues=s.data_issues,
                           not_checkable=[{"effect": n, "reason": "needs current and velocity or position",
                                           "needs": ["current", "velocity|position"]} for n in s.names],
                           aliases=[], verdict_record=rec, notes=s.ctx.notes)


def _data_notes(signals) -> list[str]:
    """What loading and cleaning noted about the recording (profile notes, --map over a profile, clocks...)."""
    return [f"data: {n}" for n in ((getattr(signals, "meta", None) or {}).get("notes") or [])]


def _strip(r):
    if not r:
        return r
    return {k: v for k, v in r.items() if k not in ("trace", "per_window")}


def paired_change(before: dict, after: dict) -> dict[str, dict]:
    """Per channel, the held-out windows' paired change of the squared simulation error, after - before: its mean
    (= after_rms^2 - before_rms^2), standard error over the windows (:func:`..frame.simulate.mean_se`: finite
    windows, at least 3; a channel with fewer is left out, judged by the 1 % rule alone) and whether the change is
    beyond 2 standard errors. A change of RMS within that band is the recording's noise, not the model (an error
    already at the noise floor moves by a few per cent with any parameter change)."""
    out: dict[str, dict] = {}
    if not (before.get("available") and after.get("available")):
        return out
    for ch in ("current", "velocity", "position", "voltage"):
        b, a = (before.get("per_window") or {}).get(ch), (after.get("per_window") or {}).get(ch)
        if b is None or a is None:
            continue
        d = np.asarray(a, float) ** 2 - np.asarray(b, float) ** 2
        mean, se = simulate.mean_se(d)
        if mean != mean:        # fewer than 3 finite windows: no paired test
            continue
        out[ch] = {"mean_square_change": mean, "standard_error": se, "windows": int(np.isfinite(d).sum()),
                   "significant": bool(abs(mean) > 2.0 * se)}
    return out


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
    if registry.get(a.effect).angle_locked and "mechanical" in ctx.blocks:
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
        "combinations": [c for c in ff.combined if set(c["columns"]) & set(a.added)],
    }
    if registry.get(a.effect).torque_scale:
        finding["frame_factor"] = p.get("frame_factor", {}).get("value", "none")
    nl = ff.nonlinear.get(a.effect, {})
    if nl.get("omega_s_corr_amplitude") is not None and abs(nl["omega_s_corr_amplitude"]) > 0.9:
        finding["correlations"].append({"a": "stribeck_velocity", "b": "stribeck_friction",
                                        "correlation": round(nl["omega_s_corr_amplitude"], 3)})
    return finding


def _aliases(sel, lib, ctx=None, updated=None, located=None) -> list[dict]:
    out = []
    nested = nested_aliases(ctx, located, lib, sel) if ctx is not None and located is not None else []
    for a in sel.aliases + nested:
        A, B = a["effects"]
        exp = (a.get("experiment") or lib[A].confusable.get(B) or lib[B].confusable.get(A)
               or "record data that excites them differently")
        rec = {"effects": [A, B], "chosen": a["chosen"], "correlation": a["correlation"],
               "message": f"cannot tell {A} from {B} with this data (their fitted contributions "
                          f"correlate {a['correlation']:.2f}); "
                          + (f"{a['chosen']} was kept" if a["chosen"] else
                             "neither was kept: together they fit implausible values")
                          + (f" ({a['decided_by']})" if a.get("decided_by") else ""),
               "experiment": exp}
        pred = _transmission_predictions(ctx, updated, lib, A, B, a.get("chosen"))
        if pred is not None:
            rec["predictions"], text = pred
            rec["experiment"] = f"{exp}. What each would show: {text}"
        out.append(rec)
    return out


def _transmission_predictions(ctx, updated, lib, A, B, chosen):
    """An alias of a hidden form behind the transmission spring the finding wrote (``hides_behind``: a dead zone
    seen from the rotor alone acts as a softer spring): each candidate fitted to the recording, and what it
    predicts for the deciding experiment (:func:`..frame.transmission.spring_or_dead_zone`)."""
    if ctx is None or updated is None or chosen not in (A, B):
        return None
    other = B if chosen == A else A
    if chosen not in (lib[other].hides_behind or ()) or not updated.gear.transmission_stiffness > 0.0:
        return None
    from ..frame import transmission

    try:
        both = transmission.spring_or_dead_zone(ctx, updated)
    except (ValueError, FloatingPointError):
        return None
    if both is None:
        return None
    spring, dz = both
    mrad = 1e3
    preds = {chosen: dataclasses.asdict(spring), other: dataclasses.asdict(dz)}
    text = (f"{chosen} (the fitted spring, {spring.stiffness:.4g} N*m/rad): a load encoder over this motion reads a "
            f"deflection of {mrad * spring.deflection_rms:.3g} mrad RMS ({mrad * spring.deflection_p2p:.3g} peak to "
            f"peak), a slow low-torque reversal shows no lost motion; {other} (a dead zone of "
            f"{mrad * dz.backlash:.3g} mrad behind a spring of {dz.stiffness:.4g} N*m/rad, fitted to follow the "
            f"recorded rotor as the spring does: its load angle differs by {mrad * dz.load_angle_rms_difference:.2g} "
            f"mrad RMS): a deflection of {mrad * dz.deflection_rms:.3g} mrad RMS "
            f"({mrad * dz.deflection_p2p:.3g} peak to peak), a lost motion of {mrad * dz.lost_motion:.3g} mrad at the "
            f"reversal (output side; simulated by the load equation driven by the recorded rotor)")
    return preds, text


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
        before, after = simulate.replay(ctx, [params, m.params], s.starts_holdout, options.window_s)
        replay_ho = {"before": before, "after": after, "paired": paired_change(before, after)}
        for f in findings:
            if registry.get(f["effect"]).route is Route.THERMAL:
                continue
            f["metrics"].append({"metric": f"short-window simulation speed error RMS (held-out, "
                                           f"{options.window_s:g} s windows, all accepted effects)",
                                 "unit": "rad/s", "before": before["velocity_rms"], "after": after["velocity_rms"]})
            f["metrics"].append({"metric": "short-window simulation current error RMS (held-out)", "unit": "A",
                                 "before": before["current_rms"], "after": after["current_rms"]})
            if before.get("voltage_rms") is not None and after.get("voltage_rms") is not None:
                f["metrics"].append({"metric": "short-window simulation q-voltage error RMS (held-out, at the recorded "
                                               "speed)", "unit": "V", "before": before["voltage_rms"],
                                     "after": after["voltage_rms"]})
    thermal_cmp = None
    if any(c in ctx.have for c in ("winding_temperature", "housing_temperature")) and "i_q" in ctx.sig:
        tb = thermal_net.thermal_error(ctx, params)
        ta = thermal_net.thermal_error(ctx, m.params, extra_heat=j.special.get("extra_heat"))
        thermal_cmp = {"before": {k: v for k, v in tb.items() if k != "sim"},
                       "after": {k: v for k, v in ta.items() if k != "sim"}}
    timing = {**s.timing, **m.timing, "show": time.perf_counter() - t0}
    timing["total"] = time.perf_counter() - t_start
    names = [f["effect"] for f in findings]
    for f in findings:
        if (f.get("simulation") or {}).get("verdict") == "not checkable in simulation":
            f["not_checkable_in_simulation"] = True
    unreproduced = sorted({v.effect for v in j.verdicts if "does not reproduce" in v.message})
    why = next((j.simulation[e]["verdict"].split(": ", 1)[1] for e in unreproduced
                if "does not reproduce" in j.simulation.get(e, {}).get("verdict", "")), None)
    clipped = decidability.clipped(getattr(signals, "meta", {}))
    base_replay = decidability.base_replay(s.replay_nominal, (replay_ho or {}).get("after") if findings else None)
    if base_replay is not None and findings and all(f.get("not_checkable_in_simulation") for f in findings):
        # the judge found the motion imposed from outside (a torque sensor): the simulation is not the judge here,
        # so its failure to follow is a caveat, not a reason to distrust the findings
        base_replay.blocking = False
        base_replay.reason += " (the motion is imposed from outside: every finding is not checkable in simulation)"
    reasons = [u for u in (clipped, base_replay,
                           # (windows lost to a clipped current are said by the clipped reason)
                           None if clipped else decidability.holdout(s.starts_holdout, options.window_s,
                                                                     options.replay)) if u is not None]
    structures = residual_structure.find(ctx, sel.final_fit)
    reasons += decidability.outside_catalogue(structures)
    reasons += decidability.undecided_candidates(sel.rejected)
    suffix = ""
    if why:
        msg = (f"equation error alone suggests {', '.join(unreproduced)}, but {why}: check the logging rate against "
               f"the control loops' bandwidth and the drive model")
        if names:
            suffix = f"not shown in simulation: {msg}"
        else:
            reasons.insert(0, Undecidable("not_shown_in_simulation", f"nothing shown in simulation: {msg}",
                                          "log faster than the control loops' bandwidth"))
    base = m.base
    limit = drive_feedforward.limit_of(ctx.drive_identified)
    verdict_rec = decide(names, reasons, prefix=base["message"] if base else "", suffix=suffix,
                         limits=[limit.short] if limit is not None else [],
                         not_checkable_in_simulation=[f["effect"] for f in findings
                                                      if f.get("not_checkable_in_simulation")])
    verdict = verdict_rec.text()
    nominal_m, final_m = ee_metrics(ctx, sel.base_fit), ee_metrics(ctx, sel.final_fit)
    oe = m.output_error
    compare = {"equation_error": {eq: {"nominal": nominal_m[eq], "updated": final_m[eq]} for eq in ctx.blocks},
               "replay": {"all_windows_nominal": _strip(s.replay_nominal),
                          "command": ctx.command_replay.to_dict() if ctx.command_replay is not None else None,
                          "start_speed": simulate.start_speed(ctx)[1] if "omega_s" in ctx.sig else None,
                          "holdout": {k: _strip(v) for k, v in replay_ho.items()} if replay_ho else None},
               "thermal": thermal_cmp,
               "output_error_refit": {k: v for k, v in oe.items() if k != "params"} if oe else None,
               "alias_simulation": j.alias_simulation or None}
    say(f"6/6 show: {verdict} ({timing['show']:.2f} s; total {timing['total']:.2f} s)")
    not_checkable = sel.not_checkable + j.special["not_checkable"]
    if any(u.code == "clipped" for u in reasons):
        scale = registry.torque_scale().name
        not_checkable = [x for x in not_checkable if x["effect"] != scale] + [
            {"effect": scale, "reason": next(u.reason for u in reasons if u.code == "clipped"),
             "needs": ["current inside the drive's limit"]}]
    rejected = sel.rejected + j.special["rejected"] + [
        {"effect": v.effect, "form": "practical significance", "verdict": v.kind, "reason": v.message}
        for v in j.verdicts]
    report = DiagnosisReport(
        channels=sorted(ctx.have), findings=findings, windows=s.windows, rejected=rejected,
        data_issues=s.data_issues, not_checkable=not_checkable,
        aliases=_aliases(sel, lib, ctx, m.params, s.located), verdict_record=verdict_rec,
        residual_structure=[x.to_dict() for x in structures],
        model_limits=[limit.to_dict()] if limit is not None else [],
        notes=_data_notes(signals) + ctx.notes + m.notes + ([base["message"]] if base else []), compare=compare,
        locate=s.located,
        rounds=sel.rounds, correlations=j.final.correlations, combinations=j.final.combined,
        not_simulated=m.not_simulated, timing=timing,
        updated_params=m.params, nominal_params=params,
        setup={"rate_hz": ctx.fs, "cutoff_hz": ctx.dec.fc, "decimation": ctx.dec.q, "samples": int(len(ctx.t)),
               "decimated_samples": int(len(ctx.dec)), "holdout": "separate recording" if options.holdout_signals
               is not None else f"{options.holdout:g} of the time (interleaved blocks)",
               "gate": vars(options.gate), "effects_tested": s.names,
               "source": getattr(signals, "source", "")})
    report._internals = {"ctx": ctx, "sel": sel, "ff": j.final, "nominal_fit": sel.base_fit, "replay_ho": replay_ho,
                         "thermal": j.special}
    return report


#: torque-balance parameter -> parameter-file field (what :func:`..torque_balance.updated_params` writes)
_TB_FIELDS = {"coulomb_friction": "effects.coulomb_friction", "viscous_damping": "motor.viscous_damping",
              "rotor_inertia": "motor.rotor_inertia", "cogging_order": "effects.cogging_order"}


def torque_balance(signals, params, res, options, say: Say, t_start: float) -> DiagnosisReport:
    """The report of the torque-balance route (:mod:`..torque_balance`: torque and motion, no current) in the
    same schema as the full route: findings, rejected, not checkable, data issues, ``compare``, the verdict."""
    from .. import torque_balance as tb_mod

    findings, rejected = [], []
    for x in res.findings:
        ev = [f"torque balance: ΔBIC {x.delta_bic:.1f}; held-out torque RMS {x.held_out['before']:.4g} -> "
              f"{x.held_out['after']:.4g} N*m"]
        if registry.get(x.effect).angle_locked and res.spectrum:
            o = res.spectrum
            ev.append(f"angle-order peak at order {o['order']:.3g} ± {o['order_sd']:.2g} per motor revolution "
                      f"({o['amplitude']:.3g} N*m, {o['peak_over_median']:.1f} x the median) over "
                      f"{o['revolutions']:.2f} revolution(s)")
        if registry.get(x.effect).route is Route.TORQUE_BALANCE and res.ripple:
            o = res.ripple
            ev.append(f"angle-locked ripple in the measured torque at order {o['order']:.3g} ± {o['order_sd']:.2g} per "
                      f"motor revolution: {o['amplitude']:.3g} ± {o['amplitude_sd']:.2g} N*m at the output, "
                      f"{o['power_over_neighbours']:.1f} x the power of its neighbouring orders (p = {o['p_value']:.2g}); "
                      f"{o['consistency']}")
        findings.append({"effect": x.effect, "description": f"{x.effect.replace('_', ' ')} (torque balance)",
                         "form": "torque balance", "parameters": x.parameters, "uncertainty": x.uncertainty,
                         "units": x.units, "fields": {k: _TB_FIELDS[k] for k in x.parameters if k in _TB_FIELDS},
                         "simulated": True, "evidence": ev,
                         "held_out": dict(x.held_out, metric="torque error RMS"),
                         "metrics": [dict(x.held_out, metric="torque error RMS")],
                         "delta_bic": x.delta_bic, "correlations": []})
    for x in res.rejected:
        rejected.append({"effect": x.effect, "form": "torque balance", "reason": x.reason, "delta_bic": x.delta_bic,
                         "heldout_gain": (x.held_out.get("before") or 0) - (x.held_out.get("after") or 0)})
    reasons = []
    if res.r2 == res.r2 and res.r2 < 0.5:
        reasons.append(Undecidable("balance_explains_little",
                                   f"the torque balance explains only {max(0.0, 100 * res.r2):.0f} % of the torque variance "
                                   f"(the motor was probably powered: its own torque is not logged without current)",
                                   "log the motor current, or turn the motor unpowered"))
    if not res.held_out:
        reasons.append(Undecidable("too_few_samples", "; ".join(res.notes[-1:]), "record longer"))
    rec = decide([f["effect"] for f in findings], reasons)
    verdict = rec.text()
    ho = res.held_out or {}
    compare = {"equation_error": {"torque_balance": {
                   "nominal": {"holdout_rms": ho.get("nominal"), "train_rms": None, "unit": "N*m"},
                   "updated": {"holdout_rms": ho.get("after"), "train_rms": None, "unit": "N*m"}}},
               "replay": None, "thermal": None, "output_error_refit": None, "alias_simulation": None,
               "torque_balance": {"angle_source": res.angle_source, "r2": res.r2, "held_out": ho,
                                  "order_spectrum": res.spectrum}}
    timing = {"total": time.perf_counter() - t_start}
    say(f"6/6 show: {verdict} (total {timing['total']:.2f} s)")
    issues = [i.to_dict() if hasattr(i, "to_dict") else dict(i) for i in getattr(signals, "issues", [])]
    rate = (getattr(signals, "meta", {}) or {}).get("rate_hz")
    return DiagnosisReport(
        channels=sorted(c for c, v in signals.channels.items() if np.isfinite(v).any()), findings=findings,
        rejected=rejected, windows=[], data_issues=issues, not_checkable=list(res.not_checkable), aliases=[],
        verdict_record=rec, notes=_data_notes(signals) + list(res.notes), compare=compare,
        updated_params=tb_mod.updated_params(params, res), nominal_params=params, timing=timing,
        method="torque balance (no motor current)",
        setup={"rate_hz": rate, "samples": int(len(signals.time)), "holdout": f"{options.holdout:g} of the samples "
               "(interleaved blocks)", "effects_tested": ["coulomb_friction", "viscous_friction", "inertia_error",
                                                          "cogging_torque"],
               "source": getattr(signals, "source", "")})
