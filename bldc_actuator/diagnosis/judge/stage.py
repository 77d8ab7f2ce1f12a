"""Stage 4, judge (simulation): which of the search's findings make the simulated actuator — the node's own kernel
— reproduce held-out data better, and which are worth a parameter at all?

:func:`run`, in order: aliased forms decided by the held-out replay (:func:`..judge.arbitrate_aliases`);
practical significance and identifiability (:func:`..significance.judge`: a parameter must move beyond the
tolerance and be identified); leave-one-out held-out simulation of every equation-error finding
(:func:`..judge.simulate_findings`); the thermal network by full-length thermal simulation
(:func:`..judge.judge_thermal`); the drive's fitted voltage limit by replay (:func:`..judge.judge_voltage_limit`);
and the drive's behaviour at the voltage limit, which only a simulation can see (:func:`..drive_modes.identify`).
With ``options.simulation_gate`` off the simulated verdicts are reported but refuse nothing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

from .. import drive_feedforward, significance
from ..frame import simulate as replay
from ..frame import thermal as thermal_net
from ..frame import writeback
from . import drive_modes
from . import simulated as judge
from ..effects import Route, registry
from ..frame.candidates import SPECIAL
from ..frame.selection import forward_select, name_unexcited, unexcited_aliases
from ..records import Judgement, Say, Search

#: simulated verdicts that keep a finding ("not simulated" does not: with the gate on, a finding the simulated
#: actuator cannot hold — no term for its form, or a fitted value outside its parameter — cannot be shown to help)
_KEEP = ("confirmed", "not checkable in simulation")

#: rounds of judging: a refused finding changes the others' fitted values, which are judged again
_ROUNDS = 3


def _refuse(verdicts: list, effect: str, v: dict, unit: str, say: Say) -> None:
    if "without" in v:
        msg = (f"{effect}: {v['verdict']} (held-out simulated {v.get('channel') or ''} error {v['without']:.3g} -> "
               f"{v['with']:.3g}{unit}, noise floor {v['noise_floor']:.2g}{unit})")
    else:
        msg = f"{effect}: {v['verdict']} ({v.get('reason', 'no simulated verdict')})"
    verdicts.append(significance.Verdict(effect, "not_confirmed_in_simulation", msg))
    say(f"5/6 judge: {verdicts[-1].message}")


def _harmful(v: dict) -> bool:
    """A refused finding whose simulation is worse with it than without it beyond the noise floor on its own channel
    (or on the other channel without a gain on its own, or that cannot be simulated at all)."""
    if "without" not in v:
        return True
    if v.get("worse") is not None:     # the measured-current replay: raw and noise-corrected errors both worse
        return bool(v["worse"])
    floor = v.get("noise_floor")
    floor = floor if floor == floor and floor else 0.0
    if v.get("with") is None:
        return str(v["verdict"]).startswith("worsens")
    if str(v["verdict"]).startswith("worsens"):
        # worse on the other channel: harmful unless its own channel gains beyond the floor; then the worsening
        # may be another finding's (it is in every "with" set), and this one is judged again without those
        return not v["without"] - v["with"] > floor
    return v["with"] - v["without"] > floor


def _significance(ctx, lib, pars: dict, special_findings: list, options) -> list:
    """Practical significance and identifiability of the linear findings' values and the special findings."""
    claimed = dict(pars)
    for f in special_findings:
        claimed[f["effect"]] = {k: {"value": v, "sd": f["uncertainty"].get(k), "field": f["fields"].get(k)}
                                for k, v in f["parameters"].items()}
    experiments = {n: next(iter(c.confusable.values()), "") for n, c in lib.items() if c.confusable}
    return significance.judge(claimed, ctx.params, tolerance=options.tolerance,
                              max_relative_uncertainty=options.max_relative_uncertainty, experiments=experiments)


def _refit_linear(s: Search, sel):
    ff = writeback.final_fit(s.ctx, sel)
    sel.final_fit = ff.fit
    return ff, writeback.effect_parameters(s.ctx, sel, ff, s.lib)


