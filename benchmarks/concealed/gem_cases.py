"""Third-party concealed cases whose truth is gym-electric-motor's PMSM (GEM, Paderborn University).

Each case runs GEM's own physical system (``SynchronousMotorSystem``: ``PermanentMagnetSynchronousMotor`` with
L_d, L_q, ψ_p; ``ContB6BridgeConverter``, its dynamically averaged B6 bridge with an optional interlocking
(dead) time; ``PolynomialStaticLoad`` τ_L = a·sign(ω) + b·ω + c·ω|ω| with its own smoothing of the constant
term near ω = 0 and a load inertia added to the rotor's; ``IdealVoltageSupply``; GEM's default ``ScipyOdeSolver``
(dopri5) between control steps). GEM simulates the plant only; its environments are made for reinforcement
learning and its classic controllers (the ``gem-controllers`` package) are not on the package index, so the
*drive* is written here, outside GEM, like a drive's firmware: a discrete d-q PI current controller (10 kHz,
tuned with the NOMINAL R, L by the bandwidth, decoupling and back-EMF feed-forward with the nominal ψ, back-
calculation anti-windup, one control period of computation delay with the angle advanced by that period, min-max
zero-sequence injection into three duty cycles) under a PI speed controller (tuned with the nominal J and ψ).

Frames at the edge (:func:`to_q`, :func:`nominal_from_gem`): GEM's d-q quantities are amplitude invariant
(``T_23 = (2/3)[[1, -1/2, -1/2], [0, √3/2, -√3/2]]``, torque ``(3/2) p (ψ_p + (L_d - L_q) i_d) i_q``), its
phase voltages are line-to-neutral peaks, ω is mechanical and ε = p·θ electrical. This project's ``_q`` frame is
power invariant: every current and voltage × √(3/2), ``K_q = √(3/2) p ψ_p``; R, L are the same numbers in both
(both sides of ``u = R i + L di/dt`` scale alike); J = GEM's j_rotor + j_load; b = GEM's load ``b``; Coulomb
friction = GEM's ``a``. ``test/test_gem_truth.py`` checks each conversion against GEM runs.

Run in the peers venv (``bash benchmarks/peers/setup.sh``): ``benchmarks/run_concealed.py --set gem``.
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
T_S = 1.0e-4                 #: control period = GEM's step tau [s]; GEM's converter takes it as the PWM period too
U_DC = 24.0                  #: [V] DC bus
I_MAX_Q = 20.0               #: [A] |i_q| limit, power-invariant (the nominal file's drive.current_limit)
ALPHA_C_HZ = 500.0           #: current-loop bandwidth [Hz] the drive's PI is tuned for
SPEED_LOOP_HZ = 12.0         #: speed loop natural frequency [Hz] (PI, ζ = 1, nominal J)
ENCODER_BITS = 14
CURRENT_NOISE_Q = 0.03       #: [A] white noise on the logged d/q currents (power-invariant)
VOLTAGE_NOISE_Q = 0.01       #: [V] on the logged d/q voltages
VELOCITY_NOISE = 0.02        #: [rad/s]

#: the joint, in GEM's own parameter names and frames (amplitude-invariant ψ_p, peak flux linkage): the
#: AK80-9-like motor of the other concealed sets, direct drive
GEM_MOTOR: dict = {"p": 21, "r_s": 0.13, "l_d": 8.0e-5, "l_q": 8.0e-5, "j_rotor": 5.0e-5,
                   "psi_p": 0.0743 / (SQRT3_2 * 21)}
#: GEM's PolynomialStaticLoad parameters of the nominal joint: datasheet damping, the output link's inertia
#: (GEM needs j_load > 0: its load divides by it before the rotor's is added); J = j_rotor + j_load = 6e-5 kg·m²
GEM_LOAD: dict = {"a": 0.0, "b": 1.0e-5, "c": 0.0, "j_load": 1.0e-5}


def nominal_from_gem(motor: dict, load: dict, *, u_dc: float = U_DC, tau: float = T_S) -> dict:
    """GEM's motor and load parameters -> this project's flat ActuatorParams values (the nominal file).

    ``p`` -> pole_pairs; ``r_s`` -> phase_resistance (per phase, frame-free); ``l_q`` -> q_inductance (the same
    number in the amplitude- and power-invariant frames; L_d is not expressible here, L = L_q);
    ``psi_p`` [Wb, peak] -> torque_constant_q = √(3/2) p ψ_p [N·m per power-invariant A] (= K_b_q [V·s/rad]);
    ``j_rotor + j_load`` -> rotor_inertia; load ``b`` -> viscous_damping; load ``a`` -> effects.coulomb_friction.
    The drive: 10 kHz control with one period of computation delay, the PWM period = GEM's step."""
    from bldc_actuator import frames

    if load.get("c", 0.0):
        raise ValueError(f"GEM load c = {load['c']} N·m·s²: a quadratic drag has no nominal parameter here "
                         "(expected 0)")
    out = {
        "motor.winding": "wye", "motor.pole_pairs": int(motor["p"]), "motor.phase_resistance": float(motor["r_s"]),
        "motor.q_inductance": float(motor["l_q"]),
        "motor.torque_constant_q": float(frames.back_emf_constant_q_from_flux_linkage(motor["psi_p"], motor["p"])),
        "motor.rotor_inertia": float(motor["j_rotor"] + load.get("j_load", 0.0)),
        "motor.viscous_damping": float(load.get("b", 0.0)),
        "motor.resistance_temperature_enabled": False, "motor.magnet_temperature_enabled": False,
        "drive.bus_voltage": float(u_dc), "drive.current_limit": I_MAX_Q, "drive.current_loop_rate": 1.0 / tau,
        "drive.current_loop_bandwidth": ALPHA_C_HZ, "drive.current_loop_delay": tau,
        "drive.pwm_frequency": 1.0 / tau, "gear.gear_ratio": 1.0,
    }
    if load.get("a", 0.0):
        out["effects.coulomb_friction"] = float(load["a"])
    return out


