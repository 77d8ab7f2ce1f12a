"""Third-party concealed cases: the truth is motulator's PMSM drive, a simulator this project did not write.

Each case runs motulator's continuous-time machine model (``SynchronousMachine`` + ``MechanicalSystem`` +
``VoltageSourceConverter`` with its own dead-time model) under motulator's own discrete drive control
(``CurrentVectorController``: flux-linkage-based PI current control with its reference generator, 1.5-period
angle compensation of the computational delay, sensored speed/angle; a 2DOF PI ``SpeedController`` outside it:
a speed-controlled drive). Hidden effects are what such a simulator can express: viscous and Coulomb-like load
friction (``B_L(ω)``), a flux-linkage (K_t) error, a resistance error, an inertia error, inverter dead time, and
L_d ≠ L_q saliency as a null stressor (the drive knows it, the user's q-axis model cannot express it).

The recording is converted at the edge into this project's recording format and frames (:func:`to_recording`):
motulator's space vectors are peak-value (amplitude-invariant) scaled, ``x = (2/3)(x_a + a x_b + a² x_c)``,
power ``(3/2) Re(u i*)``, torque ``(3/2) p Im(ψ_s* i)``; this project's ``_q`` frame is power invariant, so every
current and voltage is multiplied by √(3/2) (then ``P = v_d i_d + v_q i_q`` and ``τ = K_q i_q`` with
``K_q = √(3/2) p ψ_f``). The drive logs what drives log: its q-current command and measured d/q currents, the
commanded (limited) d/q voltage, the speed it measures, the encoder angle (14 bit, unwrapped), the bus voltage;
at 1 kHz (every 10th control sample) or 10 kHz (every sample); some cases add a torque sensor on the load side.
Sensor noise is added to the logged channels (the drive's own loop sees motulator's clean measurements).

Run in the peers venv (``bash benchmarks/peers/setup.sh``): ``benchmarks/run_concealed.py --set thirdparty``.
"""

from __future__ import annotations

import csv
import json
import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

SQRT3_2 = math.sqrt(1.5)

#: the joint of the third-party set: the concealed benchmark's AK80-9-like motor, direct drive (the torque sensor
#: sits on the motor shaft), no thermal model (motulator has none: temperature effects off in the nominal file)
NOMINAL_BASE: dict = {
    "motor.winding": "wye", "motor.pole_pairs": 21, "motor.phase_resistance": 0.13, "motor.q_inductance": 8.0e-5,
    "motor.torque_constant_q": 0.0743, "motor.rotor_inertia": 6.0e-5, "motor.viscous_damping": 1.0e-5,
    "motor.resistance_temperature_enabled": False, "motor.magnet_temperature_enabled": False,
    "drive.bus_voltage": 24.0, "drive.current_limit": 20.0, "drive.current_loop_rate": 10000.0,
    "drive.current_loop_bandwidth": 500.0, "drive.current_loop_delay": 1.0e-4, "drive.pwm_frequency": 5000.0,
    "gear.gear_ratio": 1.0,
}
T_S = 1.0e-4                 #: motulator control period [s] (double update: carrier period 2 T_S, f_pwm 5 kHz)
ENCODER_BITS = 14
CURRENT_NOISE_Q = 0.03       #: [A] white noise on the logged d/q currents (power-invariant)
VOLTAGE_NOISE_Q = 0.01       #: [V] on the logged d/q voltages
VELOCITY_NOISE = 0.02        #: [rad/s]
TORQUE_NOISE = 0.003         #: [N·m] torque sensor
F_EPS = 0.05                 #: [rad/s] tanh regularisation of the Coulomb-like load friction


