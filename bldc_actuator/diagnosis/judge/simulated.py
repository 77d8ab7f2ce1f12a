"""The simulator as the judge of each finding (issue #7): does the simulated actuator — the project's own kernel,
the code the node runs — reproduce held-out data better WITH the finding than without it?

:func:`simulate_findings`: for every accepted equation-error finding it builds the updated
parameters without that finding (leave one out), replays the held-out windows under all parameter sets in ONE
``BatchActuator`` run (multiple shooting from recorded states, :func:`.simulate.replay`), and compares, window by
window, the simulated error of the finding's channel (speed for torque-side effects, current for voltage-side
and tracking effects). Torque-side findings are judged in the replay driven by the MEASURED current wherever it
is recorded (nothing of the drive's internals needed; each set's current-noise drift taken out,
:func:`noise_drift`), the closed-loop one only where that cannot resolve them and :func:`drive_check` passes.
The noise floor is the spread of that paired difference over windows: a finding is
``confirmed`` when the mean improvement exceeds ``z`` standard errors, ``worsens`` when the other channel gets
worse by more than that AND by more than ``tolerance`` (the practical-significance tolerance, default 5 %) of its
error: a term that fixes its own channel several-fold is not refused for a 1 % side effect the windows resolve.

:func:`arbitrate_aliases` lets the same replay decide between aliased forms (the simpler one when it cannot tell
them apart); :func:`judge_voltage_limit` replays the drive's fitted voltage limit; :func:`judge_thermal` judges
thermal-network findings by the full-length thermal simulation. Plain
data in and out.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from ...kernel import DEAD_TIME_SIGNS
from ..frame import simulate

from ..frame import thermal as thermal_net

from ..frame import writeback
from ..frame.combination import same_equation
from ..effects import Route, registry
from ..effects.record import EQUATION_CHANNEL

#: the simulated channel in which each equation's effects show (voltage-side effects: the drive's q voltage,
#: since the current loop hides them in the current; current when no voltage was recorded)
_CHANNEL = EQUATION_CHANNEL


# torque-side in the equations but drive-side in fact (the current sensors' offsets and gains: the drive acts on
# what they report) is the facet ``Effect.sensor_side``, judged by the closed-loop replay where the drive check
# passes; ``Effect.external_load``: the replay cannot show it when a torque sensor is recorded (its reading is the
# replay's load)


def _speed_scale(ctx, starts: list[int], window_s: float) -> float:
    """RMS of the recorded (filtered) speed over the replayed windows [rad/s]."""
    if "omega_s" not in ctx.sig or not starts:
        return float("nan")
    L = max(5, int(round(window_s * ctx.fs)))
    idx = (np.asarray(starts)[None, :] + np.arange(1, L + 1)[:, None]).ravel()
    return float(np.sqrt(np.mean(np.square(ctx.sig["omega_s"][idx]))))


def _paired(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Mean of a - b and its standard error over windows (:func:`.simulate.mean_se`)."""
    return simulate.mean_se(np.asarray(a, float) - np.asarray(b, float))