NOMINAL_BASE: dict = nominal_from_gem(GEM_MOTOR, GEM_LOAD)


@dataclass(frozen=True)
class GEMCase:
    name: str
    effects: tuple[str, ...]
    story: str
    truth: dict                                   #: effect -> {main parameter: true value, ...}
    motor: dict = field(default_factory=dict)     #: GEM motor parameter overrides of the truth (r_s, psi_p, ...)
    load: dict = field(default_factory=dict)      #: GEM load parameter overrides of the truth (a, b, j_load)
    tau_ext: float = 0.0                          #: constant external load [N·m] (known to the user)
    interlocking_time: float = 0.0                #: GEM converter dead time [s]
    nominal: dict = field(default_factory=dict)   #: flat overrides of NOMINAL_BASE (what the user believes)
    drive_knows_saliency: bool = False
    log_rate: float = 1000.0
    train_s: float = 6.0
    heldout_s: float = 4.0
    seed: int = 0
    channel: str = "current"
    alias_ok: dict = field(default_factory=dict)

    @property
    def is_null(self) -> bool:
        return not self.effects


CASES: tuple[GEMCase, ...] = (
    GEMCase("gem_null", (), "nothing hidden: GEM's PMSM under a PI current + speed drive, logged at 1 kHz", {},
            seed=21),
    GEMCase("gem_null_salient", (), "nothing the q-axis model can name: GEM's l_d = 60 µH, l_q = 100 µH (the drive "
            "knows it; the nominal file has L = L_q)", {}, motor={"l_d": 6.0e-5, "l_q": 1.0e-4},
            nominal={"motor.q_inductance": 1.0e-4}, drive_knows_saliency=True, seed=22),
    GEMCase("gem_viscous", ("viscous_friction",), "GEM load b = 1.6e-4 N·m·s (16 x the datasheet damping)",
            {"viscous_friction": {"viscous_damping": 1.6e-4}}, load={"b": 1.6e-4}, seed=23),
    GEMCase("gem_coulomb", ("coulomb_friction",), "GEM load a = 0.02 N·m (constant term, GEM's linear smoothing "
            "within |ω| < a τ_decay / J = 0.33 rad/s)", {"coulomb_friction": {"coulomb_friction": 0.02}},
            load={"a": 0.02}, seed=24),
    GEMCase("gem_inertia", ("inertia_error",), "a load inertia the user forgot: GEM j_load 1e-5 -> 4e-5 kg·m² (J x 1.5)",
            {"inertia_error": {"inertia_ratio": 1.5}}, load={"j_load": 4.0e-5}, seed=25),
    GEMCase("gem_kt", ("torque_constant_error",), "permanent-magnet flux ψ_p 15 % above the datasheet (K_t x 1.15)",
            {"torque_constant_error": {"torque_constant_ratio": 1.15}}, motor={"psi_p": 1.15 * GEM_MOTOR["psi_p"]},
            seed=26, channel="voltage_q"),
    GEMCase("gem_resistance_loaded", ("resistance_error",), "phase resistance 40 % above the nominal under a known "
            "constant 0.25 N·m load (i_q ~ 3.4 A)", {"resistance_error": {"phase_resistance": 0.182}},
            motor={"r_s": 0.182}, tau_ext=0.25, nominal={"load.load_torque": 0.25}, seed=27, channel="voltage_q"),
    GEMCase("gem_coulomb_100hz", ("coulomb_friction",), "GEM load a = 0.02 N·m, the drive's logger samples at "
            "100 Hz", {"coulomb_friction": {"coulomb_friction": 0.02}}, load={"a": 0.02}, log_rate=100.0, seed=28),
    GEMCase("gem_dead_time", ("dead_time",), "GEM converter interlocking time 1 µs at its 10 kHz period (0.24 V per "
            "leg), uncompensated; a known 10 x load inertia makes the q current reverse at ~1-2 A",
            {"dead_time": {"dead_time": 1.0e-6}}, interlocking_time=1.0e-6, load={"j_load": 5.5e-4},
            nominal={"motor.rotor_inertia": 6.0e-4}, seed=29, channel="voltage_q"),
)


