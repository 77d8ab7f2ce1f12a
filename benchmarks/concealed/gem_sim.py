"""The recordings of the gym-electric-motor set (:mod:`.gem_cases`): GEM's PMSM system under a drive written here,
simulated from a RECORDING SPEC, and its samples converted into this project's recording format and frames.

This module is the only code that makes the set's recordings; its source (with the case's spec and the library
versions) keys their cache (:func:`.case_kit.recording_key`), so an edit anywhere else (the cases' truth, the
nominal files, the scoring) leaves every cached recording valid. :func:`simulate` reads nothing but its spec:

``spec = {"motor": GEM motor parameters, "load": GEM load parameters, "tau_ext", "interlocking_time",
          "drive": {p, r_s, l_d, l_q, psi_p, J}}`` (the truth plant in GEM's names; the drive's tuning from what
the user believes).

The drive (written outside GEM, like a drive's firmware): a discrete d-q PI current controller (10 kHz, tuned with
the NOMINAL R, L by the bandwidth, decoupling and back-EMF feed-forward with the nominal ψ, back-calculation
anti-windup, one control period of computation delay with the angle advanced by that period, min-max
zero-sequence injection into three duty cycles) under a PI speed controller (tuned with the nominal J and ψ).
"""

from __future__ import annotations

import math
import time
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
LIBRARIES = ("gym-electric-motor",)
COLUMNS = ("time", "current_command", "current", "current_d", "position", "velocity", "bus_voltage", "voltage_q",
           "voltage_d")


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


def simulate(spec: dict, duration: float, seed: int) -> dict:
    """One GEM run of the truth plant ``spec["motor"]``, ``spec["load"]`` (GEM's names, amplitude invariant),
    ``spec["tau_ext"]``, ``spec["interlocking_time"]`` under the drive written here, tuned with what the user
    believes (``spec["drive"]``: p, r_s, l_d, l_q, psi_p, J); returns the drive's samples at the control instants
    in GEM's frames (amplitude-invariant d-q, complex d + jq)."""
    mt, ld, tau_ext = spec["motor"], spec["load"], spec["tau_ext"]
    ps_ = build_system(mt, ld, tau_ext=tau_ext, interlocking_time=spec["interlocking_time"])
    ix = _index(ps_)
    lim = ps_.limits
    nom = spec["drive"]                            # the drive's model of the motor (amplitude-invariant units)
    p, psi, R = nom["p"], nom["psi_p"], nom["r_s"]
    J_nom = nom["J"]                               # the user's J
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
        out["tau_ext"][k] = tau_ext
        duty = abc_duty(v, theta_e + pw * T_S, U_DC)
    out["par"] = {"motor": mt, "load": ld, "tau_ext": tau_ext, "J": mt["j_rotor"] + ld["j_load"]}
    return out



def job(args):
    """Worker entry: ``(name, spec, role, duration, seed)`` -> ``(name, role, run, seconds)``."""
    name, spec, role, duration, seed = args
    t0 = time.perf_counter()
    run = simulate(spec, duration, seed)
    return name, role, run, time.perf_counter() - t0


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


def true_signals(run: dict) -> dict[str, np.ndarray]:
    """The clean signals of a run at the control instants (power-invariant): what the truth's concealment figure
    and ranges are computed from without simulating again."""
    return {"t": run["t"], "w": run["w"], "i_q": to_q(run["i"]).imag, "i_q_ref": to_q(run["i_ref"]).imag,
            "v_q": to_q(run["u_cmd"]).imag}