def simulate_findings(ctx, sel, pars, lib, starts: list[int], window_s: float, z: float = 2.0,
                      tolerance: float = 0.05) -> dict[str, dict[str, Any]]:
    """Per accepted effect: {"channel", "without", "with", "improvement", "noise_floor", "other_channel_change",
    "verdict": "confirmed" | "not confirmed" | "worsens the simulated <channel>" | "not simulated"}. Empty when
    no held-out windows."""
    if not starts or not sel.accepted:
        return {}
    full, _, _ = writeback.updated_params(ctx, sel, pars, lib)
    effects = [a.effect for a in sel.accepted]
    if any(registry.get(e).replay_form for e in effects) and full.drive.dead_time > 0.0:
        form = dead_time_form(ctx, full, window_s)
        if form is not None and form["chosen"] != full.drive.dead_time_sign:
            ctx.dead_time_sign = form["chosen"]
            full, _, _ = writeback.updated_params(ctx, sel, pars, lib)
    sets = [full]
    for e in effects:
        sub = type(sel)(**{**sel.__dict__, "accepted": [a for a in sel.accepted if a.effect != e]})
        sets.append(writeback.updated_params(ctx, sub, pars, lib)[0])
    res = simulate.replay(ctx, sets, starts, window_s)
    if not res or not res[0].get("available"):
        return {}
    out: dict[str, dict[str, Any]] = {}
    check = drive_check(ctx, res[0])
    # the emulated drive's current loop is reproduced: the drive check passes and the drive-form identification
    # states no limit (:mod:`..drive_feedforward`); only then can the simulated speed refuse a finding that reaches
    # it only through that loop (``Effect.through_drive``)
    limit = (getattr(ctx, "drive_identified", None) or {}).get("limit")
    loop_reproduced = bool(check["ok"]) and limit is None
    loop_why = (limit.short if limit is not None else
                f"the emulated drive misses the recorded current by {check['current_error_rms']:.3g} A RMS (recorded "
                f"{check['current_rms']:.3g} A RMS, its in-band noise {check['current_noise_lowpassed']:.2g} A)")
    # torque-side findings (friction, loads, cogging, inertia, K_t i): judged by the mechanical equation driven by
    # the MEASURED current wherever it is recorded (issue #14): it needs nothing of the drive's internals, which
    # the user rarely knows (a drive without back-EMF feed-forward delivers less than its command while the speed
    # changes, and an emulated drive that assumes otherwise makes a true K_t look wrong). The closed-loop replay
    # stays the judge of drive-side effects, and of a torque-side one only where the measured-current replay
    # cannot resolve it (its sensor noise, integrated over a window, hides a small effect) and the emulated drive
    # reproduces the recorded current (:func:`drive_check`)
    res_cd = None
    if "current" in ctx.have and any(_channel(lib, e) == "velocity" for e in effects):
        res_cd = simulate.replay(ctx, sets, starts, window_s, drive="current")
        if not res_cd or not res_cd[0].get("available"):
            res_cd = None
    w_full = res[0]["per_window"]
    signal = res[0].get("signal_rms") or {}
    temps = any(c in ctx.have for c in ("winding_temperature", "housing_temperature")) and "i_q" in ctx.sig
    th_full = _thermal_holdout(ctx, full, None) if temps else float("nan")
    # a replay that misses the speed by more than the recorded speed itself cannot judge anything in that channel.
    # With a torque sensor recorded the motion is imposed from outside (a dynamometer holding the speed): the
    # finding stands on its equation-error evidence, marked. Without one, :func:`_verdict` refuses it (the
    # simulation does not reproduce the recording: a loop ringing faster than the log, a drive unlike the model)
    speed_scale = _speed_scale(ctx, starts, window_s)
    diverges = math.isfinite(speed_scale) and float(np.mean(w_full["velocity"])) > speed_scale
    for e, r, p_without in zip(effects, res[1:], sets[1:]):
        if p_without == full:   # the simulated actuator cannot hold it: no term, or a value outside its field
            out[e] = {"verdict": "not simulated", "channel": None, "reason": _why_not_simulated(pars.get(e, {}))}
            continue
        ch = _channel(lib, e)
        if ch == "voltage" and w_full.get("voltage") is None:
            ch = "current"
        other = "current" if ch == "velocity" else "velocity"
        if ch == "velocity" and diverges and "torque" in ctx.have:
            out[e] = {"channel": ch, "verdict": "not checkable in simulation",
                      "reason": f"the replay's speed error {float(np.mean(w_full['velocity'])):.3g} rad/s exceeds the "
                                f"recorded speed's own RMS {speed_scale:.3g} rad/s (motion imposed from outside, or "
                                f"the base model far off): judged on the equation error only",
                      "without": float(np.mean(r["per_window"][ch])), "with": float(np.mean(w_full[ch])),
                      "noise_floor": float("nan")}
            continue
        if "torque" in ctx.have and registry.get(e).external_load:
            out[e] = {"channel": ch, "verdict": "not checkable in simulation",
                      "reason": "the torque sensor supplies the load in the replay, so a load term cannot show there",
                      "without": float(np.mean(r["per_window"][ch])), "with": float(np.mean(w_full[ch])),
                      "noise_floor": float("nan")}
            continue
        imposed = diverges and "torque" in ctx.have      # the other channels follow the imposed motion too
        judged_other = loop_reproduced or other != "velocity" or not registry.get(e).through_drive
        closed = _verdict(r["per_window"], w_full, ch, other, z, tolerance, len(starts), window_s,
                          None if imposed else signal, other_judged=judged_other)
        if not judged_other:
            closed["other_channel_not_judged"] = (f"the {other} is not a judge of this finding: it reaches it only "
                                                  f"through the drive's current loop, and {loop_why}")
        closed["replay"] = REPLAY_CLOSED_LOOP
        if ch == "velocity" and res_cd is not None and registry.get(e).sensor_side:
            # the drive's current sensors: the drive itself is in question, the closed loop judges (as before
            # issue #14's third-party set), the measured-current replay only where the drive check fails
            if check["ok"]:
                out[e] = closed
            else:
                k = 1 + effects.index(e)
                out[e] = _verdict(res_cd[k]["per_window"], res_cd[0]["per_window"], ch, None, z, tolerance,
                                  len(starts), window_s, None if imposed else res_cd[0].get("signal_rms"))
                out[e]["replay"] = REPLAY_MEASURED_CURRENT
        elif ch == "velocity" and res_cd is not None:
            k = 1 + effects.index(e)
            cd = _verdict_current_driven(res_cd[k]["per_window"][ch], res_cd[0]["per_window"][ch],
                                         noise_drift(ctx, p_without, window_s), noise_drift(ctx, full, window_s),
                                         z, len(starts), window_s,
                                         None if imposed else (res_cd[0].get("signal_rms") or {}).get(ch))
            if torque_side_replay(cd, closed, check) == REPLAY_CLOSED_LOOP:
                out[e] = dict(closed, measured_current_replay=_brief(cd))
            else:
                out[e] = dict(cd, closed_loop_replay=_brief(closed))
        else:
            out[e] = closed
        out[e]["drive_check"] = check
        if temps and out[e]["verdict"] == "confirmed":
            # the temperatures are simulated channels too (R, R(T) and the torque constant set the heat)
            th_without = _thermal_holdout(ctx, p_without, None)
            loss = th_full - th_without
            floor = max(THERMAL_MIN_KELVIN, THERMAL_MIN_GAIN * th_without)
            out[e]["temperature"] = {"without": th_without, "with": th_full, "noise_floor": floor}
            if math.isfinite(loss) and loss > floor:
                out[e]["verdict"] = "worsens the simulated temperature"
    return out


REPLAY_CLOSED_LOOP = "closed-loop drive emulated from the recorded commands"

REPLAY_MEASURED_CURRENT = "mechanical equation driven by the measured current"


