"""The recordings of the FRESH concealed set (:mod:`.fresh_cases`): a plant and a drive written here, from the
textbook equations, WITHOUT any of bldc_actuator's code (no kernel, model, effects, frames: this module imports
numpy, scipy and math only; ``test/test_concealed_fresh.py`` checks it).

Plant (continuous time, integrated by a fixed-step classical Runge-Kutta (RK4) with ``substeps`` steps per drive
period, the inverter's voltage held per period; ``test/test_concealed_fresh.py`` checks it against
``scipy.integrate.solve_ivp``):

* a surface PMSM in the power-invariant rotor frame (``_q``): ``v_d = R i_d + L di_d/dt - ω_e L i_q``,
  ``v_q = R i_q + L di_q/dt + ω_e L i_d + K(i, T) ω_m``, torque ``K(i, T) i_q``; ``K(i, T) = K_0 (1 - a_sat
  (|i|/i_sat)^1.5) (1 + β (T_magnet - 25 °C))`` (a power-law saturation, not a linear one), ``R(T) = R_0 (1 + α
  (T_w - 25 °C))``; the inverter holds the stationary-frame voltage vector of the last command during a period
  (the rotor turns under it), a one-period computation delay, the drive advancing its angle by ``advance`` periods;
* or a voltage-mode motor without a current loop (a brushed / coreless DC motor behind an H-bridge, or a PMSM
  driven by a q-voltage): ``i = (v - K ω)/R`` (electrical time constant far below the period);
* mechanics on the motor side behind an ideal gear N (rigid) or, for the backlash probe, a second mass behind a
  spring with a dead zone: Coulomb ``τ_c tanh(ω/ε)``, viscous, a gear friction that grows with the transmitted
  torque ``c(|τ_m|) |τ_m| tanh(ω/ε)`` with ``c`` rising linearly from ``c_0`` to ``c_1`` up to ``τ_ref``, a
  pendulum ``m g l sin θ_out``, a constant output force (a linear axis: output in metres through a screw lead);
* a two-node thermal network (winding, housing) with the magnet at the housing's temperature.

Drive (discrete, per period ``1/f_c``): d/q PI current control tuned by the bandwidth with the NOMINAL R, L,
back-EMF and cross-coupling feed-forward with the nominal K, L; voltage limited on the SVPWM circle ``V_bus/√2``
proportionally; anti-windup by back-calculation or by conditional integration (clamping); outer loops at
``f_outer``: current steps, a PI speed loop, a P position + PI speed loop, or a voltage command; the speed the
drive uses and logs is its own estimate from the quantized encoder (backward difference, first-order filtered,
or a type-2 PLL); currents through an ADC (noise, then quantization to its LSB); the log decimates to its rate,
optionally with timestamp jitter (the host stamps the sample when it arrives).
"""

from __future__ import annotations

import math
import time
from typing import Callable

import numpy as np

LIBRARIES: tuple[str, ...] = ()
SQRT2 = math.sqrt(2.0)


# ------------------------------------------------------------------------------------------- excitation

def multisine(duration: float, seed: int, amps, freqs, *, ramp: float = 0.3) -> Callable[[float], float]:
    """A seeded multisine (tones near ``freqs`` with random phases) faded in over ``ramp`` seconds."""
    rng = np.random.default_rng(seed)
    f = np.asarray(freqs, float) * rng.uniform(0.85, 1.15, len(freqs))
    a = np.asarray(amps, float)
    ph = rng.uniform(0, 2 * np.pi, len(freqs))

    def r(t: float) -> float:
        return min(1.0, t / ramp) * float(np.sum(a * np.sin(2 * np.pi * f * t + ph)))
    return r


def steps(duration: float, seed: int, levels, dwell: float) -> Callable[[float], float]:
    """A seeded staircase through ``levels`` (each level and its negative, shuffled), ``dwell`` seconds each."""
    rng = np.random.default_rng(seed)
    seq = []
    while len(seq) * dwell < duration + dwell:
        lv = list(levels) + [-x for x in levels]
        rng.shuffle(lv)
        seq += lv
    seq = np.asarray(seq, float)

    def r(t: float) -> float:
        return float(seq[min(len(seq) - 1, int(t / dwell))])
    return r


