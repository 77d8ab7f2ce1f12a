"""Adapters for the real recordings in ``../shared/data`` (read each folder's SOURCE.txt): they return
:class:`~.signals.Signals` with the recording's true semantics (units, sides of the gear, sign
conventions) and say in ``meta`` what they assumed. GPL-3.0 data stay in ``../shared``; nothing here
copies them.

* ``ak80-9``        CubeMars AK80-9 (9:1, 21 pole pairs) on CAN + Futek torque sensor (GPL-3.0)
* ``odrive-d5065``  ODrive D5065 270 KV dynamometer map: steady-state operating points (GPL-3.0)
* ``benkatz-dyno``  MIT dynamometer logs, header-less (MIT licence)

``list_datasets(shared_dir)`` enumerates what is present; ``load_dataset(name, shared_dir)`` loads one
(cleaned by default, with the dataset's own physical limits); ``adapter_for(path)`` lets
:func:`.loaders.load` recognise a file of these datasets by its path.

Sign convention of the AK80-9 adapters: the TORQUE COMMAND defines the + direction. The drive's own
telemetry (current, speed, angle) shares one frame (checked: in ``torque_step_1Nm`` positive current
accelerates positive); it is negated together when it is anti-correlated with the command. The Futek
sensor is aligned separately (its sign is opposite to the motor torque in most files). Every flip is a
``sign_convention`` DataIssue with the correlation that decided it.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .loaders import LoadError, Mapping, load_csv
from .signals import DataIssue, Signals

AK_GEAR = 9.0
AK_POLE_PAIRS = 21
#: physical limits from ak80-9/SOURCE.txt ("filter |i_q|<60, 5<v_bus<60"); the Futek is a +-100 N*m sensor
AK_LIMITS = {"current": 60.0, "current_d": 60.0, "bus_current": 60.0, "torque": 100.0, "torque_command": 100.0,
             "voltage_q": 60.0, "voltage_d": 60.0, "bus_voltage": (5.0, 60.0)}
AK_HINTS = {"gear.gear_ratio": 9.0, "motor.pole_pairs": 21,
            "kt_vendor_N*m/A": 0.091, "kt_lab_N*m/A": 0.115, "current_factor_lab": 0.59,
            "torque_max_mit_N*m": 18.0,
            "note": "TMotorCANControl constants: Kt 0.091 (vendor, 1/Kv_ll), 0.115 (lab), 0.59 'to correct the "
                    "q-axis current': a real current/Kt convention mismatch"}
DEPHY_RATIO = 50.0
DEPHY_SHIFT_S = 3.0
RPM = 2 * math.pi / 60


@dataclass
class DatasetInfo:
    name: str          # e.g. "ak80-9/sysid_final/trial5"
    path: str          # main file (or folder for combined sets)
    kind: str          # "time_series" | "steady_state_points"
    description: str
    licence: str


# ============================================================================================ helpers

def data_dir(shared_dir: str | Path | None = None) -> Path:
    """``shared_dir`` may be the ``shared/`` folder or its ``data/``; default ``<repo>/../shared/data``."""
    if shared_dir is None:
        import os

        env = os.environ.get("BLDC_SHARED_DIR")
        shared_dir = Path(env) if env else Path(__file__).resolve().parents[3] / "shared"
    p = Path(shared_dir)
    if (p / "data").is_dir():
        p = p / "data"
    if not p.is_dir():
        raise FileNotFoundError(f"shared data folder not found: {p}")
    return p


def _licence(folder: Path) -> str:
    try:
        for line in (folder / "SOURCE.txt").read_text().splitlines():
            if line.upper().startswith(("LICENCE", "LICENSE")):
                return line.split(":", 1)[1].strip().split(" (")[0].split(";")[0].strip().rstrip(".")
    except OSError:
        pass
    return "unknown (see SOURCE.txt)"


def _plausible(x: np.ndarray, bound: float) -> np.ndarray:
    return np.isfinite(x) & (np.abs(x) < bound)


def _sign_against(ref: np.ndarray, x: np.ndarray, ok: np.ndarray) -> tuple[int, str]:
    """Sign of x relative to ref: (+1|-1|0, evidence). Correlation when ref varies, else mean product."""
    ok = ok & np.isfinite(ref) & np.isfinite(x)
    if ok.sum() < 10:
        return 0, "too few samples"
    r, y = ref[ok], x[ok]
    if np.std(r) > 1e-9 * max(1.0, np.abs(r).max()) and np.std(y) > 0:
        c = float(np.corrcoef(r, y)[0, 1])
        if abs(c) >= 0.3:
            return (1 if c > 0 else -1), f"correlation {c:+.3f} over {ok.sum()} samples"
        return 0, f"correlation only {c:+.3f}"
    my, sy = float(np.mean(y)), float(np.std(y)) / math.sqrt(len(y))
    if abs(np.mean(r)) > 0 and abs(my) > 5 * sy:
        s = 1 if np.mean(r) * my > 0 else -1
        return s, f"constant command {np.mean(r):+.3g} vs mean {my:+.3g}"
    return 0, "command constant and measurement not clearly signed"


def _premask(sig: Signals, name: str, n: int) -> None:
    """Count samples an adapter masked (and reported) itself, so that cleaning does not report them again."""
    pm = sig.meta.setdefault("premasked", {})
    pm[name] = pm.get(name, 0) + int(n)


def _flip(sig: Signals, names: tuple[str, ...], aux_names: tuple[str, ...] = ()) -> list[str]:
    done = []
    for n in names:
        if n in sig.channels:
            sig.channels[n] = -sig.channels[n]
            done.append(n)
    for n in aux_names:
        if n in sig.meta["aux"]:
            sig.meta["aux"][n] = -sig.meta["aux"][n]
            done.append(n)
    return done


def _align_ak(sig: Signals, cmd: str = "torque_command", fw=("current", "velocity", "position"),
              fw_aux=("motor_measured_torque",)) -> None:
    """Make the drive telemetry and the Futek agree with the command's direction (module docstring)."""
    ch = sig.channels
    ok = _plausible(ch["current"], AK_LIMITS["current"]) if "current" in ch else None
    if cmd in ch and "current" in ch and np.any(ch[cmd][np.isfinite(ch[cmd])] != 0):
        s, why = _sign_against(ch[cmd], ch["current"], ok)
        if s < 0:
            flipped = _flip(sig, fw, fw_aux)
            sig.issues.append(DataIssue(
                "sign_convention", "current", int(ok.sum()), None,
                f"current: the drive's telemetry has the opposite sign of the torque command ({why}); "
                f"the command defines + here", f"negated {', '.join(flipped)}"))
        elif s == 0:
            sig.meta["notes"].append(f"drive telemetry sign vs command undetermined ({why}); kept as recorded")
    if "torque" in ch:
        ref_name = cmd if cmd in ch and np.any(ch[cmd][np.isfinite(ch[cmd])] != 0) else "current"
        okt = _plausible(ch["torque"], AK_LIMITS["torque"]) & (ok if ok is not None else True)
        s, why = _sign_against(ch[ref_name], ch["torque"], okt) if ref_name in ch else (0, "no reference")
        if s == 0:
            s, why = -1, f"undetermined ({why}); SOURCE.txt default applied (Futek opposite to motor torque)"
        if s < 0:
            sig.channels["torque"] = -ch["torque"]
            sig.issues.append(DataIssue(
                "sign_convention", "torque", int(okt.sum()), None,
                f"torque: the Futek reading has the opposite sign of the {ref_name.replace('_', ' ')} ({why})",
                "negated torque"))