def get_case(name: str) -> GEMCase:
    for c in CASES:
        if c.name == name:
            return c
    raise KeyError(f"no GEM case {name!r} (have: {', '.join(c.name for c in CASES)})")


def reseeded(case: GEMCase, offset: int) -> GEMCase:
    """Fresh excitation and noise seeds (offset 0 = the published ones)."""
    return case if not offset else replace(case, seed=case.seed + 1000 * offset)


def nominal_params(case: GEMCase):
    from bldc_actuator.params import from_flat

    values = dict(NOMINAL_BASE)
    values.update(case.nominal)
    return from_flat(values)


def truth_motor(case: GEMCase) -> dict:
    m = dict(GEM_MOTOR)
    if case.nominal.get("motor.q_inductance"):
        m["l_d"] = m["l_q"] = case.nominal["motor.q_inductance"]
    m.update(case.motor)
    return m


def truth_load(case: GEMCase) -> dict:
    return {**GEM_LOAD, **case.load}


# ------------------------------------------------------------------------------------------- excitation

def speed_reference(duration: float, seed: int) -> Callable[[float], float]:
    """Speed reference [motor rad/s]: a slow triangle through zero (±6 rad/s, two periods) for 25 % of the
    time, then a seeded multisine (five tones, random phases) that reverses often."""
    rng = np.random.default_rng(seed)
    f = np.array([0.3, 0.75, 1.7, 3.1, 5.3]) * rng.uniform(0.85, 1.15, 5)
    a = np.array([20.0, 11.0, 6.0, 3.5, 1.5])
    ph = rng.uniform(0, 2 * np.pi, 5)
    t1 = 0.25 * duration
    slow = 6.0

    def w_ref(t: float) -> float:
        if t < t1:
            x = (t / t1) * 2.0
            return slow * (1.0 - 4.0 * abs((x % 1.0) - 0.5)) * (1.0 if x < 1.0 else -1.0)
        s = t - t1
        ramp = min(1.0, s / 0.3)
        return ramp * float(np.sum(a * np.sin(2 * np.pi * f * s + ph)))
    return w_ref


# ------------------------------------------------------------------------------------------- GEM plant