def reference(spec: dict, duration: float, seed: int) -> Callable[[float], float]:
    e = spec["excitation"]
    if e["kind"] == "steps":
        return steps(duration, seed, e["levels"], e["dwell"])
    base = multisine(duration, seed, e["amps"], e["freqs"])
    off = float(e.get("offset", 0.0))
    if e.get("triangle"):           # a slow triangle through zero for the first quarter (low-speed friction)
        amp, t1 = float(e["triangle"]), 0.25 * duration

        def r(t: float) -> float:
            if t < t1:
                x = (t / t1) * 2.0                  # two periods of a triangle starting at zero
                return off + amp * (1.0 - 4.0 * abs(((x + 0.25) % 1.0) - 0.5))
            return off + base(t - t1)
        return r
    return (lambda t: off + base(t)) if off else base


# ------------------------------------------------------------------------------------------- the plant

class Plant:
    """The continuous plant of one case; ``deriv(x, t, u)`` with the state ``x`` = [i_d, i_q, ω_m, θ_m, T_w, T_h,
    ω_o, θ_o] (the last two only with a compliant transmission) and ``u`` the held input."""

    def __init__(self, spec: dict):
        m, g, ld = spec["motor"], spec.get("gear", {}), spec.get("load", {})
        self.mode = spec["drive"].get("mode", "current")           # current | voltage
        self.R0, self.L, self.K0, self.p = m["R"], m["L"], m["K"], m["p"]
        self.Jm, self.bm, self.tc = m["J"], m.get("b", 0.0), m.get("tau_c", 0.0)
        self.eps = m.get("eps", 0.05)
        self.a_sat, self.i_sat = m.get("a_sat", 0.0), m.get("i_sat", 1.0)
        self.alpha, self.beta = m.get("alpha_cu", 0.0), m.get("beta_magnet", 0.0)
        th = spec.get("thermal") or {}
        self.thermal = bool(th)
        self.Cw, self.Ch = th.get("C_w", 1.0), th.get("C_h", 1.0)
        self.Rwh, self.Rha, self.Ta = th.get("R_wh", 1.0), th.get("R_ha", 1.0), th.get("T_amb", 25.0)
        self.N = g.get("ratio", 1.0)
        self.gf0, self.gf1, self.gf_ref = g.get("c0", 0.0), g.get("c1", 0.0), g.get("tau_ref", 1.0)
        self.k_t, self.d_t, self.gap = g.get("stiffness", 0.0), g.get("damping", 0.0), g.get("backlash", 0.0)
        self.compliant = self.k_t > 0.0
        # output side (per output unit: N·m or, for a linear axis, N with N = 2π/lead rad/m)
        self.Jo, self.bo, self.tco = ld.get("J", 0.0), ld.get("b", 0.0), ld.get("tau_c", 0.0)
        self.eps_o = ld.get("eps", self.eps / self.N)
        self.mgl, self.f_const = ld.get("mgl", 0.0), ld.get("constant", 0.0)
        self.J_rigid = self.Jm + self.Jo / self.N ** 2

    def K(self, i_abs: float, T_mag: float) -> float:
        k = self.K0
        if self.a_sat:
            k *= 1.0 - self.a_sat * (i_abs / self.i_sat) ** 1.5
        if self.beta:
            k *= 1.0 + self.beta * (T_mag - 25.0)
        return k

    def R(self, T_w: float) -> float:
        return self.R0 * (1.0 + self.alpha * (T_w - 25.0)) if self.alpha else self.R0

    def output_load(self, w_o: float, th_o: float) -> float:
        """Output-side load torque (force) opposing positive motion."""
        return (self.bo * w_o + self.tco * math.tanh(w_o / self.eps_o) + self.mgl * math.sin(th_o)
                - self.f_const)

    def currents(self, x, u):
        """(i_d, i_q, K) of the state; in voltage mode the algebraic current."""
        T_w, T_h = x[4], x[5]
        if self.mode == "voltage":
            v = u[1]
            R = self.R(T_w)
            iq = (v - self.K(0.0, T_h) * x[2]) / R
            if self.a_sat:        # a fixed point in K(i) (two passes suffice: a_sat small)
                for _ in range(2):
                    iq = (v - self.K(abs(iq), T_h) * x[2]) / R
            return 0.0, iq, self.K(abs(iq), T_h)
        i_abs = math.hypot(x[0], x[1])
        return x[0], x[1], self.K(i_abs, T_h)

    def deriv(self, x, t, u):
        """``u`` = (v_alpha, v_beta) held (current mode: the stationary-frame vector) or (0, v) (voltage mode)."""
        i_d, i_q, w, th, T_w, T_h = x[0], x[1], x[2], x[3], x[4], x[5]
        i_d, i_q, K = self.currents(x, u)
        R = self.R(T_w)
        dx = [0.0] * len(x)
        if self.mode == "current":
            the = self.p * th
            c, s = math.cos(the), math.sin(the)
            v_d = c * u[0] + s * u[1]
            v_q = -s * u[0] + c * u[1]
            we = self.p * w
            dx[0] = (v_d - R * i_d + we * self.L * i_q) / self.L
            dx[1] = (v_q - R * i_q - we * self.L * i_d - K * w) / self.L
        tau_e = K * i_q
        tau_m = tau_e - self.bm * w - self.tc * math.tanh(w / self.eps)
        if self.gf1 or self.gf0:
            a = abs(tau_e)
            c_g = self.gf0 + (self.gf1 - self.gf0) * min(1.0, a / self.gf_ref)
            tau_m -= c_g * a * math.tanh(w / self.eps)
        if self.compliant:
            w_o, th_o = x[6], x[7]
            delta = th / self.N - th_o
            h = 0.5 * self.gap
            dz = delta - h if delta > h else (delta + h if delta < -h else 0.0)
            tau_s = self.k_t * dz + (self.d_t * (w / self.N - w_o) if dz != 0.0 else 0.0)
            dx[2] = (tau_m - tau_s / self.N) / self.Jm
            dx[6] = (tau_s - self.output_load(w_o, th_o)) / self.Jo
            dx[7] = w_o
        else:
            dx[2] = (tau_m - self.output_load(w / self.N, th / self.N) / self.N) / self.J_rigid
        dx[3] = w
        if self.thermal:
            p_cu = R * (i_d * i_d + i_q * i_q)
            q_wh = (T_w - T_h) / self.Rwh
            dx[4] = (p_cu - q_wh) / self.Cw
            dx[5] = (q_wh - (T_h - self.Ta) / self.Rha) / self.Ch
        return dx


