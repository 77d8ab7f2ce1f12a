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

The nominal file describes that drive as it is (``drive.decoupling_enabled: true``: it feeds the back-EMF and
the cross-coupling forward with the nominal ψ and L; back-calculation anti-windup, proportional voltage limit on the
SVPWM circle, one period of delay, 10 kHz PWM: the nominal file's drive fields). The recordings are made by
:mod:`.gem_sim` from each case's :func:`recording_spec` and cached per case under that key (:mod:`.case_kit`); the
truth and nominal files are written from the case definition on every run.

Run in the peers venv (``bash benchmarks/peers/setup.sh``): ``benchmarks/run_concealed.py --set gem``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from . import case_kit as kit
from . import gem_sim as sim
from .gem_sim import (ALPHA_C_HZ, CURRENT_NOISE_Q, I_MAX_Q, SPEED_LOOP_HZ, SQRT3_2, T_S, U_DC,  # noqa: F401
                      VOLTAGE_NOISE_Q, abc_duty, build_system, speed_reference, to_q, to_recording)

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
        "drive.pwm_frequency": 1.0 / tau, "drive.decoupling_enabled": True, "gear.gear_ratio": 1.0,
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
    return kit.find_case(CASES, name, "GEM")


reseeded = kit.reseeded


def nominal_params(case: GEMCase):
    return kit.nominal_params(NOMINAL_BASE, case)


def truth_motor(case: GEMCase) -> dict:
    m = dict(GEM_MOTOR)
    if case.nominal.get("motor.q_inductance"):
        m["l_d"] = m["l_q"] = case.nominal["motor.q_inductance"]
    m.update(case.motor)
    return m


def truth_load(case: GEMCase) -> dict:
    return {**GEM_LOAD, **case.load}


# ------------------------------------------------------------------------------------------- the recording spec

def simulation_spec(case: GEMCase) -> dict:
    """What GEM and the drive are given for ``case``: the truth plant in GEM's names and the drive's model of the
    motor (the nominal one; a drive that knows the saliency has the true L_d, L_q)."""
    mt, ld = truth_motor(case), truth_load(case)
    nom = dict(GEM_MOTOR)
    nom["l_d"] = nom["l_q"] = case.nominal.get("motor.q_inductance", GEM_MOTOR["l_q"])
    if case.drive_knows_saliency:
        nom["l_d"], nom["l_q"] = mt["l_d"], mt["l_q"]
    drive = {k: nom[k] for k in ("p", "r_s", "l_d", "l_q", "psi_p")}
    drive["J"] = case.nominal.get("motor.rotor_inertia", NOMINAL_BASE["motor.rotor_inertia"])
    return {"motor": mt, "load": ld, "tau_ext": float(case.tau_ext),
            "interlocking_time": float(case.interlocking_time), "drive": drive}


#: what the user of this drive knows about its log and tells ``diagnose``: the logged voltage is the one the drive
#: computed from the current sample logged with it, applied one period later (``drive.current_loop_delay``) and held
#: for a period (:mod:`.gem_sim`); nothing in a noise-free log shows it (no frame turn: the drive advances its angle
#: by the delay; no sensor noise inside the loop)
DIAGNOSE_ARGS = ("--voltage-timing", "command")


def recording_spec(case: GEMCase) -> dict:
    """Everything ``case``'s recordings depend on besides :mod:`.gem_sim`'s code and the library versions."""
    return {"simulation": simulation_spec(case), "seeds": kit.seeds(case), "train_s": float(case.train_s),
            "heldout_s": float(case.heldout_s), "log_rate": float(case.log_rate)}


def recording_key(case: GEMCase) -> str:
    return kit.recording_key(recording_spec(case), sim, sim.LIBRARIES, (write_recordings,))


def simulate(case: GEMCase, duration: float, seed: int) -> dict:
    """One GEM run of ``case`` (truth plant, nominal-parameter drive): :func:`.gem_sim.simulate`."""
    return sim.simulate(simulation_spec(case), duration, seed)


def gem_version() -> str:
    return kit.library_version("gym-electric-motor")


def code_stamp() -> str:
    return kit.code_stamp(sim, sim.LIBRARIES, (write_recordings,))


# ------------------------------------------------------------------------------------------- truth

def hidden_term(case: GEMCase, sig: dict, nominal) -> dict:
    """RMS of what the hidden effect adds, in the channel where it lives, next to the noise there: torque effects
    in q-current units, voltage effects in volts. ``sig``: the training run's clean signals."""
    w, K = sig["w"], nominal.motor.torque_constant_q
    iq = sig["i_q"]
    mt, ld = truth_motor(case), truth_load(case)
    eff = np.zeros_like(w)
    if "b" in case.load:
        eff = (ld["b"] - nominal.motor.viscous_damping) * w / K
    elif "a" in case.load:
        eff = ld["a"] * np.sign(w) / K
    elif case.interlocking_time:    # the mean d-q size of three legs' ±t_d/T·u_dc (power-invariant)
        eff = np.full_like(w, 1.5594 * case.interlocking_time / T_S * U_DC)
    elif "j_load" in case.load:
        eff = (ld["j_load"] - GEM_LOAD["j_load"]) * np.gradient(w, sig["t"]) / K
    elif "psi_p" in case.motor:
        eff = (mt["psi_p"] / GEM_MOTOR["psi_p"] - 1.0) * K * w
    elif "r_s" in case.motor:
        eff = (mt["r_s"] - nominal.motor.phase_resistance) * iq
    return kit.concealment(case, float(np.sqrt(np.mean(eff ** 2))), CURRENT_NOISE_Q, VOLTAGE_NOISE_Q)


def write_recordings(case: GEMCase, runs: dict, d: Path) -> None:
    s = kit.seeds(case)
    for role in ("train", "heldout"):
        kit.write_csv(d / f"{role}.csv", sim.to_recording(runs[role], rate=case.log_rate, seed=s[f"{role}_noise"]),
                      sim.COLUMNS)
    kit.save_train_truth(d / "train_truth.npz", **sim.true_signals(runs["train"]))


def write_truth(case: GEMCase, d: Path) -> dict:
    """``params.yaml`` and ``truth.json`` of ``case`` from its definition and the stored clean training signals."""
    return kit.write_truth(
        case, d, nominal_params(case), label="GEM",
        source=f"gym-electric-motor {gem_version()} (SynchronousMotorSystem: PermanentMagnetSynchronousMotor, "
               "ContB6BridgeConverter, PolynomialStaticLoad, IdealVoltageSupply, ScipyOdeSolver); drive: PI "
               "current (decoupling and back-EMF feed-forward) + PI speed control written outside GEM",
        specifics={"gem_motor": truth_motor(case), "gem_load": truth_load(case), "tau_ext": case.tau_ext,
                   "interlocking_time": case.interlocking_time, "nominal_overrides": case.nominal},
        concealment=hidden_term)


def _job(args):
    case, role, duration, seed = args
    return sim.job((case.name, simulation_spec(case), role, duration, seed))


def ensure(cases, outdir: Path, *, regenerate: bool = False, progress: Callable[[str], None] | None = None,
           workers: int = 2) -> tuple[dict, list[str]]:
    """Simulate the cases whose recordings are missing or stale (:func:`recording_key`), rewrite every case's
    nominal and truth files; ``({name: truth}, [names simulated])``."""
    return kit.ensure(cases, outdir, key=recording_key, simulate_job=_job, write_recordings=write_recordings,
                      write_truth=write_truth, label="GEM", regenerate=regenerate, progress=progress,
                      workers=workers)


def generate(cases, outdir: Path, *, progress: Callable[[str], None] | None = None, workers: int = 2) -> dict:
    """Simulate every case of ``cases`` and write its files; ``{name: truth}``."""
    return ensure(cases, outdir, regenerate=True, progress=progress, workers=workers)[0]