def build_system(motor: dict, load: dict, *, tau_ext: float = 0.0, interlocking_time: float = 0.0,
                 tau: float = T_S, u_dc: float = U_DC, control_space: str = "abc"):
    """GEM's SCML system for one PMSM (its classes, its default solver); returns the physical system."""
    import gym_electric_motor.physical_systems as ps

    lim = dict(i=60.0, u=u_dc, omega=400.0, epsilon=math.pi, torque=0.0)
    mot = ps.PermanentMagnetSynchronousMotor(motor_parameter=dict(motor), limit_values=dict(lim),
                                             nominal_values=dict(lim))
    if tau_ext:
        class PolynomialStaticLoadWithConstantTorque(ps.PolynomialStaticLoad):
            """GEM's polynomial load plus a constant torque (one-signed, a known external load)."""

            def _static_load(self, omega):
                return super()._static_load(omega) + tau_ext

        load_cls = PolynomialStaticLoadWithConstantTorque
    else:
        load_cls = ps.PolynomialStaticLoad
    mech = load_cls(load_parameter=dict(load), limits=dict(omega=400.0))
    conv = ps.ContB6BridgeConverter(tau=tau, interlocking_time=interlocking_time)
    return ps.SynchronousMotorSystem(converter=conv, motor=mot, load=mech,
                                     supply=ps.IdealVoltageSupply(u_nominal=u_dc), ode_solver=ps.ScipyOdeSolver(),
                                     tau=tau, control_space=control_space)


def _index(system) -> dict:
    return {n: k for k, n in enumerate(system.state_names)}


def abc_duty(u_dq: complex, theta_e: float, u_dc: float) -> np.ndarray:
    """Amplitude-invariant d-q voltage at electrical angle ``theta_e`` -> the three legs' normalised duty in GEM's
    Cont-B6C action space [-1, 1] (leg voltage a·u_dc/2), with min-max zero-sequence injection (linear up to
    |u| = u_dc/√3)."""
    u_ab = u_dq * complex(math.cos(theta_e), math.sin(theta_e))
    ua = u_ab.real
    ub = -0.5 * u_ab.real + 0.5 * math.sqrt(3.0) * u_ab.imag
    uc = -0.5 * u_ab.real - 0.5 * math.sqrt(3.0) * u_ab.imag
    zs = 0.5 * (max(ua, ub, uc) + min(ua, ub, uc))
    return np.clip(np.array([ua - zs, ub - zs, uc - zs]) / (0.5 * u_dc), -1.0, 1.0)


def simulate(case: GEMCase, duration: float, seed: int) -> dict:
    """One GEM run of ``case`` (truth plant) under the drive written here (nominal-parameter tuning); returns the
    drive's samples at the control instants in GEM's frames (amplitude-invariant d-q, complex d + jq)."""
    mt, ld = truth_motor(case), truth_load(case)
    ps_ = build_system(mt, ld, tau_ext=case.tau_ext, interlocking_time=case.interlocking_time)
    ix = _index(ps_)
    lim = ps_.limits
    # the drive's model of the motor: the nominal file (amplitude-invariant units, GEM's names)
    nom = dict(GEM_MOTOR)
    nom["l_d"] = nom["l_q"] = case.nominal.get("motor.q_inductance", GEM_MOTOR["l_q"])
    if case.drive_knows_saliency:
        nom["l_d"], nom["l_q"] = mt["l_d"], mt["l_q"]
    p, psi, R = nom["p"], nom["psi_p"], nom["r_s"]
    J_nom = case.nominal.get("motor.rotor_inertia", NOMINAL_BASE["motor.rotor_inertia"])   # the user's J
    a_c = 2 * math.pi * ALPHA_C_HZ
    kp_d, kp_q, ki = a_c * nom["l_d"], a_c * nom["l_q"], a_c * R
    w_n = 2 * math.pi * SPEED_LOOP_HZ
    kp_s, ki_s = 2.0 * w_n * J_nom, w_n * w_n * J_nom
    k_tau = 1.5 * p * psi                          # torque per amplitude-invariant q-ampere (nominal)
    i_max = I_MAX_Q / SQRT3_2
    v_max = U_DC / math.sqrt(3.0)
    w_ref = speed_reference(duration, seed)

    n = int(round(duration / T_S)) + 1
    out = {k: np.zeros(n) for k in ("t", "w", "w_ref", "theta_e", "torque", "tau_ext")}
    out.update({k: np.zeros(n, dtype=complex) for k in ("i_ref", "i", "u_cmd", "u_gem")})
    x = np.asarray(ps_.reset(), dtype=float) * lim
    z = 0j                # current-PI integrator (d + jq)
    zs = 0.0              # speed-PI integrator [N·m]
    duty = np.zeros(3)    # the duty computed last period: applied during this one (computation delay)
    theta_e = float(x[ix["epsilon"]])
    eps_prev = theta_e
    for k in range(n):
        i = complex(x[ix["i_sd"]], x[ix["i_sq"]])
        w = float(x[ix["omega"]])
        eps = float(x[ix["epsilon"]])
        theta_e += (eps - eps_prev + math.pi) % (2 * math.pi) - math.pi   # unwrap GEM's wrapped ε
        eps_prev = eps
        t = k * T_S
        # speed loop -> q-current reference (amplitude-invariant), clamped with a clamped integrator
        e_w = w_ref(t) - w
        tau_ref = kp_s * e_w + zs
        iq_ref = min(max(tau_ref / k_tau, -i_max), i_max)
        if abs(tau_ref / k_tau) < i_max:
            zs += ki_s * T_S * e_w
        # current loop (d-q PI, decoupling + back-EMF feed-forward with the nominal model)
        e = complex(0.0, iq_ref) - i
        pw = p * w
        v_ff = complex(-pw * nom["l_q"] * i.imag, pw * (nom["l_d"] * i.real + psi))
        v_pi = complex(kp_d * e.real, kp_q * e.imag) + z + v_ff
        mag = abs(v_pi)
        v = v_pi * (v_max / mag) if mag > v_max else v_pi
        z += ki * T_S * e + (v - v_pi)
        out["t"][k], out["w"][k], out["w_ref"][k], out["theta_e"][k] = t, w, w_ref(t), theta_e
        out["i_ref"][k], out["i"][k], out["u_cmd"][k] = complex(0.0, iq_ref), i, v
        out["torque"][k] = float(x[ix["torque"]])
        if k == n - 1:
            break
        # apply the previous period's duty now; this period's goes out at the next sample, at the angle then
        x = np.asarray(ps_.simulate(duty), dtype=float) * lim
        out["u_gem"][k] = complex(x[ix["u_sd"]], x[ix["u_sq"]])
        out["tau_ext"][k] = case.tau_ext
        duty = abc_duty(v, theta_e + pw * T_S, U_DC)
    out["par"] = {"motor": mt, "load": ld, "tau_ext": case.tau_ext, "J": mt["j_rotor"] + ld["j_load"]}
    return out