def rk4(f, x, t, h, u):
    k1 = f(x, t, u)
    x2 = [a + 0.5 * h * b for a, b in zip(x, k1)]
    k2 = f(x2, t + 0.5 * h, u)
    x3 = [a + 0.5 * h * b for a, b in zip(x, k2)]
    k3 = f(x3, t + 0.5 * h, u)
    x4 = [a + h * b for a, b in zip(x, k3)]
    k4 = f(x4, t + h, u)
    return [a + h / 6.0 * (b + 2 * c + 2 * d + e) for a, b, c, d, e in zip(x, k1, k2, k3, k4)]


# ------------------------------------------------------------------------------------------- the drive's sensors

class VelocityEstimator:
    """The drive's speed from its quantized encoder angle: ``diff`` (backward difference), ``lpf`` (the difference
    through a first-order low pass at ``f_hz``) or ``pll`` (a type-2 tracking loop, natural frequency ``f_hz``,
    ζ = 1)."""

    def __init__(self, kind: str, T: float, f_hz: float = 0.0):
        self.kind, self.T = kind, T
        self.prev = None
        self.w = 0.0
        self.th = 0.0
        wn = 2 * math.pi * max(f_hz, 1e-9)
        self.a = 1.0 - math.exp(-wn * T)
        self.kp, self.ki = 2.0 * wn, wn * wn

    def update(self, th_meas: float) -> float:
        if self.prev is None:
            self.prev, self.th = th_meas, th_meas
            return 0.0
        if self.kind == "pll":
            e = th_meas - self.th
            self.w += self.ki * e * self.T
            self.th += (self.w + self.kp * e) * self.T
            return self.w
        d = (th_meas - self.prev) / self.T
        self.prev = th_meas
        if self.kind == "diff":
            self.w = d
        else:
            self.w += self.a * (d - self.w)
        return self.w


def quantize(x: float, lsb: float) -> float:
    return lsb * round(x / lsb) if lsb > 0 else x


# ------------------------------------------------------------------------------------------- one run

