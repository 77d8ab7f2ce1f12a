r"""Truth simulator of a closed-loop robot joint, independent of the diagnoser's model.

Written from the physics, NOT from ``bldc_actuator.model`` / ``bldc_actuator.effects`` (the diagnoser's
candidate library): a benchmark whose truth reused the candidate terms would only test that a fit
recovers its own equations. It is richer than the nominal model in these ways:

* **three-phase inverter and sensing**: the drive measures two *phase* currents (offset, gain, white
  noise each), reconstructs the third, Clarke/Park-transforms them with the *quantised encoder* angle;
  the inverter holds the voltage vector fixed in the *stator* (alpha-beta) frame over each PWM period
  while the rotor turns (the model holds v_dq); the drive advances its angle by half a period;
* **closed loop like a robot joint**: 1 kHz impedance controller (PD on output angle + inertia and
  known-load feed-forward computed with the NOMINAL parameters) → q-current reference → discrete
  PI current loop (10 kHz, gains from the nominal R and L, decoupling with the drive's speed estimate,
  back-calculation anti-windup) → modulation limit (a fraction of the SVPWM circle) from the *measured*
  bus voltage; speed estimated by a PLL on the quantised encoder (14 bit / motor revolution);
* **supply**: the bus sags through a source resistance under load; bus sensor noise;
* **friction** regularised with ``tanh(ω/ω_ε)`` (a smooth stick model, not the model's stick/slip logic),
  Stribeck hump and direction asymmetry in the same smooth form;
* **cogging** of a 36-slot / 42-pole machine: ``N_c = lcm(36, 42) = 252`` periods per motor revolution,
  two harmonics with their own phases;
* **thermal**: two nodes, resistance ``R(T_w)`` always physical (alpha of copper), magnet flux optionally
  temperature dependent (at the housing temperature); temperature sensors quantised.

Mechanics and electrics are integrated with classical RK4 at ``plant_substeps`` × the current-loop rate
(20 kHz by default) on the rotor-frame state ``(i_d, i_q, ω, θ)``; every recording of a batch is one
column of numpy arrays, so a batch of ~100 recordings costs about as much as one.

Frames: currents/voltages are power-invariant d-q of the winding (phase) quantities, so that
``P = v_d i_d + v_q i_q`` and the torque is ``K i_q`` with ``K`` the q-axis torque constant
[N·m/A] = back-EMF constant [V·s/rad] (motor side). Angles are motor-side mechanical radians
unless ``_out`` (output side, after the gear ``N``); ``θ_e = p θ``. Load torques at the output
oppose positive motion (the project's convention): ``J dω/dt = K i_q - τ_f - τ_cog - τ_load_out/N``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

SQRT2_3 = math.sqrt(2.0 / 3.0)
SQRT3_2 = math.sqrt(1.5)
TWO_PI = 2.0 * math.pi


# --------------------------------------------------------------------------------------------- frames
# Own three-line implementations (power-invariant, rows [cos; -sin]); a test cross-checks them with
# bldc_actuator.frames so that both projects agree on the convention, not on the code.

def clarke(a, b, c):
    """abc → alpha-beta, power invariant: ``x_α = √(2/3)(a - (b+c)/2)``, ``x_β = (b - c)/√2``."""
    return SQRT2_3 * (a - 0.5 * (b + c)), (b - c) / math.sqrt(2.0)


def inverse_clarke(alpha, beta):
    a = SQRT2_3 * alpha
    b = SQRT2_3 * (-0.5 * alpha) + beta / math.sqrt(2.0)
    c = SQRT2_3 * (-0.5 * alpha) - beta / math.sqrt(2.0)
    return a, b, c


def park(alpha, beta, theta_e):
    c, s = np.cos(theta_e), np.sin(theta_e)
    return c * alpha + s * beta, -s * alpha + c * beta


def inverse_park(d, q, theta_e):
    c, s = np.cos(theta_e), np.sin(theta_e)
    return c * d - s * q, s * d + c * q


# ------------------------------------------------------------------------------------------ the spec

@dataclass(frozen=True)
class Plant:
    """The physical actuator (what is really there). Motor side unless ``_out``."""

    pole_pairs: int = 21
    R_ref: float = 0.17            #: phase resistance at T_ref [Ω]
    L: float = 5.7e-5              #: q (= d) inductance [H]
    K: float = 0.091               #: q-axis torque / back-EMF constant at T_ref [N·m/A]
    J: float = 6.0e-5              #: inertia at the rotor, load reflected [kg·m²]
    b: float = 1.0e-5              #: viscous friction [N·m·s/rad]
    gear: float = 9.0              #: N = θ / θ_out
    T_ref: float = 25.0            #: [°C]
    alpha_cu: float = 0.00393      #: copper resistance coefficient [1/K]
    beta_magnet: float = 0.0       #: magnet flux coefficient [1/K] at the housing temperature (0 = none)
    coulomb: float = 0.0           #: τ_c [N·m]
    asymmetry: float = 0.0         #: τ_a: + for ω > 0 ... added to the friction force while moving [N·m]
    stribeck: float = 0.0          #: τ_s: extra friction at low speed [N·m]
    stribeck_velocity: float = 1.0  #: ω_s [rad/s]
    friction_eps: float = 0.02     #: ω_ε of the smooth sign tanh(ω/ω_ε) [rad/s]
    cogging_order: int = 252       #: N_c = lcm(slots, 2p) = lcm(36, 42)
    cogging_amp: tuple = ()        #: amplitudes of harmonics k = 1.. of N_c θ [N·m]
    cogging_phase: tuple = ()      #: phases [rad]
    load_const_out: float = 0.0    #: τ_0 at the output [N·m]
    gravity_out: float = 0.0       #: τ_g: τ_0 + τ_g sin(θ_out + φ_g) [N·m]
    gravity_phase: float = 0.0     #: φ_g [rad]
    # thermal network
    C_w: float = 30.0
    C_h: float = 300.0
    R_wh: float = 1.0
    R_ha: float = 2.0
    T_ambient: float = 25.0
    T_w0: float = 25.0
    T_h0: float = 25.0
    # supply
    supply_voltage: float = 24.0   #: open-circuit supply [V]
    source_resistance: float = 0.05  #: [Ω]


@dataclass(frozen=True)
class Drive:
    """The drive firmware and the joint controller: built from what the user BELIEVES (nominal)."""

    current_loop_rate: float = 10000.0   #: [Hz]
    bandwidth: float = 1000.0            #: PI tuned for this bandwidth with the nominal R, L [Hz]
    R_nom: float = 0.17
    L_nom: float = 5.7e-5
    K_nom: float = 0.091
    modulation_limit: float = 1.0        #: fraction of the SVPWM circle V_bus/√2 the modulator reaches
    current_limit: float = 20.0          #: |i_q_ref| limit [A]
    pll_bandwidth: float = 150.0         #: speed estimator bandwidth [Hz]
    position_rate: float = 1000.0        #: joint controller and recording rate [Hz]
    kp_out: float = 60.0                 #: [N·m/rad] output side
    kd_out: float = 0.8                  #: [N·m·s/rad]
    J_ff: float = 6.0e-5                 #: inertia used for the feed-forward (nominal) [kg·m²]
    N_nom: float = 9.0                   #: gear ratio the controller believes
    load_const_ff_out: float = 0.0       #: known load feed-forward [N·m, output]
    gravity_ff_out: float = 0.0          #: known gravity feed-forward amplitude [N·m, output]
    gravity_ff_phase: float = 0.0
    coulomb_ff: float = 0.0              #: known Coulomb friction feed-forward [N·m, motor side]
    #: True: the PI outputs get the feed-forward u_d -= p ω̂ L i_q, u_q += p ω̂ L i_d + K ω̂ (ω̂ = the PLL speed, the
    #: nominal L and K); False: plain PI, the integrator has to build up the back-EMF itself (it lags at speed)
    decoupling: bool = True
    #: "back_calculation": the integrator takes the limiter's cut back (z += Ki T e + (v - u));
    #: "clamp": conditional integration, an axis's integrator frozen while its output is cut and the error
    #: pushes further into the cut; "none": the integrator always integrates (winds up at the voltage limit)
    anti_windup: str = "back_calculation"
    #: the PI output (u_d, u_q) onto the circle |v| <= V_lim: "proportional" scales the whole vector,
    #: "d_priority" keeps u_d (clamped to ±V_lim) and gives v_q what is left of the circle, "q_priority" keeps
    #: u_q (clamped) and gives v_d what is left (the product's drive.voltage_limit_mode, same meanings)
    voltage_limit: str = "proportional"
    #: first-order low-pass [Hz] on the speed the drive REPORTS (0 = none): ``ω_f += a (ω̂ - ω_f)`` each current-loop
    #: tick, ``a = 1 - exp(-2π f T)``. The logged ``velocity`` and the joint controller's D term use ω_f; the
    #: current loop's decoupling keeps the unfiltered PLL speed ω̂ (a firmware's display/velocity-output filter)
    velocity_filter: float = 0.0
    #: True: the recording holds every current-loop tick (a drive that logs at its current-loop rate, e.g.
    #: 10 kHz), with the joint controller still at ``position_rate``; False: one sample per joint-controller step
    record_ticks: bool = False


@dataclass(frozen=True)
class Sensors:
    current_noise: float = 0.07          #: white noise per phase sensor, standard deviation [A]
    offset_a: float = 0.001              #: phase a sensor offset [A]
    offset_b: float = -0.001             #: phase b sensor offset [A]
    gain_a: float = 1.0
    gain_b: float = 1.0
    encoder_bits: int = 14               #: per motor revolution
    bus_noise: float = 0.03              #: [V]
    bus_quantum: float = 0.01            #: [V]
    winding_quantum: float = 0.5         #: [°C]
    housing_quantum: float = 0.1         #: [°C]
    temperature_noise: float = 0.05      #: [°C]
    enabled: bool = True                 #: False: no random noise, no quantisation (offsets and gains stay:
                                         #: they are sensor *errors*, e.g. the hidden electrical ripple)


@dataclass(frozen=True)
class Reference:
    """Joint reference at the position-controller rate (output side)."""

    theta_out: np.ndarray                #: [rad]
    omega_out: np.ndarray                #: [rad/s]
    alpha_out: np.ndarray                #: [rad/s²]
    rate: float = 1000.0

    @property
    def n(self) -> int:
        return len(self.theta_out)


@dataclass(frozen=True)
class TruthSpec:
    plant: Plant = field(default_factory=Plant)
    drive: Drive = field(default_factory=Drive)
    sensors: Sensors = field(default_factory=Sensors)
    seed: int = 0
    plant_substeps: int = 2              #: RK4 steps per current-loop period


# ------------------------------------------------------------------------------------------ simulator

COLUMNS = ("time", "current_command", "current", "position", "velocity", "bus_voltage", "voltage_q",
           "winding_temperature", "housing_temperature")
#: noise-free internal signals also returned (prefixed ``true_``) for checks and the SNR table
TRUE_COLUMNS = ("i_q", "i_d", "omega", "theta", "T_w", "T_h", "tau_friction", "tau_cogging", "tau_load",
                "tau_em", "v_q", "v_d", "bus_voltage", "R", "K", "p_elec", "p_joule", "v_limit")


#: flat parameter vector shared by both kernels (numpy reference and C); order matters
PARAM_NAMES = (
    # plant
    "p", "R_ref", "L", "K0", "J", "b", "N", "T_ref", "alpha", "beta", "Fc", "Fa", "Fs", "inv_ws", "inv_eps",
    "Nc", "cog_A1", "cog_ph1", "cog_A2", "cog_ph2", "cog_A3", "cog_ph3", "load0", "grav", "grav_ph",
    "C_w", "C_h", "R_wh", "R_ha", "T_amb", "T_w0", "T_h0", "V_s", "R_s",
    # drive
    "f_cl", "sub", "ticks_per_pos", "Kp_i", "Ki_i", "L_nom", "K_nom", "m_lim", "I_lim", "k1_pll", "k2_pll",
    "kp_out", "kd_out", "N_nom", "J_ff_out", "ff_const", "ff_g", "ff_gph", "ff_c", "dec", "aw", "vlm", "a_vf", "rec_all",
    # sensors
    "sig_i", "off_a", "off_b", "g_a", "g_b", "q_enc",
)
N_COGGING_HARMONICS = 3
ANTI_WINDUP = ("back_calculation", "clamp", "none")
VOLTAGE_LIMITS = ("proportional", "d_priority", "q_priority")


def param_vector(spec: TruthSpec) -> np.ndarray:
    """Everything the kernels need, in ``PARAM_NAMES`` order (motor side, SI)."""
    P, D, S = spec.plant, spec.drive, spec.sensors
    if len(P.cogging_amp) > N_COGGING_HARMONICS or len(P.cogging_phase) != len(P.cogging_amp):
        raise ValueError(f"cogging: at most {N_COGGING_HARMONICS} harmonics with one phase each")
    cog = [0.0] * (2 * N_COGGING_HARMONICS)
    for k, (a, ph) in enumerate(zip(P.cogging_amp, P.cogging_phase)):
        cog[2 * k], cog[2 * k + 1] = a, ph
    ticks = D.current_loop_rate / D.position_rate
    if abs(ticks - round(ticks)) > 1e-9:
        raise ValueError("drive.current_loop_rate must be a multiple of drive.position_rate")
    w_c, w_pll = TWO_PI * D.bandwidth, TWO_PI * D.pll_bandwidth
    if D.anti_windup not in ANTI_WINDUP or D.voltage_limit not in VOLTAGE_LIMITS:
        raise ValueError(f"drive.anti_windup: one of {ANTI_WINDUP}, drive.voltage_limit: one of {VOLTAGE_LIMITS}; "
                         f"got {D.anti_windup!r}, {D.voltage_limit!r}")
    on = 1.0 if S.enabled else 0.0
    values = dict(
        p=P.pole_pairs, R_ref=P.R_ref, L=P.L, K0=P.K, J=P.J, b=P.b, N=P.gear, T_ref=P.T_ref, alpha=P.alpha_cu,
        beta=P.beta_magnet, Fc=P.coulomb, Fa=P.asymmetry, Fs=P.stribeck, inv_ws=1.0 / P.stribeck_velocity,
        inv_eps=1.0 / P.friction_eps, Nc=P.cogging_order,
        cog_A1=cog[0], cog_ph1=cog[1], cog_A2=cog[2], cog_ph2=cog[3], cog_A3=cog[4], cog_ph3=cog[5],
        load0=P.load_const_out / P.gear, grav=P.gravity_out / P.gear, grav_ph=P.gravity_phase,
        C_w=P.C_w, C_h=P.C_h, R_wh=P.R_wh, R_ha=P.R_ha, T_amb=P.T_ambient, T_w0=P.T_w0, T_h0=P.T_h0,
        V_s=P.supply_voltage, R_s=P.source_resistance,
        f_cl=D.current_loop_rate, sub=spec.plant_substeps, ticks_per_pos=round(ticks),
        Kp_i=w_c * D.L_nom, Ki_i=w_c * D.R_nom, L_nom=D.L_nom, K_nom=D.K_nom,
        m_lim=D.modulation_limit / math.sqrt(2.0), I_lim=D.current_limit,
        k1_pll=2.0 * w_pll, k2_pll=w_pll ** 2, kp_out=D.kp_out, kd_out=D.kd_out, N_nom=D.N_nom,
        J_ff_out=D.J_ff * D.N_nom ** 2, ff_const=D.load_const_ff_out, ff_g=D.gravity_ff_out,
        ff_gph=D.gravity_ff_phase, ff_c=D.coulomb_ff * D.N_nom, dec=1.0 if D.decoupling else 0.0,
        aw=float(ANTI_WINDUP.index(D.anti_windup)), vlm=float(VOLTAGE_LIMITS.index(D.voltage_limit)),
        a_vf=1.0 - math.exp(-TWO_PI * D.velocity_filter / D.current_loop_rate) if D.velocity_filter > 0 else 1.0,
        rec_all=1.0 if D.record_ticks else 0.0,
        sig_i=S.current_noise * on, off_a=S.offset_a, off_b=S.offset_b, g_a=S.gain_a, g_b=S.gain_b,
        q_enc=TWO_PI / 2.0 ** S.encoder_bits if S.enabled else 0.0,
    )
    return np.array([float(values[n]) for n in PARAM_NAMES])


def ticks_per_sample(drive: Drive) -> int:
    """Current-loop ticks per joint-controller step."""
    return round(drive.current_loop_rate / drive.position_rate)


def samples(drive: Drive, n_ref: int) -> int:
    """Recorded samples of a run whose reference has ``n_ref`` joint-controller steps."""
    return n_ref * ticks_per_sample(drive) if drive.record_ticks else n_ref


def _noise(spec: TruthSpec, n_ref: int):
    """Seeded noise of one recording: slow channels (3, n_samples) and phase-current sensors (2, n_ticks).
    With ``record_ticks`` the slow channels' noise at the joint-controller steps is the same draw as without
    (the extra tick samples get their own draw afterwards): a tick log sampled every ``ticks`` is the same
    recording as the one-per-step log of the same seed."""
    rng = np.random.default_rng(spec.seed)
    slow = rng.standard_normal((3, n_ref))
    ticks = ticks_per_sample(spec.drive)
    fast = rng.standard_normal((2, n_ref * ticks))
    if spec.drive.record_ticks and ticks > 1:
        every = rng.standard_normal((3, n_ref * ticks))
        every[:, ::ticks] = slow
        slow = every
    return slow, fast


# ---- numpy kernel: the readable reference (and fallback); many recordings as columns ---------------

def _kernel_numpy(par: np.ndarray, ref: np.ndarray, fast: np.ndarray, n_rec: int) -> np.ndarray:
    """``par`` (B, n_par), ``ref`` (B, 3, n_rec) [θ_out, ω_out, α_out] (``n_rec`` joint-controller steps),
    ``fast`` (B, 2, n_ticks) → ``out`` (B, len(KERNEL_ROWS), n_rec), or (..., n_ticks) with ``record_ticks``."""
    g = {name: par[:, i] for i, name in enumerate(PARAM_NAMES)}
    B = par.shape[0]
    p, L, J, b, N = g["p"], g["L"], g["J"], g["b"], g["N"]
    T = 1.0 / g["f_cl"][0]
    sub = int(g["sub"][0])
    tpp = int(g["ticks_per_pos"][0])
    h = T / sub
    pL, invL, invJ = p * L, 1.0 / L, 1.0 / J
    cogs = [(g[f"cog_A{k}"], g[f"cog_ph{k}"], k) for k in range(1, N_COGGING_HARMONICS + 1)
            if np.any(g[f"cog_A{k}"] != 0)]
    has_s, has_g, has_beta = np.any(g["Fs"] != 0), np.any(g["grav"] != 0), np.any(g["beta"] != 0)
    enc = g["q_enc"] > 0
    q_enc = np.where(enc, g["q_enc"], 1.0)

    def torque_terms(w_, th_):
        tw = np.tanh(w_ * g["inv_eps"])
        fc = g["Fc"] + g["Fs"] * np.exp(-(w_ * g["inv_ws"]) ** 2) if has_s else g["Fc"]
        fr = tw * fc + g["Fa"] * np.abs(tw) + b * w_
        cog = 0.0
        for A, ph, k in cogs:
            cog = cog + A * np.cos(k * g["Nc"] * th_ + ph)
        ld = g["load0"] + g["grav"] * np.sin(th_ / N + g["grav_ph"]) if has_g else g["load0"]
        return fr, cog, ld

    def deriv(i_d_, i_q_, w_, th_, va, vb, R, K):
        c, s = np.cos(p * th_), np.sin(p * th_)
        vd, vq = c * va + s * vb, c * vb - s * va
        pwL = pL * w_
        fr, cog, ld = torque_terms(w_, th_)
        return ((vd - R * i_d_ + pwL * i_q_) * invL, (vq - R * i_q_ - pwL * i_d_ - K * w_) * invL,
                (K * i_q_ - fr - cog - ld) * invJ)

    rec_all = bool(g["rec_all"][0])
    filt = np.any(g["a_vf"] < 1.0)
    out = np.zeros((B, len(KERNEL_ROWS), n_rec * tpp if rec_all else n_rec))
    row = {name: i for i, name in enumerate(KERNEL_ROWS)}
    i_d = np.zeros(B)
    i_q = np.zeros(B)
    w = np.zeros(B)
    th = ref[:, 0, 0] * N
    T_w, T_h = g["T_w0"].copy(), g["T_h0"].copy()
    z_d, z_q = np.zeros(B), np.zeros(B)
    th_hat, w_hat, w_f = th.copy(), np.zeros(B), np.zeros(B)
    i_ref = np.zeros(B)
    V_bus = g["V_s"].copy()
    p_el = np.zeros(B)
    for j in range(n_rec * tpp):
        th_m = np.where(enc, np.round(th / q_enc) * q_enc, th)
        a_t, b_t, _ = inverse_clarke(*inverse_park(i_d, i_q, p * th))
        a_m = g["g_a"] * a_t + g["off_a"] + g["sig_i"] * fast[:, 0, j]
        b_m = g["g_b"] * b_t + g["off_b"] + g["sig_i"] * fast[:, 1, j]
        id_m, iq_m = park(*clarke(a_m, b_m, -a_m - b_m), p * th_m)
        e = th_m - th_hat
        th_hat = th_hat + T * (w_hat + g["k1_pll"] * e)
        w_hat = w_hat + T * g["k2_pll"] * e
        # the speed the drive reports (exactly the PLL's where the filter is off, as in the C kernel)
        w_f = np.where(g["a_vf"] < 1.0, w_f + g["a_vf"] * (w_hat - w_f), w_hat) if filt else w_hat
        step = j % tpp == 0
        rec = step or rec_all
        if step:
            k = j // tpp
            th_r, w_r, a_r = ref[:, 0, k], ref[:, 1, k], ref[:, 2, k]
            tau = (g["kp_out"] * (th_r - th_m / g["N_nom"]) + g["kd_out"] * (w_r - w_f / g["N_nom"])
                   + g["J_ff_out"] * a_r + g["ff_const"] + g["ff_g"] * np.sin(th_r + g["ff_gph"])
                   + g["ff_c"] * np.tanh(w_r / 0.05))
            i_ref = np.clip(tau / (g["N_nom"] * g["K_nom"]), -g["I_lim"], g["I_lim"])
        V_lim = g["m_lim"] * V_bus
        e_d, e_q = -id_m, i_ref - iq_m
        u_d = g["Kp_i"] * e_d + z_d - g["dec"] * p * w_hat * g["L_nom"] * iq_m
        u_q = g["Kp_i"] * e_q + z_q + g["dec"] * (p * w_hat * g["L_nom"] * id_m + g["K_nom"] * w_hat)
        mag = np.hypot(u_d, u_q)
        sc = np.where(mag > V_lim, V_lim / np.maximum(mag, 1e-12), 1.0)
        vd1 = np.clip(u_d, -V_lim, V_lim)                                     # d first
        vq1 = np.clip(u_q, -np.sqrt(np.maximum(V_lim ** 2 - vd1 ** 2, 0.0)), np.sqrt(np.maximum(V_lim ** 2 - vd1 ** 2, 0.0)))
        vq2 = np.clip(u_q, -V_lim, V_lim)                                     # q first
        vd2 = np.clip(u_d, -np.sqrt(np.maximum(V_lim ** 2 - vq2 ** 2, 0.0)), np.sqrt(np.maximum(V_lim ** 2 - vq2 ** 2, 0.0)))
        vlm = g["vlm"]
        v_d = np.where(vlm == 1.0, vd1, np.where(vlm == 2.0, vd2, u_d * sc))
        v_q = np.where(vlm == 1.0, vq1, np.where(vlm == 2.0, vq2, u_q * sc))
        clamp = g["aw"] == 1.0
        hold_d = clamp & (v_d != u_d) & (e_d * u_d > 0)
        hold_q = clamp & (v_q != u_q) & (e_q * u_q > 0)
        back = g["aw"] == 0.0                 # back-calculation; "none" (2) integrates regardless
        z_d = z_d + np.where(hold_d, 0.0, g["Ki_i"] * T * e_d) + np.where(back, v_d - u_d, 0.0)
        z_q = z_q + np.where(hold_q, 0.0, g["Ki_i"] * T * e_q) + np.where(back, v_q - u_q, 0.0)
        va, vb = inverse_park(v_d, v_q, p * th_m + p * w_hat * 0.5 * T)
        R = g["R_ref"] * (1.0 + g["alpha"] * (T_w - g["T_ref"]))
        K = g["K0"] * (1.0 + g["beta"] * (T_h - g["T_ref"])) if has_beta else g["K0"]
        if rec:
            fr, cog, ld = torque_terms(w, th)
            kr = j if rec_all else k
            vals = dict(time=j * T, current_command=i_ref, current=iq_m, position=th_m, velocity=w_f,
                        bus_voltage=V_bus, voltage_q=v_q, i_q=i_q, i_d=i_d, omega=w, theta=th, T_w=T_w, T_h=T_h,
                        tau_friction=fr, tau_cogging=cog, tau_load=ld, tau_em=K * i_q, v_d=v_d,
                        R=R, K=K, p_elec=p_el, p_joule=R * (i_d * i_d + i_q * i_q), v_limit=V_lim,
                        current_d=id_m, velocity_estimate=w_hat)
            for name, val in vals.items():
                out[:, row[name], kr] = val
        for _ in range(sub):
            d2 = 0.5 * h
            k1 = deriv(i_d, i_q, w, th, va, vb, R, K)
            w2 = w + d2 * k1[2]
            k2 = deriv(i_d + d2 * k1[0], i_q + d2 * k1[1], w2, th + d2 * w, va, vb, R, K)
            w3 = w + d2 * k2[2]
            k3 = deriv(i_d + d2 * k2[0], i_q + d2 * k2[1], w3, th + d2 * w2, va, vb, R, K)
            w4 = w + h * k3[2]
            k4 = deriv(i_d + h * k3[0], i_q + h * k3[1], w4, th + h * w3, va, vb, R, K)
            h6 = h / 6.0
            i_d = i_d + h6 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            i_q = i_q + h6 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            th = th + h6 * (w + 2.0 * w2 + 2.0 * w3 + w4)
            w = w + h6 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
        vd_r, vq_r = park(va, vb, p * th)
        p_el = vd_r * i_d + vq_r * i_q
        P_j = R * (i_d * i_d + i_q * i_q)
        q_wh = (T_w - T_h) / g["R_wh"]
        T_w = T_w + T * (P_j - q_wh) / g["C_w"]
        T_h = T_h + T * (q_wh - (T_h - g["T_amb"]) / g["R_ha"]) / g["C_h"]
        V_s = g["V_s"]
        V_bus = 0.5 * (V_s + np.sqrt(np.maximum(V_s * V_s - 4.0 * g["R_s"] * p_el, 0.25 * V_s * V_s)))
    return out


#: rows the kernels write, per recording sample
KERNEL_ROWS = ("time", "current_command", "current", "position", "velocity", "bus_voltage", "voltage_q",
               "i_q", "i_d", "omega", "theta", "T_w", "T_h", "tau_friction", "tau_cogging", "tau_load", "tau_em",
               "v_d", "R", "K", "p_elec", "p_joule", "v_limit", "current_d", "velocity_estimate")


# ---- C kernel: same equations, scalar loop, compiled on first use (gcc/cc), called through ctypes -----

_C_LIB = None


def _c_library():
    """Compile ``truth_kernel.c`` (with the index macros generated from the Python lists) once per source
    hash into the temp directory; ``None`` when no C compiler works (the numpy kernel is used then)."""
    global _C_LIB
    if _C_LIB is not None:
        return _C_LIB or None
    import ctypes
    import hashlib
    import os
    import shutil
    import subprocess
    import tempfile
    from pathlib import Path

    src = Path(__file__).with_name("truth_kernel.c").read_text()
    header = "".join(f"#define I_{n} {i}\n" for i, n in enumerate(PARAM_NAMES))
    header += "".join(f"#define R_{n} {i}\n" for i, n in enumerate(KERNEL_ROWS))
    code = header + src
    digest = hashlib.sha256(code.encode()).hexdigest()[:16]
    lib_path = Path(tempfile.gettempdir()) / f"bldc_truth_kernel_{digest}.so"
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    try:
        if not lib_path.exists():
            if compiler is None:
                raise OSError("no C compiler")
            c_file = lib_path.with_suffix(f".{os.getpid()}.c")
            c_file.write_text(code)
            tmp = lib_path.with_suffix(f".{os.getpid()}.so")
            subprocess.run([compiler, "-O2", "-shared", "-fPIC", "-o", str(tmp), str(c_file), "-lm"],
                           check=True, capture_output=True, text=True)
            os.replace(tmp, lib_path)
            c_file.unlink(missing_ok=True)
        lib = ctypes.CDLL(str(lib_path))
        dp = ctypes.POINTER(ctypes.c_double)
        lib.truth_kernel.argtypes = [dp, dp, dp, ctypes.c_long, dp]
        lib.truth_kernel.restype = ctypes.c_int
        _C_LIB = lib
    except (OSError, subprocess.CalledProcessError) as exc:  # no compiler, or it failed: numpy fallback
        import warnings

        detail = getattr(exc, "stderr", "") or str(exc)
        warnings.warn(f"truth C kernel unavailable ({detail.strip()[:200]}); using the slow numpy kernel")
        _C_LIB = False
        return None
    return _C_LIB


def _kernel_c(par: np.ndarray, ref: np.ndarray, fast: np.ndarray, n_rec: int) -> np.ndarray:
    """One recording: ``n_rec`` joint-controller steps → (len(KERNEL_ROWS), samples)."""
    import ctypes

    lib = _c_library()
    dp = ctypes.POINTER(ctypes.c_double)
    par = np.ascontiguousarray(par, dtype=float)
    ref = np.ascontiguousarray(ref, dtype=float)
    fast = np.ascontiguousarray(fast, dtype=float)
    n_out = n_rec * int(par[PARAM_NAMES.index("ticks_per_pos")]) if par[PARAM_NAMES.index("rec_all")] else n_rec
    out = np.zeros((len(KERNEL_ROWS), n_out))
    lib.truth_kernel(par.ctypes.data_as(dp), ref.ctypes.data_as(dp), fast.ctypes.data_as(dp), n_rec,
                     out.ctypes.data_as(dp))
    return out


def _finish(spec: TruthSpec, raw: np.ndarray, slow: np.ndarray) -> dict[str, np.ndarray]:
    """Kernel rows → recording columns (slow sensors: noise and quantisation added here) + ``true_*``."""
    r = {name: raw[i] for i, name in enumerate(KERNEL_ROWS)}
    S = spec.sensors
    on = S.enabled

    def q(x, quantum):
        return np.round(x / quantum) * quantum if on else x

    rec = {
        "time": r["time"],
        "current_command": r["current_command"],
        "current": r["current"],
        "position": r["position"],
        "velocity": r["velocity"],
        "bus_voltage": q(r["bus_voltage"] + (S.bus_noise * slow[0] if on else 0.0), S.bus_quantum),
        "voltage_q": r["voltage_q"],
        "winding_temperature": q(r["T_w"] + (S.temperature_noise * slow[1] if on else 0.0), S.winding_quantum),
        "housing_temperature": q(r["T_h"] + (S.temperature_noise * slow[2] if on else 0.0), S.housing_quantum),
    }
    for name in KERNEL_ROWS[7:]:
        rec[f"true_{name}"] = r[name]
    rec["true_bus_voltage"] = r["bus_voltage"]
    return rec


def simulate(specs: list[TruthSpec], refs: list[Reference], *, backend: str = "auto", workers: int = 2,
             progress: Callable[[int, int], None] | None = None,
             post: Callable[[int, dict], dict] | None = None,
             timings: list | None = None) -> list[dict[str, np.ndarray]]:
    """Simulate each (spec, reference) pair; return per recording a dict of columns (``COLUMNS``) and noise-free
    internal signals ``true_*`` (motor side, SI), one sample per joint-controller step (every current-loop tick
    with ``drive.record_ticks``).

    ``backend``: ``"c"`` (compiled kernel, recordings spread over ``workers`` threads), ``"numpy"``
    (reference kernel, all recordings as one batch; slow) or ``"auto"`` (C when a compiler works).
    ``progress(done, total)`` is called after each recording (C backend). ``post(i, recording)``, when given,
    transforms recording ``i`` as soon as it is simulated (e.g. a logger's decimation: a 30-minute run at 1 kHz
    need not stay in memory until the whole batch is done). ``timings``, when given (a list as long as
    ``specs``), receives each recording's simulation time [s] (C backend: per recording, in its worker thread;
    numpy: the batch time shared equally)."""
    if len(specs) != len(refs) or not specs:
        raise ValueError("simulate: need one reference per spec")
    for s, r in zip(specs, refs):
        if abs(r.rate - s.drive.position_rate) > 1e-9:
            raise ValueError("simulate: reference rate must equal drive.position_rate")
    if backend == "auto":
        backend = "c" if _c_library() is not None else "numpy"
    if backend == "c" and _c_library() is None:
        raise RuntimeError("C kernel unavailable")

    import time

    def one(i):
        t0 = time.perf_counter()
        spec, ref = specs[i], refs[i]
        slow, fast = _noise(spec, ref.n)
        raw = _kernel_c(param_vector(spec), np.stack([ref.theta_out, ref.omega_out, ref.alpha_out]), fast, ref.n)
        rec = _finish(spec, raw, slow)
        if timings is not None:
            timings[i] = time.perf_counter() - t0
        return post(i, rec) if post is not None else rec

    if backend == "c":
        from concurrent.futures import ThreadPoolExecutor

        results: list = [None] * len(specs)
        order = sorted(range(len(specs)), key=lambda i: -refs[i].n)  # longest first
        with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
            for done, (i, res) in enumerate(zip(order, pool.map(one, order)), start=1):
                results[i] = res
                if progress is not None:
                    progress(done, len(specs))
        return results
    if backend != "numpy":
        raise ValueError(f"backend: expected auto, c or numpy, got {backend!r}")
    if len({r.n for r in refs}) != 1 or len({s.drive.current_loop_rate for s in specs}) != 1 \
            or len({s.plant_substeps for s in specs}) != 1 or len({s.drive.record_ticks for s in specs}) != 1:
        raise ValueError("numpy backend: a batch must share reference length, loop rate, sub-steps and "
                         "record_ticks")
    n = refs[0].n
    t0 = time.perf_counter()
    noises = [_noise(s, n) for s in specs]
    raw = _kernel_numpy(np.stack([param_vector(s) for s in specs]),
                        np.stack([np.stack([r.theta_out, r.omega_out, r.alpha_out]) for r in refs]),
                        np.stack([f for _, f in noises]), n)
    recs = [_finish(s, raw[i], noises[i][0]) for i, s in enumerate(specs)]
    if timings is not None:
        timings[:] = [(time.perf_counter() - t0) / len(specs)] * len(specs)
    return [post(i, r) for i, r in enumerate(recs)] if post is not None else recs