#: a converter form replaces the file's only when its training-window replay error is this much smaller
DEAD_TIME_FORM_GAIN = 0.9


def dead_time_form(ctx, full, window_s: float, max_windows: int = 120) -> dict[str, Any] | None:
    """The converter form of a found dead time (``drive.dead_time_sign``), identified as the drive's
    current-controller form is (:mod:`..drive_feedforward`): the TRAINING windows replayed in closed loop under
    ``full`` with each form; the one that reproduces the recorded current better by :data:`DEAD_TIME_FORM_GAIN`,
    else (the current cannot tell them apart) the one that reproduces the recorded q-voltage better by that
    much, else the file's form. The equation error fits the dead time against the current at each sample (the
    period-start form); a plant that clamps its current at zero (the kernel's default) and one that samples the
    current direction once per period (a switching-cycle averaged converter, motulator's) differ where the line
    currents are within ``(2/3)(h/L) V_dt`` of zero. Sets ``ctx.notes``; returns {"chosen", "errors" (per
    channel and form), "decided_by", "windows"} or None (no training windows)."""
    starts = simulate.windows(ctx, window_s, max_windows, "train")
    if not starts:
        return None
    sets = [full.replace(**{"drive.dead_time_sign": f}) for f in DEAD_TIME_SIGNS]
    res = simulate.replay(ctx, sets, starts, window_s)
    if not res or not res[0].get("available"):
        return None
    channels = ["current"] + (["voltage"] if res[0]["per_window"].get("voltage") is not None else [])
    err = {ch: {f: float(np.mean(r["per_window"][ch])) for f, r in zip(DEAD_TIME_SIGNS, res)} for ch in channels}
    chosen, decided_by = full.drive.dead_time_sign, None
    for ch in channels:     # the first channel whose best form beats the other by the margin decides
        best = min(err[ch], key=err[ch].get)
        if err[ch][best] < DEAD_TIME_FORM_GAIN * max(err[ch].values()):
            chosen, decided_by = best, ch
            break
    unit = {"current": "A", "voltage": "V"}
    note = (f"dead time's converter form: {chosen} (decided by the simulated {decided_by or 'nothing: a tie'}; "
            f"{len(starts)} training windows replayed in closed loop: "
            + "; ".join(f"{ch} error " + ", ".join(f"{f} {err[ch][f]:.3g} {unit[ch]}" for f in DEAD_TIME_SIGNS)
                        for ch in channels)
            + f"; the file's {full.drive.dead_time_sign} unless another is below {DEAD_TIME_FORM_GAIN:g}x, "
              f"current first)")
    if note not in ctx.notes:
        ctx.notes.append(note)
    return {"chosen": chosen, "errors": err, "decided_by": decided_by, "windows": len(starts)}



def _channel(lib, effect: str) -> str:
    """The simulated channel where ``effect`` shows first (velocity for torque-side effects)."""
    eqs = [q for q in lib[effect].equations if q in _CHANNEL]
    return _CHANNEL[eqs[0]] if eqs else "velocity"


def torque_side_replay(cd: dict, closed: dict, check: dict) -> str:
    """Which replay's verdict a torque-side finding gets (:data:`REPLAY_MEASURED_CURRENT` or
    :data:`REPLAY_CLOSED_LOOP`), from the measured-current verdict ``cd``, the closed-loop one ``closed`` and the
    :func:`drive_check` ``check``.

    The measured-current replay decides, unless it cannot resolve the finding (neither better nor worse beyond
    its noise floor, or its speed far off) and the emulated drive reproduces the current; where it is blind (its
    noise drift is its whole error with and without the finding: e0 = e1 = 0) the closed loop judges under the
    raw-noise drive check (builtin kt_frame_10khz: a 10 kHz drive log, 0.043 A RMS current under 0.17 A of noise).
    And where the emulated drive reproduces the recorded current closely, a closed-loop replay that the finding
    makes worse beyond its floor refuses it too: the measured current's own errors (a sensor's, or the torque's
    timing) can favour a spurious term (builtin case r_thermal_30min: a viscous term 0.94 -> 2.97 rad/s in the
    closed loop, "confirmed" 3.19 -> 2.60 driven by the measured current, the drive's current reproduced to 0.2 %
    of its RMS)."""
    decided = cd["verdict"] == "confirmed" or _worse(cd)
    contradicted = check["close"] and (_worse(closed) or str(closed["verdict"]).startswith("worsens"))
    blind = not any(cd["noise_corrected"].values())
    if (not decided and (check["ok"] or (blind and check["ok_raw_noise"]))) \
            or (cd["verdict"] == "confirmed" and contradicted):
        return REPLAY_CLOSED_LOOP
    return REPLAY_MEASURED_CURRENT


def _worse(v: dict) -> bool:
    """The simulated error is larger with the finding than without it beyond the noise floor."""
    if v.get("worse") is not None:
        return bool(v["worse"])
    floor = v.get("noise_floor")
    return bool(v.get("with") is not None and v.get("without") is not None
                and v["with"] - v["without"] > (floor if floor == floor and floor else 0.0))


def _brief(v: dict) -> dict[str, Any]:
    """The other replay's verdict and numbers, reported beside the deciding one."""
    return {k: v.get(k) for k in ("replay", "verdict", "without", "with", "noise_floor")}