def to_q(x_amplitude_invariant):
    """GEM's amplitude-invariant d-q -> this project's power-invariant d-q: × √(3/2)."""
    from bldc_actuator import frames

    return frames.dq_power_invariant_from_amplitude_invariant(np.asarray(x_amplitude_invariant))


def to_recording(run: dict, *, rate: float, seed: int, noise: bool = True) -> dict:
    """The drive's samples -> this project's recording (canonical channels, SI, motor side, power-invariant d-q),
    logged at ``rate`` (every ``10 kHz / rate``-th control sample, no filter) with sensor noise from ``seed``."""
    rng = np.random.default_rng(seed)
    q = max(1, int(round(1.0 / (T_S * rate))))
    idx = np.arange(0, len(run["t"]), q)
    m = len(idx)
    p = run["par"]["motor"]["p"]

    def nz(scale):
        return scale * rng.standard_normal(m) if noise else np.zeros(m)

    i_ref, i_m, u = to_q(run["i_ref"][idx]), to_q(run["i"][idx]), to_q(run["u_cmd"][idx])
    theta_m = run["theta_e"][idx] / p
    res = 2 * np.pi / 2 ** ENCODER_BITS
    return {
        "time": run["t"][idx] - run["t"][0],
        "current_command": i_ref.imag,
        "current": i_m.imag + nz(CURRENT_NOISE_Q),
        "current_d": i_m.real + nz(CURRENT_NOISE_Q),
        "position": np.round(theta_m / res) * res if noise else theta_m,
        "velocity": run["w"][idx] + nz(VELOCITY_NOISE),
        "bus_voltage": np.full(m, U_DC),
        "voltage_q": u.imag + nz(VOLTAGE_NOISE_Q),
        "voltage_d": u.real + nz(VOLTAGE_NOISE_Q),
        "true_omega": run["w"][idx],
        "true_i_q": i_m.imag,
    }


