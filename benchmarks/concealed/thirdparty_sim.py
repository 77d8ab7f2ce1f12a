"""The recordings of the motulator set (:mod:`.thirdparty`): motulator's drive simulated from a RECORDING SPEC, and
its time series converted into this project's recording format and frames.

This module is the only code that makes the set's recordings; its source (with the case's spec and the library
versions) keys their cache (:func:`.case_kit.recording_key`), so an edit anywhere else (the cases' truth, the
nominal files, the scoring) leaves every cached recording valid. :func:`simulate` reads nothing but its spec:

``spec = {"plant": {n_p, R_s, L_d, L_q, psi_f, J, b, F_c, t_d, tau_ext, u_dc},
          "drive": {n_p, R_s, L_d, L_q, psi_f, J, i_max_q, alpha_c_hz, alpha_s_hz, tau_M_max}}``
(the truth machine and load; the drive's tuning from what the user believes) and :func:`to_recording` its
``rate`` and ``torque_sensor``.

Frames: motulator's space vectors are peak-value (amplitude-invariant) scaled, ``x = (2/3)(x_a + a x_b + a² x_c)``,
power ``(3/2) Re(u i*)``, torque ``(3/2) p Im(ψ_s* i)``; this project's ``_q`` frame is power invariant, so every
current and voltage is multiplied by √(3/2) (then ``P = v_d i_d + v_q i_q`` and ``τ = K_q i_q`` with
``K_q = √(3/2) p ψ_f``).
"""

from __future__ import annotations

import math
import time
from typing import Callable

import numpy as np

SQRT3_2 = math.sqrt(1.5)
T_S = 1.0e-4                 #: motulator control period [s] (double update: carrier period 2 T_S, f_pwm 5 kHz)
ENCODER_BITS = 14
CURRENT_NOISE_Q = 0.03       #: [A] white noise on the logged d/q currents (power-invariant)
VOLTAGE_NOISE_Q = 0.01       #: [V] on the logged d/q voltages
VELOCITY_NOISE = 0.02        #: [rad/s]
TORQUE_NOISE = 0.003         #: [N·m] torque sensor
F_EPS = 0.05                 #: [rad/s] tanh regularisation of the Coulomb-like load friction
LIBRARIES = ("motulator",)
COLUMNS = ("time", "current_command", "current", "current_d", "position", "velocity", "bus_voltage", "voltage_q",
           "voltage_d")


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

def simulate(spec: dict, duration: float, seed: int) -> dict:
    """One motulator run (truth plant ``spec["plant"]``, drive tuned with ``spec["drive"]``); returns motulator's
    own time series in its own frames (amplitude-invariant space vectors), sampled at the control instants."""
    from motulator.drive import model
    import motulator.drive.control.sm as sm

    P, D = spec["plant"], spec["drive"]
    par_true = model.SynchronousMachinePars(n_p=P["n_p"], R_s=P["R_s"], L_d=P["L_d"], L_q=P["L_q"],
                                            psi_f=P["psi_f"])
    par_drive = model.SynchronousMachinePars(n_p=D["n_p"], R_s=D["R_s"], L_d=D["L_d"], L_q=D["L_q"],
                                             psi_f=D["psi_f"])
    J, b, F_c = P["J"], P["b"], P["F_c"]

    def B_L(w):            # motulator's load torque is B_L(w) * w
        if F_c == 0.0:
            return b
        w = float(w)
        return b + (F_c * math.tanh(w / F_EPS) / w if abs(w) > 1e-9 else F_c / F_EPS)

    mech = model.MechanicalSystem(J=J, B_L=B_L)
    tau_ext = P["tau_ext"]       # a constant external load (the user knows it: load.load_torque)
    if tau_ext:
        mech.set_external_load_torque(tau_ext)
    mdl = model.Drive(model.SynchronousMachine(par_true), mech,
                      model.VoltageSourceConverter(u_dc=P["u_dc"], t_d=P["t_d"]))
    cfg = sm.CurrentVectorControllerCfg(i_s_max=D["i_max_q"] / SQRT3_2, alpha_c=2 * math.pi * D["alpha_c_hz"],
                                        T_s=T_S, sensorless=False)
    spd = sm.SpeedController(J=D["J"], alpha_s=2 * math.pi * D["alpha_s_hz"], tau_M_max=D["tau_M_max"])
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
        "par": {"n_p": P["n_p"], "psi_f": P["psi_f"], "R_s": P["R_s"], "L_d": P["L_d"], "L_q": P["L_q"],
                "J": J, "b": b, "F_c": F_c},
    }


def job(args):
    """Worker entry: ``(name, spec, role, duration, seed)`` -> ``(name, role, run, seconds)``."""
    name, spec, role, duration, seed = args
    t0 = time.perf_counter()
    run = simulate(spec, duration, seed)
    return name, role, run, time.perf_counter() - t0


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


def columns(rec: dict) -> tuple[str, ...]:
    return COLUMNS + (("torque",) if "torque" in rec else ())


def true_signals(run: dict) -> dict[str, np.ndarray]:
    """The clean signals of a run at the control instants (power-invariant): what the truth's concealment figure
    and ranges are computed from without simulating again."""
    return {"t": run["t"], "w": run["w_M"], "i_q": to_q(run["i_meas"]).imag, "i_q_ref": to_q(run["i_ref"]).imag,
            "v_q": to_q(run["u_ref"]).imag}