@dataclass(frozen=True)
class TPCase:
    name: str
    effects: tuple[str, ...]
    story: str
    truth: dict                                   #: effect -> {main parameter: true value, ...}
    plant: dict = field(default_factory=dict)     #: R_s, psi_f_ratio, J, B_visc, F_c, t_d, L_d, L_q
    nominal: dict = field(default_factory=dict)   #: flat overrides of NOMINAL_BASE (what the user believes)
    drive: dict = field(default_factory=dict)     #: alpha_c_hz, alpha_s_hz, salient controller
    log_rate: float = 1000.0
    torque_sensor: bool = False
    train_s: float = 4.0      #: motulator runs ~10 s per simulated second (a solve_ivp call per control period)
    heldout_s: float = 2.0
    seed: int = 0
    channel: str = "current"
    alias_ok: dict = field(default_factory=dict)

    @property
    def is_null(self) -> bool:
        return not self.effects


PSI_F = NOMINAL_BASE["motor.torque_constant_q"] / (SQRT3_2 * NOMINAL_BASE["motor.pole_pairs"])

CASES: tuple[TPCase, ...] = (
    TPCase("tp_null", (), "nothing hidden: motulator's speed-controlled PMSM drive, logged at 1 kHz", {}, seed=1),
    TPCase("tp_viscous", ("viscous_friction",), "viscous load drag 20 x the datasheet damping",
           {"viscous_friction": {"viscous_damping": 2.1e-4}}, plant={"B_visc": 2.1e-4}, seed=2),
    TPCase("tp_coulomb", ("coulomb_friction",), "Coulomb-like load friction 0.02 N·m (tanh, 0.05 rad/s)",
           {"coulomb_friction": {"coulomb_friction": 0.02}}, plant={"F_c": 0.02}, seed=3),
    TPCase("tp_kt", ("torque_constant_error",), "magnet flux 15 % above the datasheet (K_t x 1.15)",
           {"torque_constant_error": {"torque_constant_ratio": 1.15}}, plant={"psi_f_ratio": 1.15}, seed=4,
           channel="voltage_q"),
    TPCase("tp_resistance", ("resistance_error",), "phase resistance 40 % above the nominal (hot winding, cables)",
           {"resistance_error": {"phase_resistance": 0.182}}, plant={"R_s": 0.182}, seed=5, channel="voltage_q"),
    TPCase("tp_inertia", ("inertia_error",), "the load's inertia was forgotten: J x 1.6",
           {"inertia_error": {"inertia_ratio": 1.6}}, plant={"J": 1.6 * 6.0e-5}, seed=6),
    TPCase("tp_dead_time", ("dead_time",), "inverter dead time 2 µs at 5 kHz PWM (0.24 V per leg), uncompensated",
           {"dead_time": {"dead_time": 2.0e-6}}, plant={"t_d": 2.0e-6}, seed=7, channel="voltage_q"),
    TPCase("tp_null_salient", (), "nothing the q-axis model can name: L_d = 60 µH, L_q = 100 µH (the drive knows "
           "it; the nominal file has L = L_q)", {}, plant={"L_d": 6.0e-5, "L_q": 1.0e-4},
           nominal={"motor.q_inductance": 1.0e-4}, drive={"salient": True}, seed=8),
    TPCase("tp_coulomb_10khz", ("coulomb_friction",), "Coulomb-like load friction 0.02 N·m, the drive logs every "
           "control sample (10 kHz)", {"coulomb_friction": {"coulomb_friction": 0.02}}, plant={"F_c": 0.02},
           log_rate=10000.0, seed=9),
    TPCase("tp_viscous_torque_sensor", ("viscous_friction",), "viscous drag 20 x datasheet in the motor (bearings, "
           "seals), with a shaft torque sensor between motor and a known 0.1 N·m load",
           {"viscous_friction": {"viscous_damping": 2.1e-4}}, plant={"B_visc": 2.1e-4, "tau_ext": 0.1},
           nominal={"load.load_torque": 0.1}, torque_sensor=True, seed=10),
    TPCase("tp_dead_time_loaded", ("dead_time",), "inverter dead time 2 µs at 5 kHz PWM, uncompensated, under a known "
           "0.25 N·m load (|i_q| ~ 3 A, well above the zero-crossing band)", {"dead_time": {"dead_time": 2.0e-6}},
           plant={"t_d": 2.0e-6, "tau_ext": 0.25}, nominal={"load.load_torque": 0.25}, seed=11, channel="voltage_q"),
    TPCase("tp_resistance_loaded", ("resistance_error",), "phase resistance 40 % above the nominal, under a known "
           "0.25 N·m load", {"resistance_error": {"phase_resistance": 0.182}}, plant={"R_s": 0.182, "tau_ext": 0.25},
           nominal={"load.load_torque": 0.25}, seed=12, channel="voltage_q"),
)