# ====================================================================================== AK80-9 files

MIT_COLUMNS = {"time": "loop_time", "torque_command": "motor_torque_command", "torque": "adc_measured_torque",
               "current": "motor_measured_current", "velocity": f"motor_measured_speed*{AK_GEAR:g}"}


def _ak_base_meta(sig: Signals, what: str) -> None:
    sig.meta.update({"dataset": "ak80-9", "gear_ratio": AK_GEAR, "hints": dict(AK_HINTS),
                     "clean_limits": dict(AK_LIMITS), "licence": "GPL-3.0", "description": what})
    sig.meta["semantics"].update({
        "current": "q-axis current reported by the drive (MIT-cheetah / VESC-derived firmware: amplitude-"
                   "invariant dq most likely; NOT converted to the power-invariant frame)",
        "velocity": "drive-reported speed at the output x 9 (motor side)"})


def load_ak_mit_log(path: str | Path) -> Signals:
    """MIT-mode logs (sysid_final, sysid_early, torque_performance_max_curr, no_torque_tests,
    torque_vs_angle/*/test-opposing-motor*.csv): 100 Hz; torque command and Futek at the output;
    current q-axis; speed output side (x 9 -> motor side). Known glitches (-504 A, 153 A: CAN decode /
    saturation artefacts) are left for :func:`.cleaning.clean` to find."""
    path = Path(path)
    sig = load_csv(path, Mapping.parse([f"{k}={v}" for k, v in MIT_COLUMNS.items()]),
                   aux={"motor_measured_torque": "motor_measured_torque"}, only_mapped=True)
    _ak_base_meta(sig, "AK80-9 MIT-mode log: torque command, Futek torque, drive current and speed (100 Hz)")
    sig.meta["semantics"].update({
        "torque_command": "motor_torque_command [N*m, output side]",
        "torque": "adc_measured_torque: Futek reaction torque sensor [N*m, output side]"})
    sig.meta["aux_semantics"] = {"motor_measured_torque": "current x Kt x 9 computed by the logging script "
                                                          "(not an independent measurement)"}
    _align_ak(sig)
    _drive_stopped(sig)
    return sig


def _drive_stopped(sig: Signals, min_s: float = 0.3) -> None:
    """Windows where the current telemetry is impossible (beyond +-60 A) while the Futek reads almost
    nothing although the command is large: the drive had stopped (fault) and the log kept its last
    garbage. The model has no fault state, so the torque there is masked (reported)."""
    ch = sig.channels
    if not all(k in ch for k in ("current", "torque", "torque_command")):
        return
    cur, tq, cmd = ch["current"], ch["torque"], ch["torque_command"]
    off = (np.abs(cur) > AK_LIMITS["current"]) & (np.abs(cmd) > 2.0) & (np.abs(tq) < 0.1 * np.abs(cmd))
    if not off.any():
        return
    edges = np.flatnonzero(np.diff(np.concatenate([[0], off.astype(int), [0]])))
    runs = [(a, b) for a, b in zip(edges[::2], edges[1::2]) if sig.time[b - 1] - sig.time[a] >= min_s]
    if not runs:
        return
    n = sum(b - a for a, b in runs)
    a, b = max(runs, key=lambda r: r[1] - r[0])
    for s_, e_ in runs:
        tq[s_:e_] = np.nan
    _premask(sig, "torque", n)
    sig.issues.append(DataIssue(
        "outlier", "torque", n, float(sig.time[runs[0][0]]),
        f"torque: drive stopped: for {n} samples ({len(runs)} window(s), longest t={sig.time[a]:.2f}..{sig.time[b - 1]:.2f} s) "
        f"the command is {np.median(cmd[a:b]):+.3g} N*m but the Futek reads {np.median(np.abs(tq[a:b][np.isfinite(tq[a:b])])) if np.isfinite(tq[a:b]).any() else 0:.3g} N*m "
        f"and the current telemetry is frozen at an impossible {np.median(cur[a:b]):+.4g} A (fault)",
        "masked (NaN): the model has no fault state"))