def current_noise_rms(ctx) -> float:
    """Per-sample RMS [A] of the recorded q current's sensor noise: what lies above the analysis low-pass,
    scaled up to the whole band as white noise would be."""
    i = np.asarray(ctx.sig["i_q"], float)
    if not len(i):
        return float("nan")
    above = float(np.std(i - ctx.dec.lowpass(i)))
    frac = max(1.0 - ctx.dec.fc / (0.5 * ctx.fs), 0.05)
    return above / math.sqrt(frac)


def current_noise_rms_robust(ctx) -> float:
    """Per-sample RMS [A] of the recorded q current's sensor noise as :func:`current_noise_rms`, with the scale
    of what lies above the low-pass taken robustly (1.4826 x its median absolute deviation): a current STEP puts a
    few samples of large above-band content there that is the signal, not the sensor (current steps of 2-8 A at
    1 kHz: 0.233 A in the standard deviation against 0.015 A of noise)."""
    i = np.asarray(ctx.sig["i_q"], float)
    if not len(i):
        return float("nan")
    r = i - ctx.dec.lowpass(i)
    r = r[np.isfinite(r)]
    if not len(r):
        return float("nan")
    above = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    frac = max(1.0 - ctx.dec.fc / (0.5 * ctx.fs), 0.05)
    return above / math.sqrt(frac)


def current_noise_in_band(ctx, robust: bool = False) -> float:
    """[A] the recorded q current's sensor noise inside the analysis pass band: what a closed-loop replay that
    reproduces the drive exactly still misses the low-passed recording by (the simulated current is compared with
    the LOW-PASSED recording, so only the in-band share of the white noise is left)."""
    if not len(ctx.sig["i_q"]):
        return float("nan")
    sigma = current_noise_rms_robust(ctx) if robust else current_noise_rms(ctx)
    return sigma * math.sqrt(min(ctx.dec.fc / (0.5 * ctx.fs), 1.0))


def noise_drift(ctx, p, window_s: float) -> float:
    """RMS over a window [rad/s] of the speed random walk the current sensor's noise drives in the replay driven
    by the measured current under parameters ``p``: the motor torque ``K n`` integrated over ``J``, white noise
    of per-sample RMS sigma at interval dt: ``(K / J) sigma sqrt(dt T / 2)`` (the mean square of a random walk
    over [0, T] is half its end variance). Low-passing the current does not remove it (the integral sees the
    noise below 1/T). It scales with K / J, so a larger torque constant or a smaller inertia replays WORSE by
    the noise alone (builtin case kt_frame: the true K x1.22 raised the measured-current replay's speed error
    1.26 -> 1.33 rad/s while the closed-loop one fell 0.66 -> 0.31)."""
    sigma = current_noise_rms(ctx)
    m = p.motor
    return float(m.torque_constant_q / m.rotor_inertia * sigma * math.sqrt(window_s / ctx.fs / 2.0))


def _verdict_current_driven(without: np.ndarray, with_: np.ndarray, drift_without: float, drift_with: float,
                            z: float, n: int, window_s: float, signal: float | None) -> dict[str, Any]:
    """The leave-one-out verdict in the replay driven by the measured current, on per-window MEAN SQUARED speed
    errors with each set's expected noise drift (:func:`noise_drift`) taken out: both sets integrate the same
    noise, scaled by their own K / J, so its share of the squared error differs by ``drift_without² -
    drift_with²`` in expectation (the cross term with the model error has zero mean). Reported ``without`` and
    ``with`` are the replay's RMS errors as simulated, ``noise_corrected`` those with the drift taken out
    (floored at 0), ``improvement`` and ``noise_floor`` in that corrected RMS."""
    a, b = np.square(np.asarray(without, float)), np.square(np.asarray(with_, float))
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    imp, se = simulate.mean_se((a - drift_without ** 2) - (b - drift_with ** 2))
    imp_raw, se_raw = simulate.mean_se(a - b)
    # the drift is an estimate (sigma from the current above the low-pass, taken as white): over-estimated it
    # would favour a larger K or a smaller J as surely as the raw errors disfavour them (a 4 s null recording: a
    # spurious J x0.49, raw 0.27 -> 0.55 rad/s, "better" by a drift estimated at 0.33 -> 0.68). So a verdict
    # needs both: confirmed when the corrected AND the raw errors improve beyond their floors, worse when both
    # get worse; else the replay cannot resolve it
    e0 = math.sqrt(max(float(np.mean(a)) - drift_without ** 2, 0.0))
    e1 = math.sqrt(max(float(np.mean(b)) - drift_with ** 2, 0.0))
    # ... and the corrected RMS itself must fall: where the 'noise' drift is as large as the replay's whole error
    # (e0 = e1 = 0 after the correction), what lies above the low-pass is not sensor noise but torque the log
    # cannot resolve (a 100 Hz log of a current ringing against its limit: magnetic saturation 'confirmed' at
    # 7.0 -> 2.3 rad/s raw while the closed loop could not follow at all, 127 rad/s), and the replay driven by
    # that current cannot judge a torque-side term
    better = imp > z * se and imp > 0 and imp_raw > z * se_raw and e0 > e1
    worse = imp < -z * se and imp_raw < -z * se_raw
    raw1 = float(np.sqrt(np.mean(b)))
    if not math.isfinite(imp):
        verdict = "not checkable in simulation"
    elif signal and raw1 > REPRODUCE_MAX * signal and e1 > REPRODUCE_MAX * signal:
        verdict = (f"not checkable in simulation: the simulated actuator does not reproduce this recording's "
                   f"velocity (error {raw1:.3g} RMS = {100 * raw1 / signal:.0f} % of the recorded {signal:.3g} RMS, "
                   f"with every finding)")
    elif better:
        verdict = "confirmed"
    else:
        verdict = "not confirmed"
    # the noise floor in error units: the paired spread of the squared errors, at the mean error level
    scale = 2.0 * max(e0, e1, 1e-12)
    raw0 = float(np.sqrt(np.mean(a)))
    return {"channel": "velocity", "without": raw0, "with": raw1, "improvement": e0 - e1,
            "noise_floor": z * se / scale if math.isfinite(se) else float("nan"),
            "improvement_squared": imp, "noise_floor_squared": z * se, "worse": bool(worse),
            "improvement_squared_raw": imp_raw, "noise_floor_squared_raw": z * se_raw,
            "noise_corrected": {"without": e0, "with": e1},
            "noise_drift": {"without": drift_without, "with": drift_with},
            "other_channel": None, "other_channel_change": None, "verdict": verdict, "windows": n,
            "window_s": window_s, "replay": REPLAY_MEASURED_CURRENT}