def get_case(name: str) -> TPCase:
    for c in CASES:
        if c.name == name:
            return c
    raise KeyError(f"no third-party case {name!r} (have: {', '.join(c.name for c in CASES)})")


def reseeded(case: TPCase, offset: int) -> TPCase:
    """Fresh excitation and noise seeds (offset 0 = the published ones)."""
    return case if not offset else replace(case, seed=case.seed + 1000 * offset)


def nominal_params(case: TPCase):
    from bldc_actuator.params import from_flat

    values = dict(NOMINAL_BASE)
    values.update(case.nominal)
    return from_flat(values)


# ------------------------------------------------------------------------------------------- excitation

def speed_reference(duration: float, seed: int) -> Callable[[float], float]:
    """Speed reference [motor rad/s]: a slow triangle through zero (friction at low speed, both directions) for
    30 % of the time, then a seeded multisine (four tones, random phases) that reverses often."""
    rng = np.random.default_rng(seed)
    f = np.array([0.35, 0.9, 2.1, 4.3]) * rng.uniform(0.85, 1.15, 4)
    a = np.array([22.0, 12.0, 6.0, 3.0])
    ph = rng.uniform(0, 2 * np.pi, 4)
    t1 = 0.3 * duration
    slow = 6.0

    def w_ref(t: float) -> float:
        if t < t1:
            x = (t / t1) * 2.0                 # two triangle periods of +-slow
            return slow * (1.0 - 4.0 * abs((x % 1.0) - 0.5)) * (1.0 if x < 1.0 else -1.0)
        s = t - t1
        ramp = min(1.0, s / 0.3)
        return ramp * float(np.sum(a * np.sin(2 * np.pi * f * s + ph)))
    return w_ref


# ------------------------------------------------------------------------------------------- simulation