def _unexcited_aliases(s: Search, sel, options, say: Say) -> None:
    """An accepted effect that a candidate this recording does not excite explains as well
    (:func:`..selection.unexcited_aliases`; a dead time under a current that never reverses is a constant offset,
    and so is ``R i`` when the current hardly changes) is never a clean finding: it stays (the simulated actuator
    judges it as usual), reported with the alias, and the verdict carries "not decidable" which of the two, with
    the experiment that separates them. The training data's preference (ΔBIC) is reported, not used: with a
    nearly constant current the ``R i`` column is mostly its sensor noise, and a true resistance error fitted
    WORSE than the noise-free constant (ΔBIC -20 on a generated one-signed recording). When the accepted form
    fits better by more than the BIC threshold the data separates them: nothing is said."""
    thr = options.gate.bic_threshold
    for al in unexcited_aliases(s.ctx, s.located, s.lib, sel, options.gate):
        x, y = al["effects"]
        if al.get("separated") == y and any(a.effect == x for a in sel.accepted):
            name_unexcited(s.ctx, sel, al)
            say(f"4/6 attribute: {x} ~ {y} ({y} not checkable here): the data separate them in favour of {y} "
                f"(training ΔBIC {al['delta_bic_common']:+.1f}, held-out {-100 * al['heldout']['rel']:+.1f} % RMS, "
                f"t = {al['heldout']['t']:.1f}): {y} takes {x}'s place")
            continue
        if al["delta_bic"] < -thr:
            say(f"4/6 attribute: {x} ~ {y} ({y} not checkable here): the training data separates them (ΔBIC "
                f"{al['delta_bic']:+.1f} for {y})")
            continue
        vals = ", ".join(f"{k} = {v:.3g}" for k, v in al["parameters"].items())
        sel.aliases.append({"effects": [x, y], "chosen": x, "correlation": al["correlation"],
                            "decided_by": f"{y} cannot be checked here ({al['why']}); which of the two is not "
                                          f"decidable with this data (ΔBIC {al['delta_bic']:+.1f} for {y})",
                            "experiment": al["experiment"], "unexcited": y})
        reason = (f"{x} and {y} explain the same residual in this recording (fitted contributions correlate "
                  f"{al['correlation']:.2f}) and {y} cannot be checked here ({al['why']}): {x} is reported, but "
                  f"which of the two it is, is not decidable with this data (training ΔBIC {al['delta_bic']:+.1f} "
                  f"for {y}{'; ' + y + ' would be ' + vals if vals else ''})")
        sel.rejected.append({"effect": y, "form": al["form"], "verdict": "not_decidable", "reason": reason,
                             "remedy": al["experiment"], "alias_of": x, "parameters": al["parameters"]})
        say(f"4/6 attribute: {x} ~ {y}: {reason}")


@dataclass
class _Judged:
    """The findings after the simulated judges (:func:`_simulated_verdicts`)."""

    sel: Any
    ff: Any
    pars: dict
    special: dict
    verdicts: list
    sim: dict
    params_linear: Any
    notes: list
    not_sim: list


def _snapshot(sel, special: dict, verdicts: list):
    """Copies of what :func:`_simulated_verdicts` changes, to judge the same findings again (the drive's
    second pass changed the replayed drive)."""
    sel2 = replace(sel, accepted=list(sel.accepted), aliases=[dict(a) for a in sel.aliases],
                   rejected=[dict(r) for r in sel.rejected])
    special2 = {k: (list(v) if isinstance(v, list) else v) for k, v in special.items()}
    return sel2, special2, list(verdicts)