def load_ak_torque_vs_angle(folder: str | Path) -> Signals:
    """torque_vs_angle/synchronized_trial_N: the AK80-9 holds a constant torque command while a Dephy
    actuator (50:1) slowly back-drives its output; the Dephy angle log (no header; 2 columns t, angle or
    3 columns t, dt, angle) gives the rotor angle: motor angle = Dephy angle / 50 x 9, Dephy time + 3 s
    (the authors' plot script). The direction of the Dephy angle relative to the AK80-9 frame is taken
    from the AK80-9's mean speed (reported)."""
    folder = Path(folder)
    ak = sorted(folder.glob("test-opposing-motor*.csv"))
    dp = folder / "log_mitry_dephy.csv"
    if not ak:
        raise LoadError(f"{folder}: no test-opposing-motor*.csv")
    sig = load_ak_mit_log(ak[0])
    sig.source = str(folder)
    sig.meta["description"] = ("AK80-9 holding a constant torque command while back-driven slowly by a Dephy "
                               "actuator; Futek torque vs rotor angle (torque ripple, direction-dependent friction)")
    if not dp.exists():
        sig.meta["notes"].append("Dephy angle log absent: no position")
        return sig
    try:
        d = np.loadtxt(dp, delimiter=",", ndmin=2)
    except ValueError as exc:
        raise LoadError(f"{dp}: {exc}") from None
    if d.shape[1] not in (2, 3):
        raise LoadError(f"{dp}: expected 2 or 3 columns (t, [dt,] angle), got {d.shape[1]}")
    td, ang = d[:, 0] + DEPHY_SHIFT_S, d[:, -1]
    slope = np.polyfit(td, ang, 1)[0] if len(td) > 2 else 0.0
    v = sig.channels.get("velocity")
    s = -1
    why = "default (trial 4: Dephy angle rises while the AK80-9 output turns negative)"
    if v is not None:
        ok = _plausible(v, 1e4)
        mv, se = float(np.mean(v[ok])), float(np.std(v[ok])) / math.sqrt(max(1, ok.sum()))
        if abs(mv) > 5 * se and slope != 0:
            s = 1 if mv * slope > 0 else -1
            why = f"AK80-9 mean motor speed {mv:+.3g} rad/s vs Dephy angle slope {slope:+.3g} rad/s"
    pos = np.interp(sig.time, td, ang, left=np.nan, right=np.nan) * (s * AK_GEAR / DEPHY_RATIO)
    sig.channels["position"] = pos
    sig.meta["semantics"]["position"] = (f"Dephy output angle / 50 x 9 x ({s:+d}) (motor side, AK80-9 frame), "
                                         f"Dephy time shifted by +{DEPHY_SHIFT_S:g} s, linearly interpolated")
    sig.meta["notes"].append(f"Dephy angle direction: {'same' if s > 0 else 'opposite'} ({why})")
    sig.meta["notes"].append(
        f"Dephy log {dp.name}: {len(td)} samples covering t = {td[0]:.2f}..{td[-1]:.2f} s on the AK80-9 time "
        f"axis; position NaN outside; electrical angle = position x {AK_POLE_PAIRS}")
    sig.meta["aux"]["dephy_angle"] = np.interp(sig.time, td, ang, left=np.nan, right=np.nan)
    return sig


