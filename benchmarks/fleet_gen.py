"""A generated fleet: N actuators x M days of short recordings in three log formats, with planted drifts.

Every recording is simulated with the project's :class:`~bldc_actuator.model.Actuator` from the TRUE
parameters of that actuator on that day, then written the way its robot logs:

``mcap``         ``<root>/<robot>/<joint>/<YYYY-MM-DD>.mcap`` written with
                 :class:`~bldc_actuator.recording.McapRecorder` with the node's topics and messages
                 (``/joint_states`` (output side), ``/<joint>/q_axis_state`` (labelled Float64MultiArray of
                 ``node.Q_AXIS_FIELDS``), ``/<joint>/winding_temperature``, ``/<joint>/housing_temperature``,
                 ``/<joint>/current_command``), the NOMINAL parameters in the metadata (as a node started
                 from the fleet's parameter file records them) and ``start_time`` (ISO 8601) in the metadata.
``wide_csv``     ``<root>/<robot>/<YYYY-MM-DD>_joints.csv``: one row per sample, ``time`` [s] and
                 ``Position<j>`` [rad, output], ``Velocity<j>`` [rad/s, output], ``Cur<j>`` [A, q-axis],
                 ``CurCmd<j>`` [A], ``Torque<j>`` [N*m, the drive's output-torque estimate K_t,nom i N],
                 ``Temp<j>`` [degC, housing] for joints j = 1..n (several actuators per file).
``output_csv``   ``<root>/<robot>/<joint>/<YYYY-MM-DD>.csv``: ``t,q_out,dq_out,iq,iq_ref,temp_winding``:
                 angles and speeds at the OUTPUT (a loader must multiply by the gear ratio).

Planted drifts (``drift`` of :class:`Unit`), over ``days`` days starting 2026-01-01:

``friction``  Coulomb friction rising linearly by +40 % over 30 days (continuing at that rate),
``r_ha``      housing-to-ambient thermal resistance rising linearly by +30 % over 30 days,
``kt_step``   torque constant falling by 5 % as a step half-way through (an over-temperature event),
``None``      stable.

Excitation (every recording, ``duration`` s at ``rate`` Hz): a multi-sine current command (random phases
per day) that moves the joint both ways over a range of speeds, so friction, viscous damping and K_t
separate. The actuator starts WARM (housing ``warm_start_K`` above ambient, as after work), so the housing
cools through R_ha during the recording: with the fleet's thermal time constant R_ha C_h of about 40 s a
20 s recording shows the cooling rate, which makes R_ha identifiable (the verification is
``test_fleet.py::test_r_ha_identifiable``).

Usage::

    python benchmarks/fleet_gen.py OUT_DIR [--actuators 8] [--days 30] [--duration 20] [--rate 250]
                                   [--loop open|closed] [--noise 1.0] [--stable]

``--loop closed``: a joint controller (PD on the output angle at the log rate, current command from the
nominal K_t and gear) follows smooth swings with two standstill holds instead of the open-loop multi-sine
current (:func:`run_closed_loop`); ``--noise 0``: no sensor noise (quantisation stays); ``--stable``: no
planted drift. In Python, :class:`Unit` ``schedule`` sets exact per-day true values and ``generate(...,
unfinalized=k)`` cuts the last k MCAP files short (a recorder that never closed them).

Writes ``OUT_DIR/params.yaml`` (the nominal parameters every diagnosis starts from), ``OUT_DIR/truth.json``
(which actuator drifts in which parameter) and the recordings.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:
    sys.path.insert(0, str(HERE.parent))

from bldc_actuator.model import Actuator  # noqa: E402
from bldc_actuator.params import ActuatorParams, dump_yaml  # noqa: E402
from bldc_actuator.profiles import Profile  # noqa: E402

START = dt.datetime(2026, 1, 1, 8, 0, 0, tzinfo=dt.timezone.utc)
FORMATS = ("mcap", "wide_csv", "output_csv")

#: the drift that is planted -> (tracked parameter name, what a correct alert says)
DRIFT_PARAMETER = {"friction": "coulomb_friction", "r_ha": "housing_to_ambient_resistance",
                   "kt_step": "torque_constant_q"}


def nominal_params() -> ActuatorParams:
    """The fleet's datasheet parameters: a small geared joint (9:1) with a light, fast thermal network."""
    return ActuatorParams().replace(**{
        "gear.gear_ratio": 9.0,
        "drive.current_loop_rate": 4000.0,
        "drive.current_loop_bandwidth": 500.0,
        "motor.phase_resistance": 0.5,
        "motor.rotor_inertia": 2.0e-3,
        "motor.viscous_damping": 2.0e-4,
        "effects.coulomb_friction": 0.03,
        "thermal.winding_heat_capacity": 3.0,
        "thermal.housing_heat_capacity": 20.0,
        "thermal.winding_to_housing_resistance": 1.0,
        "thermal.housing_to_ambient_resistance": 2.0,
        "thermal.ambient_temperature": 25.0,
    })