def simulate(spec: dict, duration: float, seed: int) -> dict:
    """One run of ``spec`` for ``duration`` s with the excitation and sensor-noise seed ``seed``; every drive
    period's samples (true and measured) as arrays."""
    pl = Plant(spec)
    d = spec["drive"]
    rng = np.random.default_rng(seed + 7)
    T = 1.0 / d["f_c"]
    n_out = max(1, int(round(d["f_c"] / d.get("f_outer", 1000.0))))
    sub = int(d.get("substeps", 2))
    h = T / sub
    n = int(round(duration / T))
    nom = d["nominal"]                               # what the drive believes: R, L, K, J
    wb = 2 * math.pi * d.get("bandwidth_hz", 500.0)
    kp_i, ki_i = wb * nom["L"], wb * nom["R"]
    aw = d.get("anti_windup", "back_calculation")
    v_bus0 = d["v_bus"]
    r_src = d.get("source_resistance", 0.0)           # a battery's internal resistance (supply sags)
    i_max = d["i_max"]
    ref = reference(spec, duration, seed)
    outer = d["outer"]                                # current | speed | position | voltage | position_voltage
    enc_lsb = 2 * math.pi / d["encoder_counts"] if d.get("encoder_counts") else 0.0
    enc_side_N = pl.N if d.get("encoder_side", "motor") == "output" else 1.0
    est = VelocityEstimator(d.get("velocity_estimator", "diff"), T * n_out, d.get("estimator_hz", 0.0))
    adc_lsb, adc_sd = d.get("adc_lsb", 0.0), d.get("adc_noise", 0.0)
    kw, kiw = d.get("speed_kp", 0.0), d.get("speed_ki", 0.0)
    kpos = d.get("position_kp", 0.0)
    advance = d.get("advance", 1.5)                   # periods the drive advances its output angle by
    dec = d.get("decoupling", True)
    th0 = spec.get("thermal", {}).get("T_amb", 25.0)
    x = [0.0, 0.0, 0.0, float(spec.get("theta0", 0.0)) * pl.N, th0, th0]
    if pl.compliant:
        x += [0.0, float(spec.get("theta0", 0.0))]
    cols = ("t", "i_d", "i_q", "i_d_meas", "i_q_meas", "i_q_ref", "v_d", "v_q", "w", "theta", "theta_enc", "w_est",
            "T_w", "T_h", "v_bus", "tau_e", "theta_o", "w_o", "ref", "duty")
    out = {c: np.zeros(n) for c in cols}
    I_d = I_q = 0.0
    I_w = 0.0
    v_cmd_d = v_cmd_q = 0.0
    u = u_next = (0.0, 0.0)
    iq_ref = 0.0
    w_est = 0.0
    duty = 0.0
    v_bus = v_bus0
    for k in range(n):
        t = k * T
        # --- sample (start of period k): currents through the ADC, encoder angle
        i_d, i_q, K = pl.currents(x, u)
        i_dm = quantize(i_d + adc_sd * rng.standard_normal(), adc_lsb)
        i_qm = quantize(i_q + adc_sd * rng.standard_normal(), adc_lsb)
        v_bus = v_bus0 - r_src * abs(i_q) if pl.mode == "voltage" else v_bus0
        if pl.compliant and d.get("encoder_side") == "output":
            th_enc = quantize(x[7], enc_lsb)
        else:
            th_enc = quantize(x[3] / enc_side_N, enc_lsb)
        th_mot = th_enc * enc_side_N                  # the drive's motor-side angle from its encoder
        th_out = th_mot / pl.N
        th_comm = quantize(x[3], 2 * math.pi / 4096)   # the commutation sensor on the rotor (12 bit)
        # --- outer loop
        if k % n_out == 0:
            w_est = est.update(th_mot)
            r = ref(t)
            if outer == "current":
                iq_ref = r
            elif outer in ("speed", "position"):
                w_ref = r if outer == "speed" else kpos * (r - th_out) * pl.N
                e_w = w_ref - w_est
                u_w = kw * e_w + I_w
                iq_ref = max(-i_max, min(i_max, u_w))
                if iq_ref == u_w or (e_w * u_w < 0):          # clamping anti-windup of the speed loop
                    I_w += kiw * e_w * T * n_out
            elif outer == "voltage":
                duty = max(-1.0, min(1.0, r))
            elif outer == "position_voltage":               # a hobby servo: P-D on its potentiometer, duty out
                e = r - th_out
                duty = max(-1.0, min(1.0, kpos * e - d.get("position_kd", 0.0) * w_est / pl.N))
                if abs(e) < d.get("deadband", 0.0):
                    duty = 0.0
        # --- current loop (computed now, applied next period: the inverter holds the previous command)
        if pl.mode == "current":
            v_lim = v_bus / SQRT2
            w_m = w_est
            e_d, e_q = 0.0 - i_dm, iq_ref - i_qm
            ud = kp_i * e_d + I_d
            uq = kp_i * e_q + I_q
            if dec:
                we = pl.p * w_m
                ud -= we * nom["L"] * i_qm
                uq += we * nom["L"] * i_dm + nom["K"] * w_m
            mag = math.hypot(ud, uq)
            sc = min(1.0, v_lim / mag) if mag > 0 else 1.0
            vd, vq = ud * sc, uq * sc
            if aw == "back_calculation":
                # tracking time T_t = K_p/K_i (Astrom & Hagglund): dI/dt = K_i e + (v_limited - v_wanted)/T_t
                I_d += T * (ki_i * e_d + (vd - ud) * (ki_i / kp_i))
                I_q += T * (ki_i * e_q + (vq - uq) * (ki_i / kp_i))
            elif aw == "clamping":                      # conditional integration: freeze when saturated and pushing
                if sc >= 1.0 or e_d * ud < 0:
                    I_d += ki_i * e_d * T
                if sc >= 1.0 or e_q * uq < 0:
                    I_q += ki_i * e_q * T
            else:
                I_d += ki_i * e_d * T
                I_q += ki_i * e_q * T
            # one period of computation delay: the inverter applies, during THIS period, the stationary-frame vector
            # computed at the previous sample (at the angle the drive predicted for the middle of this period)
            u = u_next
            log_vd, log_vq = vd, vq          # logged with the sample it was computed from
            th_e_pred = pl.p * th_comm + pl.p * w_m * advance * T
            c, s = math.cos(th_e_pred), math.sin(th_e_pred)
            u_next = (c * vd - s * vq, s * vd + c * vq)
            v_cmd_d, v_cmd_q = vd, vq
        else:
            u = (0.0, duty * v_bus)
            log_vd, log_vq = 0.0, duty * v_bus
        row = out
        row["t"][k] = t
        row["i_d"][k], row["i_q"][k] = i_d, i_q
        row["i_d_meas"][k], row["i_q_meas"][k], row["i_q_ref"][k] = i_dm, i_qm, iq_ref
        row["v_d"][k], row["v_q"][k] = log_vd, log_vq
        row["w"][k], row["theta"][k], row["theta_enc"][k], row["w_est"][k] = x[2], x[3], th_enc, w_est
        row["T_w"][k], row["T_h"][k], row["v_bus"][k], row["tau_e"][k] = x[4], x[5], v_bus, K * i_q
        row["theta_o"][k] = x[7] if pl.compliant else x[3] / pl.N
        row["w_o"][k] = x[6] if pl.compliant else x[2] / pl.N
        row["ref"][k], row["duty"][k] = (duty if pl.mode == "voltage" else iq_ref), duty
        for j in range(sub):
            x = rk4(pl.deriv, x, t + j * h, h, u)
    return out


