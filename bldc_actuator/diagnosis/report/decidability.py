"""Can this recording decide whether physics is missing? The reasons it cannot (:class:`.results.Undecidable`):

* the base model's short-window replay error is many times the recorded signal itself
  (:data:`BASE_REPLAY_MAX`): the simulation does not follow the recording at all, so "no effect helps" says
  nothing about the effects;
* the held-out set is too short (fewer than :data:`MIN_HOLDOUT_WINDOWS` replay windows): the held-out gates
  cannot tell an improvement from noise;
* the current sits at the drive's limit for most of the run (:data:`CLIPPED_MAX`): current-proportional terms
  (torque constant, its frame factor) are not identifiable;
* a large structured residual is left that no catalogued effect explains (:mod:`.residual_structure`);
* a candidate effect passed ΔBIC and improves the held-out part beyond 3 sigma, but that part has too few
  independent chunks for the gate to decide (:func:`undecided_candidates`, from the selection's rejected list).
"""

from __future__ import annotations

from ..results import Undecidable

BASE_REPLAY_MAX = 3.0          #: base replay error / recorded signal RMS above which nothing can be decided
MIN_HOLDOUT_WINDOWS = 25       #: held-out replay windows below which the held-out gates are too weak
CLIPPED_MAX = 0.5              #: fraction of current samples at the limit above which K_t is not decidable

_UNITS = {"velocity": "rad/s", "current": "A", "voltage": "V"}


def base_replay(replay: dict | None, updated: dict | None = None) -> Undecidable | None:
    """The base model's replay error against the recorded signal, per channel (worst). With ``updated`` (the
    replay of the model with the findings) the reason holds only when that model also fails: then even the
    findings are only suspected."""
    if updated and updated.get("available") and base_replay(updated) is None:
        return None
    if not replay or not replay.get("available"):
        return None
    sig = replay.get("signal_rms") or {}
    worst = None
    for ch in ("velocity", "current"):
        err, ref = replay.get(f"{ch}_rms"), sig.get(ch)
        if err is None or not ref or ref <= 0:
            continue
        ratio = err / ref
        if worst is None or ratio > worst[0]:
            worst = (ratio, ch, err, ref)
    if worst is None or worst[0] <= BASE_REPLAY_MAX:
        return None
    ratio, ch, err, ref = worst
    u = _UNITS[ch]
    return Undecidable("base_replay_error",
                       f"the base model's replay error is {ratio:.0f}x the signal ({ch} error RMS {err:.3g} {u} "
                       f"against a recorded {ch} RMS of {ref:.3g} {u} over {replay.get('windows')} windows of "
                       f"{replay.get('window_s', 0):g} s)",
                       "check the parameter file (--params) against this actuator, the channels' units, sides and "
                       "signs (data issues) and the drive mode (a position or speed loop inside the drive is not "
                       "the current-controlled model)", blocking=True)


def holdout(starts_holdout: list, window_s: float, replay: bool) -> Undecidable | None:
    if not replay:
        return None
    n = len(starts_holdout or [])
    if n >= MIN_HOLDOUT_WINDOWS:
        return None
    return Undecidable("holdout_too_short",
                       f"the held-out set has {n} replay window(s) of {window_s:g} s (needs >= {MIN_HOLDOUT_WINDOWS})",
                       "record longer, raise --holdout, or give a second recording with --holdout-file")


def clipped(meta: dict) -> Undecidable | None:
    rec = ((meta or {}).get("clipped") or {}).get("current")
    if not rec or rec.get("fraction", 0.0) < CLIPPED_MAX:
        return None
    levels = ", ".join(f"{v:.4g}" for v in rec.get("levels", []))
    return Undecidable("clipped",
                       f"current at the drive's limit ({levels} A) in {100 * rec['fraction']:.0f} % of the samples: "
                       f"current-proportional terms (torque constant, frame factor) are not identifiable",
                       "record with the current inside the drive's limit (smaller commands or loads), or raise the "
                       "limit")


def outside_catalogue(structures) -> list[Undecidable]:
    return [Undecidable("outside_catalogue", f"physics outside the catalogue: {s.describe()}",
                        "look at the residual plots where it sits; a named effect may need another form, or the "
                        "setup has something the model does not hold (a load, a controller, a sensor artefact)")
            for s in structures if s.large]


def undecided_candidates(rejected: list[dict]) -> list[Undecidable]:
    """One reason per candidate the held-out gate could not decide (``verdict: not_decidable`` in the
    selection's rejected list): a large effect is neither found nor absent on this held-out part."""
    return [Undecidable("candidate_not_decidable", f"{r['effect']} ({r.get('form', '')}): {r.get('reason', '')}",
                        r.get("remedy") or "record a longer held-out part with more varied motion (or give "
                                           "--holdout-file)")
            for r in rejected if r.get("verdict") == "not_decidable"]