@dataclass
class Unit:
    """One actuator of the fleet."""

    actuator_id: str          #: e.g. ``robot1/knee``
    fmt: str                  #: one of FORMATS
    drift: str | None = None  #: one of DRIFT_PARAMETER or None
    joint_index: int = 0      #: column number in a wide CSV (1-based), 0 otherwise
    #: exact true values per day, overriding spread and drift: ``{"effects.coulomb_friction": (0.010, 0.016,
    #: ...)}`` (the last value is kept after the schedule ends)
    schedule: dict = None


def _stable(text: str) -> int:
    """A seed from a name that does not change between processes (``hash`` of a str does)."""
    return zlib.crc32(text.encode())


def true_params(nominal: ActuatorParams, unit: Unit, day: int, days: int, rng: np.random.Generator,
                drift_days: float = 30.0) -> ActuatorParams:
    """The actuator's true parameters on ``day`` (0-based): unit-to-unit spread (1 %) plus the planted drift
    (full size after ``drift_days`` days: +40 % friction, +30 % R_ha; the K_t step at ``days // 2``)."""
    f = nominal.to_flat()
    spread = np.random.default_rng(_stable(unit.actuator_id)).normal(0.0, 0.01, 4)
    coulomb = f["effects.coulomb_friction"] * (1 + spread[0])
    r_ha = f["thermal.housing_to_ambient_resistance"] * (1 + spread[1])
    kt = f["motor.torque_constant_q"] * (1 + 0.3 * spread[2])
    visc = f["motor.viscous_damping"] * (1 + spread[3])
    if unit.drift == "friction":
        coulomb *= 1 + 0.40 * day / drift_days
    elif unit.drift == "r_ha":
        r_ha *= 1 + 0.30 * day / drift_days
    elif unit.drift == "kt_step" and day >= days // 2:
        kt *= 0.95
    warm = 12.0 + 6.0 * rng.random()
    Ta = f["thermal.ambient_temperature"]
    values = {"effects.coulomb_friction": coulomb, "thermal.housing_to_ambient_resistance": r_ha,
              "motor.torque_constant_q": kt, "motor.viscous_damping": visc,
              "thermal.initial_housing_temperature": Ta + warm, "thermal.initial_winding_temperature": Ta + warm + 2.0}
    for name, per_day in (unit.schedule or {}).items():
        values[name] = float(per_day[min(day, len(per_day) - 1)])
    return nominal.replace(**values)


def command(duration: float, rate: float, rng: np.random.Generator) -> Profile:
    """Multi-sine q-current command [A] with random phases: both directions, motor speeds up to ~120 rad/s, below the voltage limit."""
    t = np.arange(int(round(duration * rate)) + 1) / rate
    freqs = np.array([0.37, 0.83, 1.9, 4.1])
    amps = np.array([1.3, 1.0, 0.8, 0.5])
    ph = rng.uniform(0, 2 * np.pi, len(freqs))
    i = (amps[:, None] * np.sin(2 * np.pi * freqs[:, None] * t[None, :] + ph[:, None])).sum(axis=0)
    i += 0.4 * np.sign(np.sin(2 * np.pi * 0.13 * t + rng.uniform(0, 2 * np.pi)))   # slow bias: heat, asymmetry
    return Profile(t, i, "current", name="fleet multisine")