#: the emulated drive reproduces the recording when its simulated current misses the recorded (low-passed) one
#: by less than this fraction of the recorded current's RMS, or by less than this many times its sensor noise
DRIVE_CHECK_FRACTION = 0.3
DRIVE_CHECK_NOISE = 1.5
#: ... and reproduces it closely (its closed-loop verdict can then refuse a torque-side finding the measured-current
#: replay confirms) when the error is below this fraction of the recorded current's RMS (the third-party tp_kt
#: drive, no back-EMF feed-forward behind a file that says it has one: 0.33; builtin cases: <= 0.02)
DRIVE_CHECK_CLOSE = 0.1


def drive_check(ctx, full: dict[str, Any]) -> dict[str, Any]:
    """Does the emulated drive (the model's PI current loop from the recorded commands, every finding applied)
    reproduce the recorded current? ``{"current_error_rms", "current_rms", "current_noise",
    "current_noise_lowpassed", "ok", "close"}`` [A].

    The simulated current is compared with the LOW-PASSED recording, so the noise it can be excused is the noise
    left after the low-pass (the sensor's white noise in the pass band), not the raw sensor noise: the
    third-party tp_kt drive (no back-EMF feed-forward behind a file that says it has one) missed the current by
    0.0243 A, within 1.5 x the raw noise 0.0265 A, but far above what the low-pass leaves."""
    err = float(full.get("current_rms", float("nan")))
    sig = float((full.get("signal_rms") or {}).get("current") or float("nan"))
    i = np.asarray(ctx.sig["i_q"], float)
    noise = float(np.std(i - ctx.dec.lowpass(i))) if len(i) else float("nan")
    left = current_noise_in_band(ctx)
    ok = bool(math.isfinite(err) and (err <= DRIVE_CHECK_FRACTION * sig
                                      or (err <= DRIVE_CHECK_NOISE * noise and err <= DRIVE_CHECK_NOISE * left)))
    close = bool(math.isfinite(err) and math.isfinite(sig) and err <= DRIVE_CHECK_CLOSE * sig)
    # the raw-noise rule alone: where the measured-current replay is blind (its noise drift is the whole error),
    # the closed loop is the only judge left, and it is held to this weaker check (builtin kt_frame_10khz: a 10 kHz
    # drive log, current 0.043 A RMS under 0.17 A of sensor noise, error 0.074 A: within the raw noise, not within
    # the low-passed 0.025 A)
    ok_raw = bool(math.isfinite(err) and (err <= DRIVE_CHECK_FRACTION * sig or err <= DRIVE_CHECK_NOISE * noise))
    return {"current_error_rms": err, "current_rms": sig, "current_noise": noise, "current_noise_lowpassed": left,
            "ok": ok, "ok_raw_noise": ok_raw, "close": close}


def _why_not_simulated(p: dict[str, dict]) -> str:
    """Why a finding left the simulated actuator's parameters unchanged (plain words for the report)."""
    out_of_range = [f"{k} = {v['value']:.4g} {v.get('unit', '')}".rstrip() for k, v in p.items()
                    if not k.startswith("_") and isinstance(v.get("value"), (int, float)) and not v.get("field")
                    and v.get("delta") is not None]
    if out_of_range:
        return (f"the fitted {', '.join(out_of_range)} has no place in the simulated actuator (outside what its "
                f"parameter can hold): the simulator cannot reproduce it, so it cannot be shown to help")
    return "the simulated actuator has no term for this form: it cannot be shown to help in simulation"


#: the simulation can judge a channel only where it reproduces the recording at all: with every finding, the
#: simulated error must stay below this fraction of the recorded channel's own RMS (a 100 Hz log of a loop that
#: oscillates faster, or a drive unlike the model, is replayed from inputs that do not represent it: improving a
#: 130 rad/s error by 5 % proves nothing)
REPRODUCE_MAX = 0.5
#: the other channel's error is taken as at least this fraction of its recorded RMS when judging whether a finding
#: worsens it (``tolerance`` x that): a replay that reproduces a channel to a hundredth of its signal resolves no
#: practical worsening below that (issue #24: a noise-free 1 kHz simulate log with twice the Coulomb friction, current
#: replayed to 0.00064 A of 1.06 A RMS: +0.00014 A "worsened" it and refused a finding that took the velocity error
#: from 16 to 1.03 rad/s)
OTHER_CHANNEL_RESOLUTION = 0.01