def _simulated_verdicts(s: Search, sel, ff, pars: dict, special: dict, verdicts: list, options, say: Say,
                        simulate: bool) -> _Judged:
    """The equation-error findings judged by the held-out simulation (rounds of leave-one-out), then the thermal
    network and the drive's fitted voltage limit; every replay runs the drive as ``ctx.drive_updates`` says."""
    ctx, lib, starts, win = s.ctx, s.lib, s.starts_holdout, options.window_s
    # equation-error findings: held-out simulated error with and without each (leave one out). A refused finding
    # moves the others' fitted values (correlated columns): those are judged again, significance and simulation
    sim: dict = {}
    for _ in range(_ROUNDS):
        if not (simulate and sel.accepted):
            break
        round_sim = judge.simulate_findings(ctx, sel, pars, lib, starts, win, tolerance=options.tolerance)
        sim.update(round_sim)
        refused = {e for e, v in round_sim.items() if v["verdict"] not in _KEEP}
        if not (options.simulation_gate and refused):
            break
        # a finding that makes the simulation worse also spoils the others' leave-one-out comparison (it is in
        # every "with" set): when some do, only those go in this round and the rest are judged again without them
        harmful = {e for e in refused if _harmful(round_sim[e])}
        refused = harmful or refused
        for e in sorted(refused):
            _refuse(verdicts, e, round_sim[e], "", say)
        sel.accepted = [a for a in sel.accepted if a.effect not in refused]
        ff, pars = _refit_linear(s, sel)
        again = _significance(ctx, lib, pars, [], options)
        if again:
            verdicts += again
            for v in again:
                say(f"5/6 judge: {v.message}")
            sel.accepted = [a for a in sel.accepted if a.effect not in {v.effect for v in again}]
            ff, pars = _refit_linear(s, sel)
    kept = {a.effect for a in sel.accepted}
    sel.aliases = [a for a in sel.aliases if not a.get("unexcited") or a["chosen"] in kept]
    for r in sel.rejected:      # the not-decidable record stays: the residual is there, and so is the question
        if r.get("alias_of") and r["alias_of"] not in kept and r.get("verdict") == "not_decidable":
            r["reason"] = r["reason"].replace(f"{r['alias_of']} is reported, but which",
                                              f"{r['alias_of']} was then refused, and which")
    params_linear, notes, not_sim = writeback.updated_params(ctx, sel, pars, lib)

    # thermal network: full-length thermal simulation of the model with the linear findings (leave one out)
    thermal = judge.judge_thermal(ctx, params_linear, special) if special["findings"] else {}
    sim.update(thermal)
    refused = {e for e, v in thermal.items() if v["verdict"] != "confirmed"}
    if options.simulation_gate and refused:
        for e in sorted(refused):
            _refuse(verdicts, e, thermal[e], " K", say)
        special["findings"] = [f for f in special["findings"] if f["effect"] not in refused]

    # the drive's fitted voltage limit: held-out windows replayed with it and with the nominal one
    vlim = registry.one(lambda e: e.route is Route.VOLTAGE_LIMIT).name
    vs = next((f for f in special["findings"] if f["effect"] == vlim), None)
    if vs is not None and options.replay:
        v = judge.judge_voltage_limit(ctx, thermal_net.apply_thermal(params_linear, {"findings": [vs]})[0], vs, starts,
                                      win, tolerance=options.tolerance)
        sim[vlim] = v
        if options.simulation_gate and v["verdict"] not in ("confirmed", "not checkable in simulation"):
            _refuse(verdicts, vlim, v, " A", say)
            special["findings"] = [f for f in special["findings"] if f is not vs]

    return _Judged(sel=sel, ff=ff, pars=pars, special=special, verdicts=verdicts, sim=sim,
                   params_linear=params_linear, notes=notes, not_sim=not_sim)


def _drive_second_pass(s: Search, j: _Judged, options, say: Say) -> bool:
    """The drive's form (current controller, feed-forward) identified again with the judged findings in the replay model
    (:func:`..drive_feedforward.identify`). The first pass replays the nominal model, and an unmodelled torque
    (Coulomb friction) drives its simulated speed, hence the back-EMF the two drives differ by, so far off that it
    cannot see the feed-forward (a drive without it behind a file that says it has one, plus 0.02 N*m of Coulomb
    friction: the file's drive 'reproduced the current best', 0.020 vs 0.046 A; with the friction in the model
    0.023 vs 0.017 A). A result of this pass replaces the first one (against the FILE's setting; a replay that
    cannot follow the recording even with the findings keeps the first). Returns whether the replayed drive
    changed (then the findings are judged again with it)."""
    ctx = s.ctx
    first = ctx.drive_identified
    if first is None or not options.replay:
        return False
    found = [a.effect for a in j.sel.accepted] + [f["effect"] for f in j.special["findings"]]
    if not found:
        return False
    on_file = drive_feedforward.form_of(ctx.params)
    used = drive_feedforward.form_from_updates(ctx.drive_updates, ctx.params)
    model = thermal_net.apply_thermal(j.params_linear, j.special)[0] if j.special["findings"] else j.params_linear
    starts_tr = replay.windows(ctx, options.window_s, options.max_windows, "train")
    second = drive_feedforward.identify(ctx, model.replace(**drive_feedforward.fields(on_file)), starts_tr,
                                        s.starts_holdout, options.window_s, tolerance=options.tolerance,
                                        findings=tuple(found))
    if second["simulation"] is None or second["not_checkable"]:
        say(f"5/6 judge: drive form, second pass with {', '.join(found)}: "
            f"{drive_feedforward.note(second)}; the first pass stands")
        return False
    old_note = drive_feedforward.note(first)
    second["first_pass"] = {"note": old_note, "updated_fields": dict(first["updated_fields"]),
                            "simulation": first["simulation"]}
    for f in second["findings"]:
        f["evidence"].append(f"first pass, the nominal model without those findings: {old_note}")
    ctx.drive_identified = second
    ctx.drive_updates = dict(second["updated_fields"])
    new_note = drive_feedforward.note(second) + f" [second pass, with {', '.join(found)} in the replay model]"
    ctx.notes = [new_note if n == old_note else n for n in ctx.notes]
    if new_note not in ctx.notes:
        ctx.notes.append(new_note)
    now = drive_feedforward.form_from_updates(ctx.drive_updates, ctx.params)
    say(f"5/6 judge: {new_note}" + (f"; the findings are judged again with that drive ({now[0]}, "
                                    f"{drive_feedforward.FIELD}: {str(now[1]).lower()})" if now != used else ""))
    return now != used


