"""What a recording's drive tuned its current loop with (one module for the writers that declare it and the
diagnosis that reads it, like :mod:`bldc_actuator.voltage_timing`).

A drive's current loop is tuned on ITS model of the motor (K_p = 2 pi f L, K_i = 2 pi f R) and feeds forward its
K omega: the ``drive.controller_*`` fields, 0 standing for the motor's own value. The diagnosis replays a recording
with the drive it was made with, so a finding that changes the motor (R, L, K) does not retune the drive
(:func:`bldc_actuator.params.keep_controller_of`); without a declaration that drive is taken as tuned on the
nominal motor (``--params``). A drive that calibrates itself (ODrive's motor calibration measures R and L) and this
project's simulator (``bldc-actuator simulate``: its drive is tuned on the simulated motor) are not: a writer that
knows the values declares them, in a CSV's leading ``# key: value`` comment lines (:func:`declaration`), and
:func:`from_metadata` reads them back.
"""

from __future__ import annotations

import math

from .params import CONTROLLER_FIELDS, ActuatorParams, controller_motor

#: metadata key -> (drive field, unit): the values the drive's current loop was tuned with, SI
KEYS = {"drive_tuned_with_phase_resistance_ohm": ("drive.controller_resistance", "ohm"),
        "drive_tuned_with_q_inductance_h": ("drive.controller_inductance", "H"),
        "drive_tuned_with_torque_constant_q_nm_per_a": ("drive.controller_torque_constant", "N*m/A")}
assert [f for f, _ in KEYS.values()] == list(CONTROLLER_FIELDS)


def declaration(params: ActuatorParams) -> dict[str, str]:
    """``str -> str`` metadata pairs: the R, L, K the drive of ``params`` is tuned with
    (:func:`bldc_actuator.params.controller_motor`)."""
    return {k: repr(float(v)) for k, v in zip(KEYS, controller_motor(params))}


def from_metadata(meta: dict, source: str) -> dict[str, float] | None:
    """{drive field: value} the metadata declares (None when it declares none); a malformed value is an error
    naming the key, its expected range and unit."""
    out = {}
    for key, (field, unit) in KEYS.items():
        raw = meta.get(key)
        if raw is None or raw == "":
            continue
        try:
            v = float(raw)
        except (TypeError, ValueError):
            raise ValueError(f"{source}: {key}: expected a positive number in {unit}, got {raw!r}") from None
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{source}: {key}: expected a positive number in {unit}, got {raw!r}")
        out[field] = v
    return out or None


def declared(recordings) -> dict[str, float] | None:
    """The tuning the recordings declare (``meta["declared"]`` comment pairs); None when none does. Recordings that
    declare different tunings are an error (diagnose them apart)."""
    found = []
    for sig in recordings:
        meta = getattr(sig, "meta", {}) or {}
        t = from_metadata(meta.get("declared") or {}, getattr(sig, "source", "") or "recording")
        if t is not None:
            found.append(t)
    if not found:
        return None
    if any(f != found[0] for f in found[1:]):
        raise ValueError("drive tuning: the recordings declare different current-loop tunings "
                         f"({'; '.join(map(str, found))}): diagnose them apart")
    return found[0]


def apply(params: ActuatorParams, tuning: dict[str, float] | None) -> tuple[ActuatorParams, str | None]:
    """``params`` with the drive's model of the motor set to the declared ``tuning``, and a note for the report
    (None when nothing changes)."""
    if not tuning:
        return params, None
    before = dict(zip(CONTROLLER_FIELDS, controller_motor(params)))
    changed = {f: v for f, v in tuning.items() if not math.isclose(before[f], v, rel_tol=1e-9)}
    if not changed:
        return params, None
    note = ("the recording declares the motor values its drive's current loop was tuned with; the replay's drive "
            "uses them, not --params': " + ", ".join(f"{f} {v:.4g} (--params {before[f]:.4g})"
                                                    for f, v in changed.items()))
    return params.replace(**changed), note