def reference(duration: float, rate: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Output-angle reference [rad] and its rate [rad/s] of a closed-loop day: smooth swings both ways
    (a joint at work) with two standstill holds, random phases per day."""
    t = np.arange(int(round(duration * rate)) + 1) / rate
    freqs = np.array([0.11, 0.29, 0.53])
    amps = np.array([0.9, 0.45, 0.2])
    ph = rng.uniform(0, 2 * np.pi, len(freqs))
    # two holds of 2 s (where a joint rests): the reference stays where it was
    speed = np.ones_like(t)
    for start in (0.3 * duration, 0.7 * duration):      # the reference's speed ramps to 0 and back in 0.5 s
        speed *= np.clip(np.abs(t - (start + 1.0)) / 0.5 - 1.5, 0.0, 1.0)
    # warp time: where speed is 0 the reference stands still
    tw = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))])
    theta = (amps[:, None] * np.sin(2 * np.pi * freqs[:, None] * tw[None, :] + ph[:, None])).sum(axis=0)
    theta = theta - theta[0]
    return theta, np.gradient(theta, t)


def run_closed_loop(p: ActuatorParams, duration: float, rate: float, rng: np.random.Generator,
                    kp_out: float = 20.0, kd_out: float = 1.0) -> dict[str, np.ndarray]:
    """A joint controller at ``rate``: PD on the OUTPUT angle (gains [N*m/rad], [N*m*s/rad] at the output),
    its torque turned into a q-current command with the NOMINAL-file K_t and gear (what the drive believes),
    held until the next sample; every sample the model's outputs are recorded before the new command."""
    theta_ref, omega_ref = reference(duration, rate, rng)
    act = Actuator(p)
    k_cmd = 1.0 / (p.motor.torque_constant_q * p.gear.gear_ratio)
    i_lim = p.drive.current_limit
    dt_ns = int(round(1e9 / rate))
    rows = []
    for k in range(len(theta_ref)):
        o = act.outputs()
        rows.append(o)
        tau = kp_out * (theta_ref[k] - o["position_out"]) + kd_out * (omega_ref[k] - o["velocity_out"])
        act.set_current_command(float(np.clip(tau * k_cmd, -i_lim, i_lim)))
        if k + 1 < len(theta_ref):
            act.step_ns(dt_ns)
    keys = [k for k, v in rows[0].items() if isinstance(v, (int, float, bool, np.bool_))]
    return {k: np.array([r[k] for r in rows], dtype=float) for k in keys}


def simulate(p: ActuatorParams, duration: float, rate: float, rng: np.random.Generator, *, noise: float = 1.0,
             loop: str = "open") -> dict[str, np.ndarray]:
    """Run the command through the model; return signals with measurement noise (``noise`` x the default
    sensor noise; 0: none) and quantisation (the 14-bit encoder, 0.01 K temperatures; kept at ``noise=0``).
    ``loop``: ``"open"`` (the multi-sine current command of :func:`command`) or ``"closed"`` (the joint
    controller of :func:`run_closed_loop` following :func:`reference`)."""
    if loop == "closed":
        res = run_closed_loop(p, duration, rate, rng)
    elif loop == "open":
        res = Actuator(p).run(command(duration, rate, rng))
    else:
        raise ValueError(f"loop: expected 'open' or 'closed', got {loop!r}")
    n = len(res["t"])
    enc = 2 * np.pi / 2 ** 14                                   # 14-bit output encoder
    out = {
        "t": res["t"],
        "i_q_ref": res["i_q_ref"],
        "i_q": res["i_q"] + noise * rng.normal(0, 0.03, n),
        "i_d": res["i_d"] + noise * rng.normal(0, 0.03, n),
        "v_q": res["v_q"] + noise * rng.normal(0, 0.02, n),
        "v_d": res["v_d"],
        "omega": res["omega"],
        "position_out": np.round(res["position_out"] / enc) * enc,
        "velocity_out": res["velocity_out"] + noise * rng.normal(0, 0.01, n),
        "effort_out": res["effort_out"],
        "T_winding": np.round(res["T_winding"] + noise * rng.normal(0, 0.05, n), 2),
        "T_housing": np.round(res["T_housing"] + noise * rng.normal(0, 0.05, n), 2),
        "v_limit_q": res["v_limit_q"], "v_magnitude_q": res["v_magnitude_q"],
        "torque_em": res["torque_em"], "current_limit_effective": res["current_limit_effective"],
        "joule_power": res["joule_power"], "resistance_phase": res["resistance_phase"],
        "voltage_saturated": res["voltage_saturated"],
    }
    out["bus_voltage"] = np.full(n, p.drive.bus_voltage)
    out["tripped"] = np.zeros(n)
    return out


# -------------------------------------------------------------------------------------------- writers

def write_mcap(path: Path, sig: dict, nominal: ActuatorParams, actuator_id: str, start: dt.datetime) -> None:
    """As the node records: same topics, message types, labelled q-axis layout, nominal parameters."""
    from sensor_msgs.msg import JointState, Temperature
    from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension

    from bldc_actuator.node import Q_AXIS_FIELDS
    from bldc_actuator.recording import McapRecorder

    path.parent.mkdir(parents=True, exist_ok=True)
    joint = actuator_id.split("/")[-1]
    ns = f"/{joint}"
    meta = {"node": ns, "start_time": start.isoformat(), "actuator_id": actuator_id}
    with McapRecorder(path, parameters=nominal.to_flat(), metadata=meta) as rec:
        q = Float64MultiArray()
        q.layout.dim = [MultiArrayDimension(label=",".join(Q_AXIS_FIELDS), size=len(Q_AXIS_FIELDS),
                                            stride=len(Q_AXIS_FIELDS))]
        last_cmd = None
        for k in range(len(sig["t"])):
            t_ns = int(round(sig["t"][k] * 1e9))
            sec, nsec = divmod(t_ns, 1_000_000_000)
            j = JointState(name=[joint])
            j.header.stamp.sec, j.header.stamp.nanosec = sec, nsec
            j.position = [float(sig["position_out"][k])]
            j.velocity = [float(sig["velocity_out"][k])]
            j.effort = [float(sig["effort_out"][k])]
            q.data = [float(sig[f][k]) for f in Q_AXIS_FIELDS]
            rec.write("/joint_states", j, t_ns)
            rec.write(f"{ns}/q_axis_state", q, t_ns)
            for name, key in (("winding_temperature", "T_winding"), ("housing_temperature", "T_housing")):
                m = Temperature(temperature=float(sig[key][k]))
                m.header.stamp = j.header.stamp
                rec.write(f"{ns}/{name}", m, t_ns)
            c = float(sig["i_q_ref"][k])
            if c != last_cmd:
                rec.write(f"{ns}/current_command", Float64(data=c), t_ns)
                last_cmd = c


def write_wide_csv(path: Path, sigs: list[dict]) -> None:
    """Several joints side by side, one row per sample (the first joint's clock)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    t = sigs[0]["t"]
    cols = {"time": t}
    for j, s in enumerate(sigs, start=1):
        cols[f"Position{j}"] = s["position_out"]
        cols[f"Velocity{j}"] = s["velocity_out"]
        cols[f"Cur{j}"] = s["i_q"]
        cols[f"CurCmd{j}"] = s["i_q_ref"]
        cols[f"Torque{j}"] = s["effort_out"]
        cols[f"Temp{j}"] = s["T_housing"]
    _write_csv(path, cols)


def write_output_csv(path: Path, sig: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_csv(path, {"t": sig["t"], "q_out": sig["position_out"], "dq_out": sig["velocity_out"],
                      "iq": sig["i_q"], "iq_ref": sig["i_q_ref"], "temp_winding": sig["T_winding"]})


def _write_csv(path: Path, cols: dict[str, np.ndarray]) -> None:
    names = list(cols)
    data = np.column_stack([cols[n] for n in names])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.7g")


# -------------------------------------------------------------------------------------------- fleet

def default_units(n_actuators: int) -> list[Unit]:
    """The drifting three first, then stable ones; formats mixed: every format has a stable unit when
    n_actuators >= 6. Wide-CSV units share a robot (one file per day holds all of them)."""
    plan = [("robot1/knee", "mcap", "friction"), ("robot2", "wide_csv", "r_ha"), ("robot3/hip", "output_csv", "kt_step"),
            ("robot1/ankle", "mcap", None), ("robot2", "wide_csv", None), ("robot3/knee", "output_csv", None)]
    k = 0
    while len(plan) < n_actuators:
        fmt = FORMATS[k % 3]
        plan.append((f"robot4/joint{k}" if fmt == "mcap" else "robot2" if fmt == "wide_csv"
                     else f"robot5/joint{k}", fmt, None))
        k += 1
    units, wide = [], 0
    for name, fmt, drift in plan[:n_actuators]:
        if fmt == "wide_csv":
            wide += 1
            units.append(Unit(f"{name}/joint{wide}", fmt, drift, wide))
        else:
            units.append(Unit(name, fmt, drift))
    return units


def generate(root: str | Path, n_actuators: int = 8, days: int = 30, duration: float = 20.0, rate: float = 250.0,
             seed: int = 1, corrupt: int = 0, progress: bool = False, drift_days: float = 30.0,
             units: list[Unit] | None = None, formats: tuple[str, ...] = FORMATS, loop: str = "open",
             noise: float = 1.0, nominal_overrides: dict | None = None, unfinalized: int = 0) -> dict:
    """Write the fleet under ``root``; returns the truth (also written to ``root/truth.json``).
    ``corrupt`` > 0 adds that many corrupt files (truncated MCAP / garbage CSV) that a run must report;
    ``units`` replaces :func:`default_units`; ``formats`` keeps only the units logging in those formats;
    ``loop``/``noise``: see :func:`simulate`; ``nominal_overrides``: flat fields of the fleet's parameter file
    (e.g. ``{"effects.coulomb_friction": 0.010}``); ``unfinalized`` > 0: that many of the last MCAP files are
    cut back to 60 % of their size (a recorder that never closed them: readable up to the cut)."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    nominal = nominal_params()
    if nominal_overrides:
        nominal = nominal.replace(**nominal_overrides)
    (root / "params.yaml").write_text(dump_yaml(nominal))
    units = [u for u in (units or default_units(n_actuators)) if u.fmt in formats]
    files: list[str] = []
    for day in range(days):
        start = START + dt.timedelta(days=day)
        stamp = start.strftime("%Y-%m-%d")
        wide = []
        for u in units:
            rng = np.random.default_rng([seed, day, _stable(u.actuator_id)])
            sig = simulate(true_params(nominal, u, day, days, rng, drift_days), duration, rate, rng, noise=noise,
                           loop=loop)
            if u.fmt == "mcap":
                f = root / u.actuator_id / f"{stamp}.mcap"
                write_mcap(f, sig, nominal, u.actuator_id, start)
                files.append(str(f))
            elif u.fmt == "output_csv":
                f = root / u.actuator_id / f"{stamp}.csv"
                write_output_csv(f, sig)
                files.append(str(f))
            else:
                wide.append(sig)
        if wide:
            robot = next(u.actuator_id.split("/")[0] for u in units if u.fmt == "wide_csv")
            f = root / robot / f"{stamp}_joints.csv"
            write_wide_csv(f, wide)
            files.append(str(f))
        if progress:
            print(f"day {day + 1}/{days}: {len(files)} files", file=sys.stderr, flush=True)
    cut = []
    for f in [f for f in files if f.endswith(".mcap")][::-1][:unfinalized]:
        data = Path(f).read_bytes()
        Path(f).write_bytes(data[: int(0.6 * len(data))])
        cut.append(f)
    for k in range(corrupt):
        if k % 2 == 0:
            good = next((Path(f) for f in files if f.endswith(".mcap")), None)
            f = root / "robot9" / "broken" / f"2026-01-{k + 1:02d}.mcap"
            f.parent.mkdir(parents=True, exist_ok=True)
            f.write_bytes(good.read_bytes()[:300] if good else b"\x89MCAP0\r\n garbage")
        else:
            f = root / "robot9" / "broken" / f"2026-01-{k + 1:02d}.csv"
            f.parent.mkdir(parents=True, exist_ok=True)
            f.write_text("t,q_out,dq_out,iq\n1,2,x\n")
        files.append(str(f))
    truth = {"start": START.isoformat(), "days": days, "duration_s": duration, "rate_hz": rate,
             "drift_days": drift_days,
             "actuators": [{"actuator_id": u.actuator_id, "format": u.fmt, "drift": u.drift,
                            "parameter": DRIFT_PARAMETER.get(u.drift) if u.drift else None} for u in units],
             "files": len(files), "unfinalized": cut, "loop": loop, "noise": noise,
             "schedules": {u.actuator_id: u.schedule for u in units if u.schedule}}
    (root / "truth.json").write_text(json.dumps(truth, indent=1))
    return truth


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--actuators", type=int, default=8)
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--duration", type=float, default=20.0, help="[s] per recording")
    ap.add_argument("--rate", type=float, default=250.0, help="[Hz] sample rate")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--drift-days", type=float, default=30.0, help="days over which the drifts reach full size")
    ap.add_argument("--formats", default=",".join(FORMATS), help="comma-separated subset of " + ", ".join(FORMATS))
    ap.add_argument("--corrupt", type=int, default=0, help="add this many corrupt files")
    ap.add_argument("--loop", choices=("open", "closed"), default="open",
                    help="open: multi-sine current command; closed: a PD joint controller following swings")
    ap.add_argument("--noise", type=float, default=1.0, help="sensor noise scale (0: none; quantisation stays)")
    ap.add_argument("--stable", action="store_true", help="no planted drift: every actuator stable")
    a = ap.parse_args(argv)
    units = [Unit(u.actuator_id, u.fmt, None, u.joint_index) for u in default_units(a.actuators)] if a.stable else None
    truth = generate(a.out, a.actuators, a.days, a.duration, a.rate, a.seed, a.corrupt, progress=True,
                     drift_days=a.drift_days, formats=tuple(a.formats.split(",")), units=units, loop=a.loop,
                     noise=a.noise)
    print(f"wrote {truth['files']} files under {a.out} ({a.actuators} actuators x {a.days} days)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