def run(s: Search, options, say: Say) -> Judgement:
    t0 = time.perf_counter()
    ctx, lib, sel, special = s.ctx, s.lib, s.selection, dict(s.special)
    linear = [n for n in s.names if n not in SPECIAL]
    starts, win = s.starts_holdout, options.window_s
    simulate = options.replay and bool(starts)
    alias_records: list[dict] = []
    if options.simulation_gate and simulate and sel.aliases:
        # aliased forms: the held-out simulation decides (the simpler one when it cannot tell them apart)
        sel, alias_records = judge.arbitrate_aliases(
            ctx, sel, lambda out: forward_select(ctx, s.located, lib, [n for n in linear if n not in out], options.gate),
            lib, starts, win, progress=lambda m: say(f"4/6 attribute: {m}"))
    if sel.accepted:
        _unexcited_aliases(s, sel, options, say)
    say(f"4/6 attribute: accepted {[a.effect for a in sel.accepted] + [f['effect'] for f in special['findings']] or 'nothing'}; "
        f"{len(sel.not_checkable) + len(special['not_checkable'])} not checkable")

    # practical significance and identifiability, before the final fit and the parameter file
    ff = writeback.final_fit(ctx, sel)
    pars = writeback.effect_parameters(ctx, sel, ff, lib)
    verdicts = _significance(ctx, lib, pars, special["findings"], options)
    dropped = {v.effect for v in verdicts}
    if dropped:
        if any(a.effect in dropped for a in sel.accepted):
            sel.accepted = [a for a in sel.accepted if a.effect not in dropped]
            ff, pars = _refit_linear(s, sel)
        special["findings"] = [f for f in special["findings"] if f["effect"] not in dropped]
        for v in verdicts:
            say(f"5/6 judge: {v.message}")

    # equation-error findings, thermal network, voltage limit: judged by the simulation; then the drive's
    # feed-forward again with those findings in the replay model; when that changes the replayed drive, the same
    # findings are judged again from the start (a wrong drive must neither block nor distort them)
    before = _snapshot(sel, special, verdicts)
    j = _simulated_verdicts(s, sel, ff, pars, special, verdicts, options, say, simulate)
    if simulate and _drive_second_pass(s, j, options, say):
        sel, special, verdicts = before
        j = _simulated_verdicts(s, sel, ff, pars, special, verdicts, options, say, simulate)
    sel, ff, pars, special, verdicts, sim = j.sel, j.ff, j.pars, j.special, j.verdicts, j.sim
    params_linear, notes, not_sim = j.params_linear, j.notes, j.not_sim

    # the drive's behaviour at the voltage limit: only the simulation can see it
    if options.replay:
        with_special = thermal_net.apply_thermal(params_linear, special)[0] if special["findings"] else params_linear
        mode = registry.one(lambda e: e.route is Route.DRIVE_MODE).name
        dm = drive_modes.identify(ctx, with_special, win, wanted=mode in s.names, z=2.0,
                                  tolerance=options.tolerance)
        for k in ("findings", "rejected", "not_checkable"):
            special[k] = special[k] + dm[k]
        if dm["simulation"] is not None:
            sim[mode] = dm["simulation"]
    # the drive's feed-forward: identified before anything was judged, and again with the judged findings
    # (:func:`_drive_second_pass`)
    df = ctx.drive_identified
    if df is not None:
        for k in ("findings", "rejected", "not_checkable"):
            special[k] = special[k] + df[k]
        if df["simulation"] is not None:
            sim[drive_feedforward.EFFECT] = df["simulation"]
    return Judgement(selection=sel, final=ff, parameters=pars, special=special, verdicts=verdicts, simulation=sim,
                     alias_simulation=alias_records, params_linear=params_linear, notes=notes,
                     not_simulated=not_sim, timing={"judge": time.perf_counter() - t0})