def load_ak_servo_efficiency(path: str | Path) -> Signals:
    """servo_efficiency/Measuring_efficiency_0_A_antagonist<epoch>.csv (servo mode velocity steps against
    an antagonist motor; 10-20 Hz): v_q, i_q, v_bus, i_bus (and i_d, v_d in later files), Futek torque,
    output speed. Time = epoch - first epoch. All-zero telemetry rows (not yet received) are masked.
    Velocity columns are checked against each other (see module notes in docs/realdata.md)."""
    path = Path(path)
    with open(path, newline="") as f:
        header = [h.strip() for h in next(csv.reader(f))]
    cols = {"time": "timestamp (epoch)", "current": "i_q", "voltage_q": "v_q", "bus_voltage": "v_bus",
            "bus_current": "i_bus", "torque": "Futek Torque (Nm)"}
    if "i_d" in header:
        cols.update({"current_d": "i_d", "voltage_d": "v_d"})
    aux = {"duty": "duty", "mosfet_temperature": "mosfet_temp", "antagonist_current": "Antagonist Q-Current (A)",
           "adc_voltage": "ADC Voltage (V)", "velocity_setpoint_out": "des velocity", "error": "error",
           "velocity_column_rad_s": '"velocity (Rad/S)"', "velocity_column_erpm": '"velocity (ERPM)"'}
    m = Mapping()
    for k, v in cols.items():
        if v not in header:
            raise LoadError(f"{path}: expected column {v!r} (header: {', '.join(header)})")
        m.add(k, f'"{v}"')
    sig = load_csv(path, m, aux=aux, only_mapped=True)
    a = sig.meta["aux"]
    rad = a.get("velocity_column_rad_s")
    erpm = a.get("velocity_column_erpm")
    vel, how = None, ""
    if erpm is not None and rad is not None:
        nz = np.isfinite(rad) & np.isfinite(erpm) & (rad != 0)
        ratio = float(np.median(erpm[nz] / rad[nz])) if nz.any() else float("nan")
        expect = 1 / (RPM / AK_POLE_PAIRS / AK_GEAR)  # ERPM per output rad/s = 1804.8
        if abs(ratio / 4010.7 - 1) < 0.01:
            vel = erpm * RPM / AK_POLE_PAIRS
            how = "velocity (ERPM) / 21 x 2 pi/60 (motor side)"
            sig.issues.append(DataIssue(
                "unit_suspect", "velocity", int(nz.sum()), None,
                f"velocity: column 'velocity (Rad/S)' = ERPM / {ratio:.1f}, but ERPM / {expect:.1f} is output rad/s: "
                f"it is {ratio / expect:.3f} x too small (the back-EMF fit agrees with the ERPM column)",
                "velocity taken from the ERPM column"))
        elif abs(ratio / 1718.87 - 1) < 0.01:
            vel = erpm * AK_GEAR
            how = "column labelled 'velocity (ERPM)' x 9: it holds output rad/s in this file"
            sig.issues.append(DataIssue(
                "unit_suspect", "velocity", int(nz.sum()), None,
                f"velocity: column 'velocity (ERPM)' holds output rad/s (max {np.nanmax(np.abs(erpm)):.3g}; "
                f"back-EMF consistent), and 'velocity (Rad/S)' is that divided again by {ratio:.1f}",
                "velocity taken from the column labelled ERPM, as output rad/s x 9"))
        elif nz.any():
            sig.meta["notes"].append(f"velocity columns ERPM/Rad/S ratio {ratio:.1f} not recognised: 'velocity "
                                     f"(Rad/S)' used as output rad/s")
    if vel is None and rad is not None:
        vel, how = rad * AK_GEAR, "velocity (Rad/S) x 9 (output -> motor side)"
    if vel is not None:
        sig.channels["velocity"] = vel
    # placeholder rows: telemetry not yet received
    ch = sig.channels
    zero = (ch["bus_voltage"] == 0) & (ch["current"] == 0) & (ch["voltage_q"] == 0)
    if zero.any():
        for n in ("current", "voltage_q", "bus_voltage", "bus_current", "current_d", "voltage_d"):
            if n in ch:
                _premask(sig, n, int(np.sum(zero & np.isfinite(ch[n]))))
                ch[n][zero] = np.nan
        first = float(sig.time[np.flatnonzero(zero)[0]] - sig.time[0])
        sig.issues.append(DataIssue(
            "nan", "current", int(zero.sum()), first,
            f"current, voltages, bus: {int(zero.sum())} row(s) of all-zero telemetry (v_bus = i_q = v_q = 0): not "
            f"yet received (SOURCE.txt)", "masked (NaN), excluded from fits"))
    t0 = float(sig.time[0])
    sig.time = sig.time - t0
    _ak_base_meta(sig, "AK80-9 servo-mode velocity steps against an antagonist: v_q, i_q, v_bus, Futek torque")
    sig.meta["time_offset_s"] = t0
    sig.meta["semantics"].update({
        "time": "timestamp (epoch) - first epoch [s]",
        "velocity": how,
        "voltage_q": "v_q reported by the VESC-derived servo firmware (amplitude-invariant dq most likely; "
                     "NOT converted)",
        "torque": "Futek Torque (Nm), output side (sign aligned with the current)"})
    sig.meta["notes"].append("duty caps at 0.90 while v_bus sags: voltage saturation is visible (SOURCE.txt)")
    # torque sign vs current (no command column in these files)
    if "torque" in ch:
        ok = _plausible(ch["current"], 60) & _plausible(ch["torque"], 100)
        s, why = _sign_against(ch["current"], ch["torque"], ok)
        if s == 0:
            s, why = -1, f"undetermined ({why}); SOURCE.txt default applied (Futek opposite to motor torque)"
        if s < 0:
            ch["torque"] = -ch["torque"]
            sig.issues.append(DataIssue("sign_convention", "torque", int(ok.sum()), None,
                                        f"torque: the Futek reading has the opposite sign of the current ({why})",
                                        "negated torque"))
    return sig


def load_ak_servo_efficiency_all(folder: str | Path) -> Signals:
    """All servo_efficiency files in one :class:`Signals` (time from their epochs; one segment per file)."""
    folder = Path(folder)
    files = sorted(folder.glob("Measuring_efficiency_*.csv"))
    parts = []
    for f in files:
        try:
            parts.append(load_ak_servo_efficiency(f))
        except LoadError as exc:
            raise LoadError(f"{f}: {exc}") from None
    parts = [p for p in parts if len(p.time)]
    if not parts:
        raise LoadError(f"{folder}: no servo_efficiency files")
    parts.sort(key=lambda p: p.meta["time_offset_s"])
    t0 = parts[0].meta["time_offset_s"]
    names = sorted({n for p in parts for n in p.channels})
    anames = sorted({n for p in parts for n in p.meta["aux"]})
    time, chans, aux, segs, issues, lines = [], {n: [] for n in names}, {n: [] for n in anames}, [], [], []
    k = 0
    for p in parts:
        n = len(p.time)
        time.append(p.time + p.meta["time_offset_s"] - t0)
        for c in names:
            chans[c].append(p.channels.get(c, np.full(n, np.nan)))
        for c in anames:
            v = p.meta["aux"].get(c)
            aux[c].append(v if isinstance(v, np.ndarray) and len(v) == n else np.full(n, np.nan))
        segs.append((k, k + n))
        k += n
        for i in p.issues:
            i.detail = f"{Path(p.source).name}: {i.detail}"
            if i.first_time is not None:
                i.first_time += p.meta["time_offset_s"] - t0
            issues.append(i)
    issues = _merge_issues(issues, len(parts))
    sig = Signals(np.concatenate(time), {c: np.concatenate(v) for c, v in chans.items()}, str(folder), issues,
                  segs, {"aux": {c: np.concatenate(v) for c, v in aux.items()}, "notes": [], "semantics": {}})
    _ak_base_meta(sig, f"AK80-9 servo_efficiency: {len(parts)} files, time from their epochs")
    sig.meta["semantics"].update(parts[-1].meta["semantics"])
    sig.meta["semantics"]["velocity"] = "per file, see issues (ERPM column in the early files)"
    sig.meta["time_offset_s"] = t0
    sig.meta["files"] = [Path(p.source).name for p in parts]
    for p in parts:
        for k, v in p.meta.get("premasked", {}).items():
            _premask(sig, k, v)
    sig.meta["notes"].append("one segment per file; per-file velocity/sign decisions are in the issues")
    return sig