def hidden_term(case: GEMCase, run: dict, nominal) -> dict:
    """RMS of what the hidden effect adds, in the channel where it lives, next to the noise there: torque effects
    in q-current units, voltage effects in volts."""
    w, K = run["w"], nominal.motor.torque_constant_q
    iq = to_q(run["i"]).imag
    mt, ld = run["par"]["motor"], run["par"]["load"]
    eff = np.zeros_like(w)
    if "b" in case.load:
        eff = (ld["b"] - nominal.motor.viscous_damping) * w / K
    elif "a" in case.load:
        eff = ld["a"] * np.sign(w) / K
    elif case.interlocking_time:    # the mean d-q size of three legs' ±t_d/T·u_dc (power-invariant)
        eff = np.full_like(w, 1.5594 * case.interlocking_time / T_S * U_DC)
    elif "j_load" in case.load:
        eff = (ld["j_load"] - GEM_LOAD["j_load"]) * np.gradient(w, run["t"]) / K
    elif "psi_p" in case.motor:
        eff = (mt["psi_p"] / GEM_MOTOR["psi_p"] - 1.0) * K * w
    elif "r_s" in case.motor:
        eff = (mt["r_s"] - nominal.motor.phase_resistance) * iq
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
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for i in range(len(rec["time"])):
            w.writerow([f"{rec[c][i]:.7g}" if c != "time" else f"{rec[c][i]:.5f}" for c in COLUMNS])


def gem_version() -> str:
    try:
        from importlib.metadata import version

        return version("gym-electric-motor")
    except Exception:   # noqa: BLE001
        return "not installed"


def _job(args):
    import time

    case, role, duration, seed = args
    t0 = time.perf_counter()
    run = simulate(case, duration, seed)
    return case.name, role, run, time.perf_counter() - t0


def generate(cases, outdir: Path, *, progress: Callable[[str], None] | None = None, workers: int = 2) -> dict:
    """Simulate each case's training and held-out runs with GEM and write the files (same layout as
    :func:`cases.generate`: train.csv, heldout.csv, params.yaml, truth.json)."""
    import time

    from bldc_actuator.params import dump_yaml

    outdir = Path(outdir)
    jobs = []
    for c in cases:
        jobs += [(c, "train", c.train_s, 1000 * c.seed + 1), (c, "heldout", c.heldout_s, 1000 * c.seed + 2)]
    runs, secs, t0 = {}, {}, time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as ex:
        for k, (name, role, run, dt) in enumerate(ex.map(_job, jobs), start=1):
            runs[(name, role)] = run
            secs[name] = secs.get(name, 0.0) + dt
            if progress:
                progress(f"simulated {k}/{len(jobs)} recordings with GEM ({time.perf_counter() - t0:.0f} s)")
    truths = {}
    for c in cases:
        d = outdir / c.name
        d.mkdir(parents=True, exist_ok=True)
        nominal = nominal_params(c)
        for role, sd in (("train", 1000 * c.seed + 11), ("heldout", 1000 * c.seed + 12)):
            write_csv(d / f"{role}.csv", to_recording(runs[(c.name, role)], rate=c.log_rate, seed=sd))
        dump_yaml(nominal, d / "params.yaml", header=f"GEM concealed case {c.name}: the NOMINAL model")
        tr = runs[(c.name, "train")]
        truth = {
            "case": c.name, "effects": list(c.effects), "story": c.story, "truth": c.truth,
            "alias_ok": {k: list(v) for k, v in c.alias_ok.items()},
            "source": f"gym-electric-motor {gem_version()} (SynchronousMotorSystem: PermanentMagnetSynchronousMotor, "
                      "ContB6BridgeConverter, PolynomialStaticLoad, IdealVoltageSupply, ScipyOdeSolver); drive: PI "
                      "current + PI speed control written outside GEM",
            "gem_motor": truth_motor(c), "gem_load": truth_load(c), "tau_ext": c.tau_ext,
            "interlocking_time": c.interlocking_time, "nominal_overrides": c.nominal,
            "concealment": hidden_term(c, tr, nominal), "oracle": None, "generation_seconds": secs[c.name],
            "train": {"excitation": "speed: triangle + multisine", "duration_s": c.train_s, "seed": 1000 * c.seed + 1},
            "heldout": {"excitation": "speed: triangle + multisine", "duration_s": c.heldout_s,
                        "seed": 1000 * c.seed + 2},
            "log": {"rate": c.log_rate, "filter": "sample", "torque_sensor": False},
            "ranges": {"max_abs_velocity_motor_rad_s": float(np.max(np.abs(tr["w"]))),
                       "max_abs_current_A": float(np.max(np.abs(to_q(tr["i"]).imag)))},
        }
        (d / "truth.json").write_text(json.dumps(truth, indent=2, default=float) + "\n")
        truths[c.name] = truth
    return truths