def _verdict(without: dict, with_: dict, ch: str, other: str, z: float, tolerance: float, n: int,
             window_s: float, signal: dict | None = None, other_judged: bool = True) -> dict[str, Any]:
    """The leave-one-out verdict from per-window simulated errors without and with a finding. The ``other``
    channel refuses it ("worsens") only where it is a judge of it (``other_judged``: not a channel the finding
    reaches only through a drive loop the emulation does not reproduce) and the simulation reproduces that channel
    at all (its error with every finding below :data:`REPRODUCE_MAX` of its recorded RMS)."""
    imp, se = _paired(without[ch], with_[ch])          # error without - error with
    imp_o, se_o = _paired(without[other], with_[other]) if other else (float("nan"), float("nan"))
    sig = (signal or {}).get(ch)
    err = float(np.sqrt(np.mean(np.square(with_[ch])))) if with_.get(ch) is not None else float("nan")
    sig_o = (signal or {}).get(other) if other else None
    if other and sig_o and with_.get(other) is not None and \
            float(np.sqrt(np.mean(np.square(with_[other])))) > REPRODUCE_MAX * sig_o:
        other_judged = False
    if not math.isfinite(imp):
        verdict = "not checkable in simulation"
    elif sig and err > REPRODUCE_MAX * sig:
        verdict = (f"not checkable in simulation: the simulated actuator does not reproduce this recording's {ch} "
                   f"(error {err:.3g} RMS = {100 * err / sig:.0f} % of the recorded {sig:.3g} RMS, with every finding)")
    elif other_judged and math.isfinite(imp_o) and imp_o < -z * se_o and imp_o < -tolerance * max(
            float(np.mean(with_[other])), OTHER_CHANNEL_RESOLUTION * float((signal or {}).get(other) or 0.0)):
        verdict = f"worsens the simulated {other}"
    elif imp > z * se and imp > 0:
        verdict = "confirmed"
    else:
        verdict = "not confirmed"
    return {"channel": ch, "without": float(np.mean(without[ch])), "with": float(np.mean(with_[ch])),
            "improvement": imp, "noise_floor": z * se, "other_channel": other,
            "other_channel_change": -imp_o if math.isfinite(imp_o) else None, "other_channel_judged": other_judged,
            "verdict": verdict, "windows": n, "window_s": window_s}


def judge_voltage_limit(ctx, params_with, finding: dict[str, Any], starts: list[int], window_s: float,
                        z: float = 2.0, tolerance: float = 0.05) -> dict[str, Any]:
    """voltage_saturation (the drive's modulation limit): the held-out windows replayed with the fitted limit and
    with the nominal one; judged on the simulated current (the drive stops tracking its command at the limit),
    the speed being the other channel. When the held-out recording never nears the limit the equation-error check
    fell back to training blocks and the simulation cannot judge it: "not checkable in simulation"."""
    if not finding.get("heldout_nears_limit", True):
        return {"channel": None, "verdict": "not checkable in simulation",
                "reason": "the held-out recording never nears the voltage limit"}
    if not starts:
        return {"channel": None, "verdict": "not checkable in simulation", "reason": "no held-out windows"}
    fld = "drive.modulation_limit"
    without = params_with.replace(**{fld: ctx.params.drive.modulation_limit})
    res = simulate.replay(ctx, [without, params_with], starts, window_s)
    if not res or not res[0].get("available"):
        return {"channel": None, "verdict": "not checkable in simulation", "reason": "no replay"}
    return _verdict(res[0]["per_window"], res[1]["per_window"], "current", "velocity", z, tolerance, len(starts),
                    window_s, res[1].get("signal_rms"))


#: a thermal finding must lower the held-out simulated temperature error by more than this fraction of the
#: error without it, and by more than this many kelvin (temperature sensors resolve ~0.1 K; the thermal
#: network is simulated over the whole recording, so its error is one number per channel, not a spread)
THERMAL_MIN_GAIN = 0.05
THERMAL_MIN_KELVIN = 0.05


def _thermal_holdout(ctx, params, extra_heat) -> float:
    err = thermal_net.thermal_error(ctx, params, extra_heat=extra_heat)
    vals = [err[c]["holdout_rms"] for c in ("winding_temperature", "housing_temperature") if c in err]
    vals = [v for v in vals if math.isfinite(v)]
    return float(math.sqrt(np.mean(np.square(vals)))) if vals else float("nan")