def simulate(case: TPCase, duration: float, seed: int) -> dict:
    """One motulator run of ``case`` (truth plant, nominal-parameter drive); returns motulator's own time series
    in its own frames (amplitude-invariant space vectors), sampled at the control instants."""
    from motulator.drive import model
    import motulator.drive.control.sm as sm

    P = case.plant
    p = NOMINAL_BASE["motor.pole_pairs"]
    L_nom = case.nominal.get("motor.q_inductance", NOMINAL_BASE["motor.q_inductance"])
    par_true = model.SynchronousMachinePars(
        n_p=p, R_s=P.get("R_s", NOMINAL_BASE["motor.phase_resistance"]), L_d=P.get("L_d", L_nom),
        L_q=P.get("L_q", L_nom), psi_f=PSI_F * P.get("psi_f_ratio", 1.0))
    # the drive is tuned with what the user believes (nominal R, L, psi_f); a salient drive knows L_d and L_q
    par_drive = model.SynchronousMachinePars(
        n_p=p, R_s=NOMINAL_BASE["motor.phase_resistance"],
        L_d=P.get("L_d", L_nom) if case.drive.get("salient") else L_nom,
        L_q=P.get("L_q", L_nom) if case.drive.get("salient") else L_nom, psi_f=PSI_F)
    J = P.get("J", NOMINAL_BASE["motor.rotor_inertia"])
    b = P.get("B_visc", NOMINAL_BASE["motor.viscous_damping"])
    F_c = P.get("F_c", 0.0)

    def B_L(w):            # motulator's load torque is B_L(w) * w
        if F_c == 0.0:
            return b
        w = float(w)
        return b + (F_c * math.tanh(w / F_EPS) / w if abs(w) > 1e-9 else F_c / F_EPS)

    mech = model.MechanicalSystem(J=J, B_L=B_L)
    tau_ext = P.get("tau_ext", 0.0)       # a constant external load (the user knows it: load.load_torque)
    if tau_ext:
        mech.set_external_load_torque(tau_ext)
    mdl = model.Drive(model.SynchronousMachine(par_true), mech,
                      model.VoltageSourceConverter(u_dc=NOMINAL_BASE["drive.bus_voltage"], t_d=P.get("t_d", 0.0)))
    cfg = sm.CurrentVectorControllerCfg(i_s_max=NOMINAL_BASE["drive.current_limit"] / SQRT3_2,
                                        alpha_c=2 * math.pi * case.drive.get("alpha_c_hz", 500.0), T_s=T_S,
                                        sensorless=False)
    spd = sm.SpeedController(J=NOMINAL_BASE["motor.rotor_inertia"],
                             alpha_s=2 * math.pi * case.drive.get("alpha_s_hz", 15.0),
                             tau_M_max=1.2)
    ctrl = sm.VectorControlSystem(sm.CurrentVectorController(par_drive, cfg), spd)
    ctrl.set_speed_ref(speed_reference(duration, seed))
    res = model.Simulation(mdl, ctrl, show_progress=False).simulate(t_stop=duration)
    c, m = res.ctrl, res.mdl
    t = np.asarray(c.t, dtype=float)
    theta_M = np.unwrap(np.asarray(m.mechanics.theta_M, dtype=float))
    return {
        "t": t,
        "i_ref": np.asarray(c.ref.i_s, dtype=complex),          # current reference, controller (rotor) frame
        "i_meas": np.asarray(c.fbk.i_s, dtype=complex),         # measured current, controller frame
        "u_ref": np.asarray(c.ref.u_s_lim, dtype=complex),      # commanded (limited) voltage, controller frame
        "w_M_meas": np.asarray(c.fbk.w_M, dtype=float),
        "u_dc": np.asarray(c.fbk.u_dc, dtype=float),
        "theta_M": np.interp(t, m.t, theta_M),
        "w_M": np.interp(t, m.t, np.asarray(m.mechanics.w_M, dtype=float)),
        "tau_M": np.interp(t, m.t, np.asarray(m.machine.tau_M, dtype=float)),
        "tau_L": np.interp(t, m.t, np.asarray(m.mechanics.tau_L_tot, dtype=float)),
        # continuous-time machine signals (rotor frame, amplitude invariant) on the solver's grid, for the tests
        "mdl_t": np.asarray(m.t, dtype=float),
        "mdl_i_dq": np.asarray(m.machine.i_s_dq, dtype=complex),
        "mdl_u_ab": np.asarray(m.machine.u_s_ab, dtype=complex),
        "mdl_theta_m": np.asarray(m.machine.theta_m, dtype=float),
        "mdl_tau_M": np.asarray(m.machine.tau_M, dtype=float),
        "mdl_w_M": np.asarray(m.mechanics.w_M, dtype=float),
        "tau_ext": np.full(len(t), tau_ext),
        "par": {"n_p": p, "psi_f": par_true.psi_f, "R_s": par_true.R_s, "L_d": par_true.L_d, "L_q": par_true.L_q,
                "J": J, "b": b, "F_c": F_c},
    }


def to_q(x_amplitude_invariant):
    """motulator's peak-value (amplitude-invariant) space vector -> this project's power-invariant d-q: × √(3/2)."""
    return np.asarray(x_amplitude_invariant) * SQRT3_2