def _merge_issues(issues: list[DataIssue], n_files: int) -> list[DataIssue]:
    """One issue per (kind, channel, action) for a set of files: counts summed, details of the first few."""
    groups: dict[tuple, list[DataIssue]] = {}
    for i in issues:
        groups.setdefault((i.kind, i.channel, i.action), []).append(i)
    out = []
    for (kind, chan, action), items in groups.items():
        if len(items) == 1:
            out.append(items[0])
            continue
        firsts = [i.first_time for i in items if i.first_time is not None]
        shown = "; ".join(i.detail for i in items[:2])
        out.append(DataIssue(kind, chan, sum(i.count for i in items), min(firsts) if firsts else None,
                             f"in {len(items)} of {n_files} files: {shown}"
                             + (f"; ... ({len(items) - 2} more)" if len(items) > 2 else ""), action))
    return out


def load_ak_mit_control(path: str | Path) -> Signals:
    """mit_control_mode_tests/*/log.csv (MIT mode, no Futek, no command column): pi_time, (output_)angle,
    (output_)velocity, current; motor_angle/motor_velocity where logged (else output x 9)."""
    path = Path(path)
    with open(path, newline="") as f:
        header = [h.strip() for h in next(csv.reader(f))]
    m = Mapping()
    m.add("time", "pi_time")
    m.add("current", "current")
    if "motor_angle" in header:
        m.add("position", "motor_angle")
        m.add("velocity", "motor_velocity")
    else:
        a = "output_angle" if "output_angle" in header else "angle"
        v = "output_velocity" if "output_velocity" in header else "velocity"
        m.add("position", f"{a}*{AK_GEAR:g}")
        m.add("velocity", f"{v}*{AK_GEAR:g}")
    aux = {"torque_from_current_out": "output_torque" if "output_torque" in header else "torque",
           "acceleration_out": "output_acceleration" if "output_acceleration" in header else "acceleration"}
    sig = load_csv(path, m, aux=aux, only_mapped=True)
    _ak_base_meta(sig, "AK80-9 MIT-mode control test (no torque sensor, no command column)")
    sig.meta["semantics"]["position"] = "drive-reported angle (motor side; output x 9 where not logged)"
    sig.meta["notes"].append("no command column: replay is impossible; judge on the equation error only")
    if len(sig.time) > 1 and sig.time[1] - sig.time[0] > 0.2:
        sig.meta["notes"].append(f"first row logged {sig.time[1] - sig.time[0]:.2f} s before the rest "
                                 "(start-up artefact; its angle is stale)")
    return sig


def load_ak_servo_static(path: str | Path) -> Signals:
    """servo_static_torque/torque_test_script_<I>_A.csv: current control at I amps with the output locked
    against the Futek; no header and NO time column: time is synthesised at the nominal 100 Hz.
    Columns: ADC V, Futek torque, reported current, velocity [ERPM], (temperature degC)."""
    path = Path(path)
    mm = re.search(r"_(-?[\d.]+)_A\.csv$", path.name)
    d = np.loadtxt(path, delimiter=",", ndmin=2)
    if d.shape[1] not in (4, 5):
        raise LoadError(f"{path}: expected 4 or 5 columns, got {d.shape[1]}")
    n = len(d)
    ch = {"torque": d[:, 1], "current": d[:, 2], "velocity": d[:, 3] * RPM / AK_POLE_PAIRS}
    if mm:
        ch["current_command"] = np.full(n, float(mm.group(1)))
    if d.shape[1] == 5:
        ch["housing_temperature"] = d[:, 4]
    sig = Signals(np.arange(n) * 0.01, ch, str(path), [], [],
                  {"aux": {"adc_voltage": d[:, 0]}, "notes": [], "semantics": {}})
    _ak_base_meta(sig, f"AK80-9 servo-mode locked-rotor current step at {mm.group(1) if mm else '?'} A")
    sig.meta["semantics"].update({
        "time": "SYNTHESISED at the nominal 100 Hz (no time column in the file)",
        "velocity": "ERPM / 21 x 2 pi/60 (motor side)",
        "housing_temperature": "motor-reported temperature (sensor location unknown)",
        "current_command": "from the file name"})
    sig.meta["notes"].append("time synthesised at 100 Hz: the file has no time column")
    ok = _plausible(ch["current"], 60) & _plausible(ch["torque"], 100)
    s, why = _sign_against(ch["current"], ch["torque"], ok)
    if s == 0:
        s, why = -1, f"undetermined ({why}); SOURCE.txt default applied"
    if s < 0:
        sig.channels["torque"] = -ch["torque"]
        sig.issues.append(DataIssue("sign_convention", "torque", int(ok.sum()), None,
                                    f"torque: the Futek reading has the opposite sign of the current ({why})",
                                    "negated torque"))
    return sig