def job(args):
    """Worker entry: ``(name, spec, role, duration, seed)`` -> ``(name, role, run, seconds)``."""
    name, spec, role, duration, seed = args
    t0 = time.perf_counter()
    run = simulate(spec, duration, seed)
    return name, role, run, time.perf_counter() - t0


def to_log(run: dict, spec: dict, seed: int) -> dict:
    """The drive's log of a run: every ``f_c/rate``-th period, in the vendor's column names and units (the case's
    ``columns``: name -> (signal, scale)), timestamps with jitter where the logger has it."""
    lg = spec["log"]
    d = spec["drive"]
    rng = np.random.default_rng(seed)
    q = max(1, int(round(d["f_c"] / lg["rate"])))
    idx = np.arange(0, len(run["t"]), q)
    rec = {}
    t = run["t"][idx].copy()
    if lg.get("jitter_s"):
        t = t + np.abs(rng.normal(0.0, lg["jitter_s"], len(t)))
        t = np.maximum.accumulate(t + 1e-7 * np.arange(len(t)))     # the host's clock never runs back
    rec[lg.get("time_column", "time")] = t
    for col, (sig, scale) in lg["columns"].items():
        x = run[sig][idx] * scale
        sd = lg.get("noise", {}).get(col, 0.0)
        if sd:
            x = x + sd * rng.standard_normal(len(x))
        lsb = lg.get("lsb", {}).get(col, 0.0)
        if lsb:
            x = lsb * np.round(x / lsb)
        rec[col] = x
    return rec