def torque_constant_q(n_p: int, psi_f: float) -> float:
    """K_q [N·m/A, power-invariant i_q] of a machine motulator describes by ``psi_f`` [Wb, peak]:
    τ = (3/2) p ψ_f i_q,amp = √(3/2) p ψ_f i_q,pi."""
    return SQRT3_2 * n_p * psi_f


def to_recording(run: dict, *, rate: float, seed: int, torque_sensor: bool = False, noise: bool = True) -> dict:
    """motulator time series -> this project's recording (canonical channels, SI, motor side, power-invariant d-q),
    logged at ``rate`` (every ``10 kHz / rate``-th control sample) with sensor noise drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    q = max(1, int(round(1.0 / (T_S * rate))))
    idx = np.arange(0, len(run["t"]), q)
    n = len(idx)

    def nz(scale):
        return scale * rng.standard_normal(n) if noise else np.zeros(n)

    i_ref, i_m, u = to_q(run["i_ref"][idx]), to_q(run["i_meas"][idx]), to_q(run["u_ref"][idx])
    res = 2 * np.pi / 2 ** ENCODER_BITS
    rec = {
        "time": run["t"][idx] - run["t"][0],
        "current_command": i_ref.imag,
        "current": i_m.imag + nz(CURRENT_NOISE_Q),
        "current_d": i_m.real + nz(CURRENT_NOISE_Q),
        "position": np.round(run["theta_M"][idx] / res) * res if noise else run["theta_M"][idx],
        "velocity": run["w_M_meas"][idx] + nz(VELOCITY_NOISE),
        "bus_voltage": run["u_dc"][idx],
        "voltage_q": u.imag + nz(VOLTAGE_NOISE_Q),
        "voltage_d": u.real + nz(VOLTAGE_NOISE_Q),
    }
    if torque_sensor:
        # shaft sensor between the motor (its inertia and its drag B_L, bearings and seals) and a massless load: it
        # reads the external load torque (motulator's tau_L_tot minus the drag B_L(w) w)
        rec["torque"] = run["tau_ext"][idx] + nz(TORQUE_NOISE)
    rec["true_omega"] = run["w_M"][idx]
    rec["true_tau_M"] = run["tau_M"][idx]
    rec["true_i_q"] = i_m.imag
    return rec


def hidden_term(case: TPCase, run: dict, nominal) -> dict:
    """RMS of what the hidden effect adds, in the channel where it lives, next to the noise there (the
    concealment line of the table): torque effects in q-current units, voltage effects in volts."""
    w, K = run["w_M"], nominal.motor.torque_constant_q
    iq = to_q(run["i_meas"]).imag
    P, par = case.plant, run["par"]
    eff = np.zeros_like(w)
    if "B_visc" in P:
        eff = (P["B_visc"] - nominal.motor.viscous_damping) * w / K
    elif "F_c" in P:
        eff = P["F_c"] * np.tanh(w / F_EPS) / K
    elif "J" in P:
        eff = (P["J"] - nominal.motor.rotor_inertia) * np.gradient(w, run["t"]) / K
    elif "psi_f_ratio" in P:
        eff = (P["psi_f_ratio"] - 1.0) * K * w
    elif "R_s" in P:
        eff = (P["R_s"] - nominal.motor.phase_resistance) * iq
    elif "t_d" in P:
        eff = np.full_like(w, 1.5594 * P["t_d"] * NOMINAL_BASE["drive.pwm_frequency"] * NOMINAL_BASE["drive.bus_voltage"])
    noise = CURRENT_NOISE_Q if case.channel == "current" else VOLTAGE_NOISE_Q
    e = float(np.sqrt(np.mean(eff ** 2))) if not case.is_null else 0.0
    out = {"channel": case.channel, "effect_rms": e, "noise_rms": noise, "snr": e / noise}
    out["current"] = {"effect_rms": e if case.channel == "current" else 0.0, "noise_rms": CURRENT_NOISE_Q}
    out["voltage_q"] = {"effect_rms": e if case.channel == "voltage_q" else 0.0, "noise_rms": VOLTAGE_NOISE_Q}
    return out


# ------------------------------------------------------------------------------------------- writing

COLUMNS = ("time", "current_command", "current", "current_d", "position", "velocity", "bus_voltage", "voltage_q",
           "voltage_d")


def write_csv(path: Path, rec: dict) -> None:
    cols = list(COLUMNS) + (["torque"] if "torque" in rec else [])
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for i in range(len(rec["time"])):
            w.writerow([f"{rec[c][i]:.7g}" if c != "time" else f"{rec[c][i]:.5f}" for c in cols])


def _job(args):
    case, role, duration, seed = args
    return case.name, role, simulate(case, duration, seed)


def motulator_version() -> str:
    try:
        from importlib.metadata import version

        return version("motulator")
    except Exception:   # noqa: BLE001
        return "not installed"


def generate(cases, outdir: Path, *, progress: Callable[[str], None] | None = None, workers: int = 2) -> dict:
    """Simulate each case's training and held-out runs with motulator and write the files (same layout as
    :func:`cases.generate`: train.csv, heldout.csv, params.yaml, truth.json)."""
    import time

    from bldc_actuator.params import dump_yaml

    outdir = Path(outdir)
    jobs = []
    for c in cases:
        jobs += [(c, "train", c.train_s, 1000 * c.seed + 1), (c, "heldout", c.heldout_s, 1000 * c.seed + 2)]
    runs, t0 = {}, time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as ex:
        for k, (name, role, run) in enumerate(ex.map(_job, jobs), start=1):
            runs[(name, role)] = run
            if progress:
                progress(f"simulated {k}/{len(jobs)} recordings with motulator ({time.perf_counter() - t0:.0f} s)")
    truths = {}
    for c in cases:
        d = outdir / c.name
        d.mkdir(parents=True, exist_ok=True)
        nominal = nominal_params(c)
        recs = {}
        for role, sd in (("train", 1000 * c.seed + 11), ("heldout", 1000 * c.seed + 12)):
            recs[role] = to_recording(runs[(c.name, role)], rate=c.log_rate, seed=sd, torque_sensor=c.torque_sensor)
            write_csv(d / f"{role}.csv", recs[role])
        dump_yaml(nominal, d / "params.yaml", header=f"third-party concealed case {c.name}: the NOMINAL model")
        tr = runs[(c.name, "train")]
        truth = {
            "case": c.name, "effects": list(c.effects), "story": c.story, "truth": c.truth,
            "alias_ok": {k: list(v) for k, v in c.alias_ok.items()},
            "source": f"motulator {motulator_version()} (SynchronousMachine, MechanicalSystem, VoltageSourceConverter; "
                      "CurrentVectorController + SpeedController, sensored)",
            "plant_changes": c.plant, "drive_changes": c.drive, "nominal_overrides": c.nominal,
            "concealment": hidden_term(c, tr, nominal), "oracle": None,
            "train": {"excitation": "speed: triangle + multisine", "duration_s": c.train_s, "seed": 1000 * c.seed + 1},
            "heldout": {"excitation": "speed: triangle + multisine", "duration_s": c.heldout_s,
                        "seed": 1000 * c.seed + 2},
            "log": {"rate": c.log_rate, "filter": "sample", "torque_sensor": c.torque_sensor},
            "ranges": {"max_abs_velocity_motor_rad_s": float(np.max(np.abs(tr["w_M"]))),
                       "max_abs_current_A": float(np.max(np.abs(to_q(tr["i_meas"]).imag)))},
        }
        (d / "truth.json").write_text(json.dumps(truth, indent=2, default=float) + "\n")
        truths[c.name] = truth
    return truths