# ======================================================================================= ODrive D5065

ODRIVE_COLUMNS = {
    "bus_voltage": "Input voltage", "housing_temperature": "Test Motor Temperature",
    "current": "Test motor q-axis current", "current_d": "Test motor d-axis current",
    "bus_current": "Test motor Ibus", "torque": "Output Torque", "velocity": "Output Speed"}
ODRIVE_AUX = {"velocity_setpoint": "Output Speed set-point", "output_power": "Output Power",
              "fet_temperature": "Test motor FET temp", "absorber_current_q": "Absorber q-axis current",
              "absorber_current_d": "Absorber d-axis current", "absorber_temperature": "Absorber Motor Temperature"}


def load_odrive_map(path: str | Path) -> Signals:
    """odrive-d5065/odrive_data.csv: 344 STEADY-STATE operating points (not a time series). ``time`` is the
    point index; ``meta["steady_state_points"] = True``. Torque converted from N*mm to N*m. Signs as
    recorded: motoring is negative current, torque and speed (one consistent frame)."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise LoadError(f"{path}: cannot read: {exc.strerror}") from None
    if len(lines) < 4:
        raise LoadError(f"{path}: expected timestamp, names, units and data lines")
    names = [c.strip() for c in lines[1].split(",")]
    units = [c.strip() for c in lines[2].split(",")]
    rows = []
    for k, ln in enumerate(lines[3:], start=4):
        if not ln.strip():
            continue
        try:
            rows.append([float(x) for x in ln.split(",")])
        except ValueError:
            raise LoadError(f"{path}: line {k}: not numbers: {ln[:80]!r}") from None
        if len(rows[-1]) != len(names):
            raise LoadError(f"{path}: line {k}: {len(rows[-1])} fields, header has {len(names)}")
    d = np.asarray(rows)
    col = {n: d[:, i] for i, n in enumerate(names)}
    unit = dict(zip(names, units))
    ch = {}
    for canon, name in ODRIVE_COLUMNS.items():
        if name not in col:
            raise LoadError(f"{path}: expected column {name!r} (have: {', '.join(names)})")
        ch[canon] = col[name].copy()
    if unit.get("Output Torque", "").lower().replace(" ", "") in ("n.mm", "nmm", "n*mm"):
        ch["torque"] = ch["torque"] * 1e-3
    else:
        raise LoadError(f"{path}: Output Torque unit {unit.get('Output Torque')!r}, expected N.mm")
    sig = Signals(np.arange(len(d), dtype=float), ch, str(path), [], [],
                  {"aux": {k: col[v] for k, v in ODRIVE_AUX.items() if v in col}, "notes": [],
                   "semantics": {}})
    sig.meta.update({
        "dataset": "odrive-d5065", "steady_state_points": True, "time_is_index": True, "gear_ratio": 1.0,
        "licence": "GPL-3.0", "recorded_at": lines[0].strip(),
        "description": "ODrive D5065 270 KV four-quadrant dyno map at 48 V: one row = one averaged operating "
                       "point (speed set-point x q-current level)",
        "clean_limits": {"spike_sigma": None, "bus_voltage": (5.0, 60.0)},
        "hints": _odrive_hints(path.parent)})
    sig.meta["semantics"].update({
        "time": "operating-point index (NOT seconds)",
        "torque": "load-cell torque, N*mm -> N*m; sign as recorded (same frame as current and speed)",
        "current": "ODrive measured Iq (negative = motoring in this frame)",
        "current_d": "ODrive measured Id (tens of A at the top speeds: voltage limit / field weakening)",
        "housing_temperature": "thermistor on the test motor (25..37 degC over the run)",
        "velocity": "measured shaft speed (mechanical, direct drive)"})
    sig.meta["notes"].append("steady-state table: no dynamics (inertia, inductance, thermal time constants "
                             "are not identifiable); derivatives are meaningless")
    sp = sig.meta["aux"].get("velocity_setpoint")
    if sp is not None:
        # the speed set-point is positive while the measured speed is negative in this frame
        with np.errstate(divide="ignore", invalid="ignore"):
            r = -ch["velocity"] / sp
        bad = np.isfinite(r) & (np.abs(r - 1) > 0.25)
        if bad.any():
            rows = np.flatnonzero(bad)
            desc = ", ".join(f"row {i + 4}: {ch['velocity'][i]:.4g} rad/s for set-point {sp[i]:.4g}" for i in rows[:5])
            stale = [i for i in rows if i > 0 and ch["current"][i] == ch["current"][i - 1]]
            for name in sig.channels:
                _premask(sig, name, int(np.sum(bad & np.isfinite(sig.channels[name]))))
                sig.channels[name][bad] = np.nan
            sig.issues.append(DataIssue(
                "outlier", "velocity", len(rows), float(rows[0]),
                f"velocity: {len(rows)} operating point(s) did not reach their speed set-point ({desc})"
                + (f"; {len(stale)} of them repeat the previous row's currents exactly (stale)" if stale else ""),
                "masked (NaN) whole row: not a steady operating point"))
    return sig


def _odrive_hints(folder: Path) -> dict:
    hints = {"kv_rpm_per_V": 270.0, "motor.pole_pairs": 7, "drive.bus_voltage": 48.0,
             "kt_from_kv_8.27/Kv_N*m/A": 8.27 / 270}
    try:
        rs, ls = [], []
        for ln in (folder / "motor_param.csv").read_text().splitlines():
            if ln.startswith("Test motor resistance"):
                rs.append(float(ln.split(",")[1]))
            elif ln.startswith("Test motor inductance"):
                ls.append(float(ln.split(",")[1]))
        if rs:
            hints["phase_resistance_ohm_odrive_calibration"] = float(np.mean(rs))
        if ls:
            hints["phase_inductance_H_odrive_calibration"] = float(np.mean(ls))
    except (OSError, ValueError, IndexError):
        pass
    hints["note"] = "pole pairs 7 is the D5065 datasheet value (not in the data)"
    return hints


# ===================================================================================== benkatz-dyno

BENKATZ = {
    "u8_pro_emap": "T-Motor U8 Pro efficiency-map sweep (motoring): torque to ~3 N*m, speed to ~200 rad/s",
    "u8_pro_emap_regen": "T-Motor U8 Pro efficiency-map sweep (regen)",
    "new_controller_u12": "T-Motor U12 run at 137-168 rad/s",
    "friction_test": "torque +-7 N*m, speed -28..11 rad/s sweeps (friction)",
    "spinup_series": "spin-ups to ~440 rad/s at 44-56 V (inertia, back-EMF, voltage limit)",
    "vs_thermal_4a": "geared maxon-based 'vs' drive held at ~4 A: temperature rises 30->46 degC",
    "vs_thermal_4a_2": "geared maxon-based 'vs' drive held at ~4 A: temperature rises 40->65 degC",
}


def load_benkatz(path: str | Path) -> Signals:
    """Header-less dyno logs (~200 Hz, jittery): [t, torque N*m (dyno sensor), speed rad/s (dyno), supply
    V, supply A, flag] (6 columns); 8 columns: [t, torque, speed, V, I, cmd, p1, p2]; 11 columns: the 9-column
    layout [.., cmd, p1, p2, flag] + motor current [mA] + temperature [degC] (inferred, see SOURCE.txt).
    Torque and speed are in one frame (their product is positive when motoring); the supply current is
    the DC bus current, not the motor current. Time starts at 0 (offset in meta)."""
    path = Path(path)
    with open(path) as f:
        first = f.readline()
    ncol = len(first.split(","))
    m = Mapping.parse(["time=#0", "torque=#1", "bus_voltage=#3", "bus_current=#4"])
    aux: dict[str, str] = {}
    semantics = {"torque": "dyno torque sensor [N*m] at the shaft of the motor under test",
                 "bus_voltage": "DC supply voltage [V]", "bus_current": "DC supply current [A] (not motor current)"}
    notes = []
    if ncol == 11:
        m.add("current", "#9*0.001")
        m.add("housing_temperature", "#10")
        aux = {"velocity_output_side": "#2", "cmd": "#5", "flag": "#8"}
        semantics.update({"current": "column 9 [mA] x 0.001: motor current from the test drive (INFERRED; "
                                     "frame unknown)",
                          "housing_temperature": "column 10 [degC] (INFERRED temperature; sensor location unknown)"})
        notes.append("'vs' is a geared drive with unknown ratio: dyno speed kept in aux['velocity_output_side'], "
                     "not as the (motor-side) velocity channel")
    else:
        m.add("velocity", "#2")
        semantics["velocity"] = "dyno speed [rad/s] (direct drive: motor side = shaft)"
        aux = {"flag": "#5"} if ncol == 6 else {"cmd": "#5", "p1": "#6", "p2": "#7"}
    sig = load_csv(path, m, aux=aux, only_mapped=True)
    t0 = float(sig.time[0]) if len(sig.time) else 0.0
    sig.time = sig.time - t0
    sig.meta["semantics"].update(semantics)
    sig.meta["notes"].extend(notes)
    name = path.stem
    sig.meta.update({"dataset": "benkatz-dyno", "licence": "MIT", "gear_ratio": 1.0 if ncol != 11 else None,
                     "time_offset_s": t0, "columns": ncol,
                     "description": BENKATZ.get(name, "Ben Katz dyno log"),
                     "clean_limits": {}})
    if ncol == 11 and "torque" in sig.channels:
        ch = sig.channels
        ok = np.isfinite(ch["current"]) & np.isfinite(ch["torque"])
        s_, why = _sign_against(ch["current"], ch["torque"], ok)
        if s_ < 0:
            ch["torque"] = -ch["torque"]
            sig.issues.append(DataIssue("sign_convention", "torque", int(ok.sum()), None,
                                        f"torque: the dyno torque has the opposite sign of the drive current "
                                        f"({why}): dyno frame vs drive frame", "negated torque"))
    if "flag" in sig.meta["aux"]:
        sig.meta["notes"].append("aux['flag'] = 1 while a test point is measured (the authors average each "
                                 "flag window)")
    return sig


# ============================================================================== registry / dispatch

def _ak_entries(root: Path) -> list[tuple[DatasetInfo, Callable[[], Signals]]]:
    out = []
    lic = _licence(root)
    mit_dirs = {"sysid_final": "torque-command ramps/steps, Futek torque (glitches: -504 A, 153 A in trials 1-3)",
                "sysid_early": "early system-identification runs", "torque_performance_max_curr":
                "torque performance up to 30 N*m command", "no_torque_tests": "zero-torque command runs"}
    for sub, what in mit_dirs.items():
        for f in sorted((root / sub).glob("**/*.csv")):
            try:
                with open(f) as fh:
                    head = fh.readline()
            except OSError:
                continue
            if not head.startswith("loop_time"):
                continue
            stem = f.parent.name if f.name == "log_adc_and_motor.csv" else f.stem
            out.append((DatasetInfo(f"ak80-9/{sub}/{stem}", str(f), "time_series",
                                    f"AK80-9 MIT mode, 100 Hz: {what}", lic),
                        lambda f=f: load_ak_mit_log(f)))
    for d in sorted((root / "torque_vs_angle").glob("synchronized_trial_*")):
        if list(d.glob("test-opposing-motor*.csv")):
            out.append((DatasetInfo(f"ak80-9/torque_vs_angle/{d.name}", str(d), "time_series",
                                    "AK80-9 at constant torque command back-driven by a Dephy (angle log): Futek "
                                    "torque vs rotor angle", lic), lambda d=d: load_ak_torque_vs_angle(d)))
    eff = root / "servo_efficiency"
    files = sorted(eff.glob("Measuring_efficiency_*.csv"))
    if files:
        out.append((DatasetInfo("ak80-9/servo_efficiency", str(eff), "time_series",
                                f"AK80-9 servo-mode velocity steps against an antagonist, {len(files)} files "
                                f"combined (v_q, i_q, v_bus, Futek)", lic),
                    lambda: load_ak_servo_efficiency_all(eff)))
        for f in files:
            ep = f.stem.rsplit("antagonist", 1)[-1]
            out.append((DatasetInfo(f"ak80-9/servo_efficiency/{ep}", str(f), "time_series",
                                    "AK80-9 servo-mode velocity steps against an antagonist (one file)", lic),
                        lambda f=f: load_ak_servo_efficiency(f)))
    for f in sorted((root / "mit_control_mode_tests").glob("*/log.csv")):
        out.append((DatasetInfo(f"ak80-9/mit_control_mode_tests/{f.parent.name}", str(f), "time_series",
                                "AK80-9 MIT-mode control test (current, angle, speed; no torque sensor)", lic),
                    lambda f=f: load_ak_mit_control(f)))
    for f in sorted((root / "servo_static_torque").glob("torque_test_script_*_A.csv")):
        tag = f.stem.replace("torque_test_script_", "")
        out.append((DatasetInfo(f"ak80-9/servo_static_torque/{tag}", str(f), "time_series",
                                "AK80-9 locked rotor at a constant current (servo mode), Futek torque; time "
                                "synthesised at 100 Hz", lic), lambda f=f: load_ak_servo_static(f)))
    return out


def _registry(root: Path) -> list[tuple[DatasetInfo, Callable[[], Signals]]]:
    out = []
    ak = root / "ak80-9"
    if ak.is_dir():
        out += _ak_entries(ak)
    od = root / "odrive-d5065" / "odrive_data.csv"
    if od.exists():
        out.append((DatasetInfo("odrive-d5065/odrive_data", str(od), "steady_state_points",
                                "ODrive D5065 270 KV dyno map at 48 V: 344 steady-state points (Iq, Id, torque, "
                                "speed, temperatures)", _licence(od.parent)), lambda: load_odrive_map(od)))
    bk = root / "benkatz-dyno"
    for f in sorted(bk.glob("*.csv")) if bk.is_dir() else []:
        out.append((DatasetInfo(f"benkatz-dyno/{f.stem}", str(f), "time_series",
                                "MIT dyno log: " + BENKATZ.get(f.stem, "(layout from SOURCE.txt)"), _licence(bk)),
                    lambda f=f: load_benkatz(f)))
    return out


def list_datasets(shared_dir: str | Path | None = None) -> list[DatasetInfo]:
    """Every loadable recording present under ``shared_dir`` (``shared/`` or ``shared/data``)."""
    return [info for info, _ in _registry(data_dir(shared_dir))]


def load_dataset(name: str, shared_dir: str | Path | None = None, *, clean: bool = True, params=None) -> Signals:
    """Load one dataset by name (see :func:`list_datasets`); cleaned with its own limits unless
    ``clean=False``."""
    reg = _registry(data_dir(shared_dir))
    for info, fn in reg:
        if info.name == name:
            sig = fn()
            sig.meta["dataset_name"] = name
            if clean:
                from .cleaning import clean as _clean

                sig = _clean(sig, params=params)
            return sig
    close = [i.name for i, _ in reg if name.split("/")[0] in i.name][:12]
    raise KeyError(f"no dataset named {name!r}" + (f" (e.g. {', '.join(close)})" if close else
                                                   f" (have {len(reg)}: see list_datasets())"))


def adapter_for(path: str | Path) -> Callable[[Path], Signals] | None:
    """The adapter that reads ``path`` if it is a file of one of the known datasets, else None."""
    p = Path(path).resolve()
    parts = p.parts
    for ds in ("ak80-9", "odrive-d5065", "benkatz-dyno"):
        if ds in parts:
            root = Path(*parts[: parts.index(ds) + 1])
            if not (root / "SOURCE.txt").exists():
                return None
            rel = p.relative_to(root).parts
            if ds == "benkatz-dyno" and p.suffix == ".csv":
                return load_benkatz
            if ds == "odrive-d5065" and p.name == "odrive_data.csv":
                return load_odrive_map
            if ds == "ak80-9" and rel:
                sub = rel[0]
                if sub in ("sysid_final", "sysid_early", "torque_performance_max_curr", "no_torque_tests"):
                    try:
                        with open(p) as fh:
                            head = fh.readline()
                    except OSError:
                        return None
                    return load_ak_mit_log if head.startswith("loop_time") else load_ak_mit_control
                if sub == "torque_vs_angle":
                    if p.name.startswith("test-opposing-motor"):
                        return lambda _p, d=p.parent: load_ak_torque_vs_angle(d)
                    return None
                if sub == "servo_efficiency":
                    return load_ak_servo_efficiency
                if sub == "mit_control_mode_tests":
                    return load_ak_mit_control
                if sub == "servo_static_torque":
                    return load_ak_servo_static
            return None
    return None