def judge_thermal(ctx, linear_params, thermal: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Per simulated thermal-network finding (thermal_parameters, iron_loss): the held-out temperature error of
    the FULL-LENGTH thermal simulation (driven by the measured current) of the final model with the finding and
    without it (leave one out, every other finding and the linear ones applied). ``confirmed`` when it gains
    more than :data:`THERMAL_MIN_GAIN` and :data:`THERMAL_MIN_KELVIN`; ``worsens the simulated temperature``
    when it loses that much."""
    found = [f for f in thermal.get("findings", []) if f.get("simulated") and registry.get(f["effect"]).route is Route.THERMAL]
    if not found:
        return {}
    full, _, _ = thermal_net.apply_thermal(linear_params, thermal)
    e_with = _thermal_holdout(ctx, full, thermal.get("extra_heat"))
    out: dict[str, dict[str, Any]] = {}
    for f in found:
        sub = dict(thermal, findings=[g for g in thermal["findings"] if g is not f])
        without, _, _ = thermal_net.apply_thermal(linear_params, sub)
        e_without = _thermal_holdout(ctx, without, None if registry.get(f["effect"]).motion_heat else thermal.get("extra_heat"))
        gain = e_without - e_with
        floor = max(THERMAL_MIN_KELVIN, THERMAL_MIN_GAIN * e_without) if math.isfinite(e_without) else float("nan")
        if not (math.isfinite(gain) and math.isfinite(floor)):
            verdict = "not checkable in simulation"
        elif gain > floor:
            verdict = "confirmed"
        elif gain < -floor:
            verdict = "worsens the simulated temperature"
        else:
            verdict = "not confirmed"
        out[f["effect"]] = {"channel": "temperature", "without": e_without, "with": e_with, "improvement": gain,
                            "noise_floor": floor, "verdict": verdict,
                            "method": "full-length thermal simulation from the measured current, held-out samples"}
    return out


def _form_sets(ctx, sel, effect: str, lib):
    """Parameter sets of the selection ``sel`` for the replay: as fitted, then the fitted coefficients of the
    form ``effect`` moved by one standard deviation each way along each principal direction of their covariance
    (the final fit's, :func:`.writeback.final_fit`: autocorrelation-corrected). Returns ``(sets, n_directions)``:
    ``sets[0]`` as fitted, ``sets[1 + 2 j]`` / ``sets[2 + 2 j]`` the + / - step along direction ``j``."""
    ff = writeback.final_fit(ctx, sel)
    sets = [writeback.updated_params(ctx, sel, writeback.effect_parameters(ctx, sel, ff, lib), lib)[0]]
    a = next(x for x in sel.accepted if x.effect == effect)
    idx = [ff.keys.index(k) for k in a.added if k in ff.keys]
    if not idx:
        return sets, 0
    cov = np.asarray(ff.cov, float)[np.ix_(idx, idx)]
    if not np.all(np.isfinite(cov)):
        return sets, 0
    lam, vec = np.linalg.eigh(0.5 * (cov + cov.T))
    n = 0
    for j in range(len(lam)):
        if not lam[j] > 0.0:
            continue
        step = vec[:, j] * math.sqrt(lam[j])
        for sign in (1.0, -1.0):
            beta = np.array(ff.beta, float)
            beta[idx] = beta[idx] + sign * step
            ffj = dataclasses.replace(ff, beta=beta)
            sets.append(writeback.updated_params(ctx, sel, writeback.effect_parameters(ctx, sel, ffj, lib), lib)[0])
        n += 1
    return sets, n


def parameter_spread(e0: float, plus, minus) -> float:
    """Standard deviation [error units] of a replay error ``e(beta_hat)`` that the estimate's own uncertainty
    causes, by the delta method to second order from the errors one standard deviation either way along each
    principal direction of the estimate's covariance (``plus[j]``, ``minus[j]``): ``sum_j a_j^2 + b_j^2 / 2``
    with the first and second central differences ``a_j = (e+ - e-) / 2`` and ``b_j = e+ + e- - 2 e0`` (for a
    quadratic error in independent normal directions: the variance of ``a x + b x^2 / 2``, ``x ~ N(0, 1)``,
    is ``a^2 + b^2 / 2``)."""
    var = 0.0
    for ep, em in zip(plus, minus):
        if not (math.isfinite(ep) and math.isfinite(em) and math.isfinite(e0)):
            return float("nan")
        var += (0.5 * (ep - em)) ** 2 + 0.5 * (ep + em - 2.0 * e0) ** 2
    return math.sqrt(var)


def arbitrate_aliases(ctx, sel, reselect, lib, starts: list[int], window_s: float, z: float = 2.0,
                      progress=None):
    """Aliases decided by the simulator. Equation error chose ``chosen`` over an aliased alternative (their fitted
    contributions correlate > 0.9) by a small margin of held-out equation error; a form with more parameters can
    win that way by fitting noise (on fresh seeds a hidden friction asymmetry was named a position-dependent load:
    sin/cos of the angle + constant, aliased with the constant offset while moving). Here the selection is run again
    without ``chosen`` (``reselect(names_excluded)``) and both models replay the held-out windows: the alternative
    replaces ``chosen`` when it simulates its channel better beyond the noise floor, or — the simulator
    cannot tell them apart — when it has fewer parameters, and it worsens no simulated channel beyond the paired
    window floor. The noise floor is ``z`` times the root sum of squares of the paired window spread (standard
    error of the mean difference over windows) and of each form's :func:`parameter_spread`: both forms replay
    at values fitted on the training data, and an estimate off by a standard deviation or two moves the error of
    EVERY window alike (the replay of a constant torque resolves 1e-4 N*m); a comparison of fitted values is
    not a comparison of forms. Returns the (possibly new) selection and one record per alias examined."""
    say = progress or (lambda m: None)
    records: list[dict[str, Any]] = []
    if not starts:
        return sel, records
    for al in list(sel.aliases):
        chosen = al.get("chosen")
        acc = {a.effect: a for a in sel.accepted}
        if chosen not in acc:
            continue
        alt = next((e for e in al["effects"] if e != chosen), None)
        if alt is None or alt in acc:
            continue
        sel2 = reselect({chosen})
        acc2 = {a.effect: a for a in sel2.accepted}
        if alt not in acc2 or set(acc2) - {alt} != set(acc) - {chosen}:
            records.append({"effects": [chosen, alt], "kept": chosen, "reason": "the selection without "
                            f"{chosen} is not the same model with {alt} in its place"})
            continue
        eqs = [q for q in lib[chosen].equations if q in _CHANNEL]
        ch = _CHANNEL[eqs[0]] if eqs else "velocity"
        sets0, n_dir0 = _form_sets(ctx, sel, chosen, lib)
        sets1, n_dir1 = _form_sets(ctx, sel2, alt, lib)
        rr = simulate.replay(ctx, sets0 + sets1, starts, window_s)
        if not rr or not rr[0].get("available"):
            continue
        r = [rr[0], rr[len(sets0)]]
        if ch == "voltage" and r[0]["per_window"].get("voltage") is None:
            ch = "current"
        gain, se = _paired(r[0]["per_window"][ch], r[1]["per_window"][ch])      # >0: the alternative is better
        # each form's replay error at its fitted values carries that fit's uncertainty: common to every window,
        # it does not average out over them as the paired window spread does (builtin seed 5 `asymmetric`: the
        # friction's Coulomb part fitted 2.2 sd low, 0.009875 +- 0.000057 for 0.01, cost it 0.02 rad/s of
        # held-out speed error; the load form keeps the nominal Coulomb friction and won by +0.0196 > 0.015)
        spread = []
        for sub, n_dir in ((rr[:len(sets0)], n_dir0), (rr[len(sets0):], n_dir1)):
            e = [float(np.mean(x["per_window"][ch])) for x in sub]
            spread.append(parameter_spread(e[0], e[1::2][:n_dir], e[2::2][:n_dir]))
        # (a form whose perturbed replay fails has no spread: the window floor alone, as before)
        par = math.sqrt(sum(x * x for x in spread)) if all(math.isfinite(x) for x in spread) else 0.0
        floor = z * math.sqrt(se * se + par * par)
        worse = []
        for c in ("velocity", "current", "voltage"):
            if c == ch or r[0]["per_window"].get(c) is None:
                continue
            g, s_ = _paired(r[0]["per_window"][c], r[1]["per_window"][c])
            if math.isfinite(g) and g < -z * s_ and g < -0.01 * float(np.mean(r[0]["per_window"][c])):
                worse.append(c)
        n0, n1 = len(acc[chosen].added), len(acc2[alt].added)
        parts = f"windows {z * se:.2g}, the two forms' fitted values {z * par:.2g}"
        both_cols = {**sel2.cols, **sel.cols}
        r2 = same_equation(ctx, both_cols, acc[chosen].added, acc2[alt].added)
        nested = None if r2 is None else f"its columns in the span of {chosen}'s, R² {r2:.5f}"
        r2_back = same_equation(ctx, both_cols, acc2[alt].added, acc[chosen].added)
        if r2_back is not None and registry.get(chosen).external_load and not registry.get(alt).external_load:
            # the external load is one equation with the actuator's own physics on these data (its columns in the
            # span of the alternative's): not preferred to it, as in the selection (frame/selection.py)
            swap, why = True, (f"{chosen}'s columns lie in the span of {alt}'s on these data (R² {r2_back:.5f}): "
                               f"an external load is not preferred to the actuator's own physics it cannot be told "
                               f"from (held-out {ch} error difference {gain:+.3g}); {alt} kept, the two reported as "
                               f"aliases")
        elif nested is not None:
            # the alternative's columns lie in the chosen form's span on every row the equation uses: the two are
            # one model there, and any replay difference is a difference of fitted values, not of forms
            swap, why = False, (f"{alt} is the same equation as {chosen} on these data ({nested}): the simulator "
                                f"cannot separate forms the recording does not (held-out {ch} error difference "
                                f"{gain:+.3g}); {chosen} kept, the two reported as aliases")
        elif not math.isfinite(gain) or worse:
            swap, why = False, f"the alternative worsens the simulated {', '.join(worse) or ch}"
        elif gain > floor:
            swap, why = True, (f"{alt} simulates the held-out {ch} better ({gain:+.3g} > noise floor {floor:.2g}: "
                               f"{parts})")
        elif gain >= -floor and n1 < n0:
            swap, why = True, (f"the held-out simulation cannot tell them apart ({ch} error difference {gain:+.3g}, "
                               f"noise floor {floor:.2g}: {parts}): the simpler form ({n1} vs {n0} parameters) is kept")
        else:
            swap, why = False, (f"{alt} does not simulate the held-out {ch} better beyond the noise floor (error "
                                f"difference {gain:+.3g}, floor {floor:.2g}: {parts}) and has no fewer parameters")
        rec = {"effects": [chosen, alt], "kept": alt if swap else chosen, "channel": ch,
               "error": {chosen: float(np.mean(r[0]["per_window"][ch])), alt: float(np.mean(r[1]["per_window"][ch]))},
               "noise_floor": floor, "window_floor": z * se, "parameter_floor": z * par,
               "parameter_spread": {chosen: spread[0], alt: spread[1]}, "reason": why}
        records.append(rec)
        say(f"alias {chosen} ~ {alt}: {rec['kept']} kept ({why})")
        if swap:
            sel2.aliases = [x for x in sel2.aliases if set(x["effects"]) != {chosen, alt}] + [
                dict(al, chosen=alt, decided_by=why)]
            sel2.rejected = [x for x in sel2.rejected if x.get("effect") != chosen] + [
                {"effect": chosen, "form": acc[chosen].variant.label,
                 "reason": f"explains the same residual as {alt} (aliased); {why}"}]
            sel = sel2
    return sel, records
