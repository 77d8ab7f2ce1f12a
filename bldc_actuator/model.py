"""The actuator: q-axis PMSM + field-oriented drive + gear + two-node thermal network.

Continuous-time plant (motor side, power-invariant d-q of the winding quantities, ``i = i_d + j i_q``)::

    L_q di/dt  = v - R(T_w) i - j p ω L_q i - j K(T_m) ω              [V]
    J dω/dt    = K(T_m) i_q - b ω - τ_f(ω) - τ_cog(θ) - τ_load(θ/N)/N   [N·m]
    dθ/dt      = ω                                                     [rad/s]
    C_w dT_w/dt = R(T_w)|i|² - (T_w - T_h)/R_wh                        [W]
    C_h dT_h/dt = (T_w - T_h)/R_wh - (T_h - T_a)/R_ha                  [W]

Drive: a discrete PI current controller (d and q, pole-zero cancelling gains, decoupling feed-forward,
back-calculation anti-windup) runs at ``drive.current_loop_rate``; its voltage, limited to the circle
the SVPWM inverter can make (:func:`frames.voltage_limit_q`), is held until the next tick.

Integration over each interval ``h`` between controller ticks (or shorter, when ``step(dt)`` asks):

* electrical: exact solution for a held voltage, with the cross-coupling speed frozen at the interval
  start and the back-EMF speed equal to the interval's mean speed ``w = (ω0 + ω1)/2``;
* mechanical: implicit midpoint with the electrical interval-mean torque ``K ī_q``; electrical and
  mechanical equations are affine in ``w`` and ``ī_q`` and are solved together exactly (no iteration),
  so the energy exchanged between the two domains is the same number on both sides;
* friction without a bristle state: stick/slip decided per interval (a zero crossing stops the rotor
  exactly; breakaway needs the static friction to be exceeded);
* thermal: exact exponential of the 2×2 network for the interval's exact mean Joule power.

So the energy ledger closes to round-off, and trajectories agree across step sizes.

One kernel (:func:`_advance`, :func:`_control_tick`) serves both :class:`Actuator` (Python floats, fast)
and :class:`BatchActuator` (numpy arrays over many actuators or parameter sets).
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, fields
from typing import Any, Sequence

import numpy as np

from . import effects, frames
from .params import ActuatorParams

TWO_PI = 2.0 * math.pi


# -- arithmetic back-ends (one kernel, two number types) ---------------------------------------------

class _ScalarOps:
    cexp = staticmethod(cmath.exp)
    exp = staticmethod(math.exp)
    sqrt = staticmethod(math.sqrt)

    @staticmethod
    def where(cond, a, b):
        return a if cond else b

    @staticmethod
    def sign(x):
        return (x > 0.0) - (x < 0.0)

    @staticmethod
    def clip(x, lo, hi):
        return lo if x < lo else hi if x > hi else x

    @staticmethod
    def either(a, b):
        return a or b

    @staticmethod
    def both(a, b):
        return a and b

    @staticmethod
    def negate(a):
        return not a

    all_true = any_true = staticmethod(bool)


class _ArrayOps:
    cexp = staticmethod(np.exp)
    exp = staticmethod(np.exp)
    sqrt = staticmethod(np.sqrt)
    where = staticmethod(np.where)
    sign = staticmethod(np.sign)
    clip = staticmethod(np.clip)
    either = staticmethod(np.logical_or)
    both = staticmethod(np.logical_and)
    negate = staticmethod(np.logical_not)
    all_true = staticmethod(np.all)
    any_true = staticmethod(np.any)


# -- compiled coefficients ----------------------------------------------------------------------------

class _Coeffs:
    """Parameters flattened into plain numbers (or arrays, for a batch) for the kernel."""

    def __init__(self, params: ActuatorParams | Sequence[ActuatorParams]):
        batch = not isinstance(params, ActuatorParams)
        plist = list(params) if batch else [params]
        col = (lambda f: np.array([f(p) for p in plist], dtype=float)) if batch else (lambda f: float(f(plist[0])))
        m = lambda name: col(lambda p: getattr(p.motor, name))  # noqa: E731
        self.batch = batch
        self.pole_pairs = m("pole_pairs")
        self.R_ref = m("phase_resistance")
        self.L = m("q_inductance")
        self.K_ref = m("torque_constant_q")
        self.J = m("rotor_inertia")
        self.b = m("viscous_damping")
        self.T_ref = m("reference_temperature")
        self.alpha = m("copper_temperature_coefficient") * m("resistance_temperature_enabled")
        self.beta = m("magnet_temperature_coefficient") * m("magnet_temperature_enabled")
        self.has_alpha = bool(np.any(self.alpha))
        self.has_beta = bool(np.any(self.beta))
        self.N = col(lambda p: p.gear.gear_ratio)
        d = lambda name: col(lambda p: getattr(p.drive, name))  # noqa: E731
        self.V_bus = d("bus_voltage")
        wind = [p.motor.winding for p in plist]
        self.V_max = (np.array([frames.voltage_limit_q(v, w) for v, w in zip(np.atleast_1d(self.V_bus), wind)])
                      if batch else frames.voltage_limit_q(self.V_bus, wind[0]))
        self.I_lim = d("current_limit")
        rates = {p.drive.current_loop_rate for p in plist}
        if len(rates) != 1:
            raise ValueError("drive.current_loop_rate must be the same for every actuator of a batch")
        self.tick_ns = int(round(1e9 / rates.pop()))
        self.T_c = self.tick_ns * 1e-9
        w_c = TWO_PI * d("current_loop_bandwidth")
        self.Kp = w_c * self.L
        self.Ki = w_c * self.R_ref
        self.decouple = d("decoupling_enabled")
        self.T_derate = d("derate_temperature")
        self.T_trip = d("trip_temperature")
        t = lambda name: col(lambda p: getattr(p.thermal, name))  # noqa: E731
        self.T_amb = t("ambient_temperature")
        self.R_wh = t("winding_to_housing_resistance")
        self.R_ha = t("housing_to_ambient_resistance")
        self.C_w = t("winding_heat_capacity")
        self.C_h = t("housing_heat_capacity")
        e = lambda name: col(lambda p: getattr(p.effects, name))  # noqa: E731
        self.tau_c = e("coulomb_friction")
        self.tau_asym = e("friction_asymmetry")
        self.tau_s = e("stribeck_friction")
        self.omega_s = e("stribeck_velocity")
        self.has_stribeck = bool(np.any(self.tau_s))
        self.has_friction = bool(np.any(self.tau_c) or np.any(self.tau_asym) or np.any(self.tau_s))
        self.cog_order = e("cogging_order")
        n_h = max(len(p.effects.cogging_cos) for p in plist)
        pad = lambda seq: list(seq) + [0.0] * (n_h - len(seq))  # noqa: E731
        self.cog_cos = [col(lambda p, k=k: pad(p.effects.cogging_cos)[k]) for k in range(n_h)]
        self.cog_sin = [col(lambda p, k=k: pad(p.effects.cogging_sin)[k]) for k in range(n_h)]
        if not np.any(self.cog_order):
            self.cog_cos, self.cog_sin = [], []
        ld = lambda name: col(lambda p: getattr(p.load, name))  # noqa: E731
        self.load0 = ld("load_torque")
        self.load_g = ld("gravity_torque")
        self.load_phi = ld("gravity_phase")
        self.load_k = ld("spring_stiffness")
        self.load_k0 = ld("spring_zero")
        self.has_position_load = bool(np.any(self.load_g) or np.any(self.load_k))
        self._thermal_cache: dict[int, tuple] = {}

    def thermal(self, h_ns: int):
        """Exact discretisation of the thermal network for an interval of ``h_ns`` (cached)."""
        hit = self._thermal_cache.get(h_ns)
        if hit is None:
            hit = _thermal_matrices(self.R_wh, self.R_ha, self.C_w, self.C_h, h_ns * 1e-9,
                                    _ArrayOps if self.batch else _ScalarOps)
            if len(self._thermal_cache) > 64:
                self._thermal_cache.clear()
            self._thermal_cache[h_ns] = hit
        return hit


def thermal_step_matrices(thermal, h: float):
    """Exact discretisation of the two-node thermal network (:class:`~bldc_actuator.params.ThermalParams`)
    over ``h`` seconds for constant Joule power P, with ``y`` = temperatures above ambient:
    ``y_w' = p11 y_w + p12 y_h + G1 P``, ``y_h' = p21 y_w + p22 y_h + G2 P``. Returns
    ``(p11, p12, p21, p22, G1, G2)``: the same matrices the simulator uses (floats or, for array
    parameters, arrays)."""
    ops = _ArrayOps if isinstance(thermal.winding_heat_capacity, np.ndarray) else _ScalarOps
    return _thermal_matrices(thermal.winding_to_housing_resistance, thermal.housing_to_ambient_resistance,
                             thermal.winding_heat_capacity, thermal.housing_heat_capacity, h, ops)[:6]


def _thermal_matrices(R_wh, R_ha, C_w, C_h, h, ops):
    """``y(h) = Φ y(0) + Γ P`` for ``dy/dt = A y + g P`` (y = temperatures above ambient), and
    ``∫y dt = A⁻¹ (y(h) - y(0) - g P h)``. Closed-form 2×2 exponential (Sylvester): the passive RC
    network has real, distinct, negative eigenvalues."""
    a11, a12 = -1.0 / (R_wh * C_w), 1.0 / (R_wh * C_w)
    a21, a22 = 1.0 / (R_wh * C_h), -(1.0 / R_wh + 1.0 / R_ha) / C_h
    tr, det = a11 + a22, a11 * a22 - a12 * a21
    disc = ops.sqrt(tr * tr / 4.0 - det)
    l1, l2 = tr / 2.0 + disc, tr / 2.0 - disc
    e1, e2 = ops.exp(l1 * h), ops.exp(l2 * h)
    dl = l1 - l2
    # Φ = (e1 (A - l2 I) - e2 (A - l1 I)) / (l1 - l2)
    p11 = (e1 * (a11 - l2) - e2 * (a11 - l1)) / dl
    p12 = (e1 - e2) * a12 / dl
    p21 = (e1 - e2) * a21 / dl
    p22 = (e1 * (a22 - l2) - e2 * (a22 - l1)) / dl
    # A^-1
    i11, i12, i21, i22 = a22 / det, -a12 / det, -a21 / det, a11 / det
    g1 = 1.0 / C_w
    # Γ = A^-1 (Φ - I) g
    q1, q2 = (p11 - 1.0) * g1, p21 * g1
    G1, G2 = i11 * q1 + i12 * q2, i21 * q1 + i22 * q2
    return p11, p12, p21, p22, G1, G2, i21, i22, g1


# -- state ---------------------------------------------------------------------------------------------

@dataclass
class ActuatorState:
    """Snapshot of the actuator. Motor side unless ``_out``; currents/voltages q-axis (power-invariant)."""

    t_ns: int = 0               #: simulation time [ns]
    i_d: float = 0.0            #: d-axis current [A]
    i_q: float = 0.0            #: q-axis current [A]
    omega: float = 0.0          #: rotor speed [rad/s]
    theta: float = 0.0          #: rotor angle [rad] (unwrapped)
    T_winding: float = 25.0     #: winding temperature [degC]
    T_housing: float = 25.0     #: housing temperature [degC]
    v_d: float = 0.0            #: applied d-axis voltage [V] (held since the last controller tick)
    v_q: float = 0.0            #: applied q-axis voltage [V]
    z_d: float = 0.0            #: PI integrator, d [V]
    z_q: float = 0.0            #: PI integrator, q [V]
    i_q_ref: float = 0.0        #: q-axis current reference after limits [A]
    tripped: bool = False       #: over-temperature trip (latched)

    @property
    def t(self) -> float:
        return self.t_ns * 1e-9


@dataclass
class EnergyLedger:
    """Cumulative energies [J] since t = 0 (stored ones are current values)."""

    electrical_in: float = 0.0      #: ∫ (v_d i_d + v_q i_q) dt: power from the inverter
    joule: float = 0.0              #: ∫ R |i|² dt
    magnetic: float = 0.0           #: ½ L |i|² now
    kinetic: float = 0.0            #: ½ J ω² now
    viscous: float = 0.0            #: ∫ b ω² dt
    friction: float = 0.0           #: ∫ τ_f ω dt
    load: float = 0.0               #: work done on the external load and cogging ∫ (τ_load/N + τ_cog) ω dt
    heat_to_ambient: float = 0.0    #: ∫ (T_h - T_a)/R_ha dt
    thermal: float = 0.0            #: C_w (T_w - T_w0) + C_h (T_h - T_h0)
    #: ∫ K ω(t) i_q dt (electrical side) minus the work of the interval-mean torque (mechanical side):
    #: the integrator's own energy error, O(h³) per interval. Reported, never subtracted in residual().
    discretization: float = 0.0

    def residual(self, initial: "EnergyLedger") -> float:
        """Electrical energy in minus everything it went to [J] (0 up to round-off)."""
        return (self.electrical_in - self.joule - (self.magnetic - initial.magnetic)
                - (self.kinetic - initial.kinetic) - self.viscous - self.friction - self.load)

    def thermal_residual(self) -> float:
        """Joule heat minus (heat stored + heat to ambient) [J]."""
        return self.joule - self.thermal - self.heat_to_ambient


class _S:
    """Mutable kernel state (floats for one actuator, arrays for a batch)."""

    __slots__ = ("t_ns", "i", "omega", "theta", "T_w", "T_h", "v", "z", "i_ref", "tripped", "cmd_q", "v_cmd",
                 "tau_ext_out", "acc", "e_disc", "e_in", "e_joule", "e_visc", "e_fric", "e_load", "e_amb", "h_left")


# -- the kernel ----------------------------------------------------------------------------------------

def _current_limit(c: _Coeffs, s: _S, ops):
    """Thermal protection: limit falls linearly from derate to trip temperature; trip latches."""
    s.tripped = ops.either(s.tripped, s.T_w >= c.T_trip)
    return _current_limit_readonly(c, s, ops)


def _control_tick(c: _Coeffs, s: _S, ops) -> None:
    """One execution of the discrete d/q PI current controller; sets the voltage held until the next.
    In voltage mode (``s.v_cmd`` not None) the PI is bypassed and the commanded voltage is applied."""
    if s.v_cmd is not None:
        mag = abs(s.v_cmd)
        s.v = s.v_cmd * ops.where(mag > c.V_max, c.V_max / ops.where(mag > 0.0, mag, 1.0), 1.0)
        s.i_ref = 0.0 * s.omega
        return
    lim = _current_limit(c, s, ops)
    s.i_ref = ops.clip(s.cmd_q, -lim, lim)
    err = 1j * s.i_ref - s.i                                   # i_d_ref = 0
    v_ff = ops.where(c.decouple, 1j * (c.pole_pairs * s.omega * c.L * s.i + c.K_ref * s.omega), 0.0)
    v_pi = c.Kp * err + s.z + v_ff
    mag = abs(v_pi)
    scale = ops.where(mag > c.V_max, c.V_max / ops.where(mag > 0.0, mag, 1.0), 1.0)
    s.v = v_pi * scale
    s.z = s.z + c.Ki * c.T_c * err + (s.v - v_pi)              # back-calculation anti-windup


def _advance(c: _Coeffs, s: _S, h_ns: int, ops) -> None:
    """Advance the plant by ``h_ns`` with the held voltage ``s.v``."""
    h = h_ns * 1e-9
    i0, w0, th0, v = s.i, s.omega, s.theta, s.v
    R = effects.resistance_at(c.R_ref, s.T_w, c.T_ref, c.alpha) if c.has_alpha else c.R_ref
    K = c.K_ref * effects.flux_factor(s.T_h, c.T_ref, c.beta) if c.has_beta else c.K_ref  # magnet at T_housing
    L, J = c.L, c.J
    # electrical: L di/dt = v - (R + j p w0 L) i - j K ω(t), with the speed ramping linearly over the
    # interval, ω(t) = w0 + r t, r = 2 (w - w0)/h (w = mean speed, found below). Exact solution:
    # i(t) = c0 + c1 t + (i0 - c0) e^{-a t}, c1 = -j K r/(L a), c0 = (v - j K w0)/(L a) - c1/a.
    # cross-coupling (does no work) at the predicted mid-interval speed, extrapolating the last acceleration
    Z = R + 1j * c.pole_pairs * (w0 + 0.5 * h * s.acc) * L
    a = Z / L
    ah = a * h
    E = ops.cexp(-ah)
    phi1 = (1.0 - E) / ah                        # (1/h) ∫ e^{-at} dt
    # mean current ī = c0 (1 - phi1) + c1 h/2 + i0 phi1, affine in w: split c0, c1 into parts
    c1_w = -2j * K / (h * Z)                     # c1 = c1_w (w - w0)
    c0_v = (v - 1j * K * w0) / Z
    c0_w = -c1_w / a                             # c0 = c0_v + c0_w (w - w0)
    m_w = c0_w * (1.0 - phi1) + c1_w * (0.5 * h)
    A = (c0_v * (1.0 - phi1) + i0 * phi1 - m_w * w0).imag   # mean i_q = A + B w
    B = m_w.imag
    # external torques at the motor side, at the predicted mid-interval angle
    if c.has_position_load:
        th_mid = th0 + 0.5 * h * w0
        tau_other = effects.position_load_torque_out(th_mid / c.N, c.load0 + s.tau_ext_out, c.load_g,
                                                     c.load_phi, c.load_k, c.load_k0) / c.N
    else:
        tau_other = (c.load0 + s.tau_ext_out) / c.N
    if c.cog_cos:
        tau_other = tau_other + effects.cogging_torque_mean(th0, h * w0, c.cog_order, c.cog_cos, c.cog_sin)
    # mechanical, implicit midpoint: J (w1 - w0)/h = K (A + B w) - b w - tau_other - tau_f, w = (w0 + w1)/2
    den = 2.0 * J / h + c.b - K * B
    num = 2.0 * J * w0 / h + K * A - tau_other
    if c.has_friction:
        w, tau_f = _friction(c, num, den, w0, h, ops)
    else:
        w = num / den
        tau_f = 0.0
    w1 = 2.0 * w - w0
    # electrical solution with that w
    c1 = c1_w * (w - w0)
    c0 = c0_v + c0_w * (w - w0)
    d = i0 - c0
    i1 = c0 + c1 * h + d * E
    i_mean = c0 * (1.0 - phi1) + c1 * (0.5 * h) + i0 * phi1
    # exact ∫|i|² dt and ∫ t i dt
    sigma2h = 2.0 * (R / L) * h
    phi2 = (1.0 - ops.exp(-sigma2h)) / sigma2h
    psi1 = (1.0 - E * (1.0 + ah)) / (ah * ah)   # (1/h²) ∫ t e^{-at} dt
    joule = R * h * (abs(c0) ** 2 + (c0.conjugate() * c1).real * h + abs(c1) ** 2 * h * h / 3.0
                     + 2.0 * (d * (c0.conjugate() * phi1 + c1.conjugate() * h * psi1)).real
                     + abs(d) ** 2 * phi2)
    int_t_iq = (c0 * (0.5 * h * h) + c1 * (h ** 3 / 3.0) + d * (h * h) * psi1).imag
    conv_el = K * (w0 * i_mean.imag * h + (2.0 * (w - w0) / h) * int_t_iq)   # ∫ K ω(t) i_q dt
    conv_mech = K * i_mean.imag * w * h                                        # work of the mean torque
    dth = w * h
    # thermal: exact for the interval-mean Joule power
    p11, p12, p21, p22, G1, G2, i21, i22, g1 = c._thermal_cache.get(h_ns) or c.thermal(h_ns)
    P = joule / h
    y1, y2 = s.T_w - c.T_amb, s.T_h - c.T_amb
    n1 = p11 * y1 + p12 * y2 + G1 * P
    n2 = p21 * y1 + p22 * y2 + G2 * P
    int_y2 = i21 * (n1 - y1 - g1 * P * h) + i22 * (n2 - y2)
    # ledger
    s.e_in = s.e_in + (v.conjugate() * i_mean).real * h
    s.e_joule = s.e_joule + joule
    s.e_visc = s.e_visc + c.b * w * w * h
    s.e_fric = s.e_fric + tau_f * dth
    s.e_load = s.e_load + tau_other * dth
    s.e_amb = s.e_amb + int_y2 / c.R_ha
    s.e_disc = s.e_disc + (conv_el - conv_mech)
    # commit
    s.acc = (w1 - w0) / h
    s.i, s.omega, s.theta = i1, w1, th0 + dth
    s.T_w, s.T_h = n1 + c.T_amb, n2 + c.T_amb
    s.t_ns = s.t_ns + h_ns


def _friction(c: _Coeffs, num, den, w0, h, ops):
    """Mean speed ``w`` and friction torque ``τ_f`` (constant over the interval) from the mechanical
    balance ``den·w = num - τ_f`` (implicit midpoint, see :func:`_advance`), without a bristle state.

    * moving: kinetic friction at the predicted mid-interval speed (one corrector pass, so a fast pass
      through the Stribeck region is not evaluated at a stale speed);
    * the speed would cross zero: up to the crossing time ``t*`` friction opposes the old direction; after
      it the rotor either sticks (ends the interval at exactly 0, friction balancing the drive) or, when
      the drive exceeds breakaway, slips the other way — friction is then the time-weighted mean of the
      two phases, which keeps the result second-order accurate across step sizes;
    * at rest: stays stuck while the drive torque is within static friction, else breaks away.
    """
    mag = lambda d, speed: effects.friction_magnitude(d, speed, c.tau_c, c.tau_asym, c.tau_s, c.omega_s)  # noqa: E731
    J2h = 2.0 * c.J / h                       # den = J2h + (b - K B); num = J2h w0 + drive(0)
    d0 = ops.sign(w0)
    F_mov = mag(d0, abs(w0))
    if c.has_stribeck:
        w_pred = (num - d0 * F_mov) / den
        F_mov = mag(d0, abs(ops.where(w_pred * w0 > 0.0, w_pred, 0.5 * w0)))
    w_mov = (num - d0 * F_mov) / den
    crossed = ops.both(w0 * (2.0 * w_mov - w0) < 0.0, F_mov > 0.0)
    moving = w0 != 0.0
    if ops.all_true(moving) and not ops.any_true(crossed):   # the common case: sliding on
        return w_mov, d0 * F_mov
    # drive torque (everything but friction and inertia) at the crossing, w ~ 0: num - J2h w0 - (den - J2h)*0
    drive = num - J2h * w0
    push = ops.sign(drive)
    F_st = mag(push, 0.0 * w0)
    breaks = abs(drive) > F_st
    # crossing time: w0 + (drive - d0 F_mov) t*/J = 0
    t_star = ops.clip(-c.J * w0 / ops.where(crossed, drive - d0 * F_mov, -1.0), 0.0, h)
    f_cross = (t_star * d0 * F_mov + (h - t_star) * push * F_st) / h
    w_rev = (num - f_cross) / den
    reverses = ops.both(crossed, ops.both(breaks, push == -d0))
    w = ops.where(moving,
                  ops.where(reverses, w_rev, ops.where(crossed, 0.5 * w0, w_mov)),
                  ops.where(breaks, (num - push * F_st) / den, 0.0 * w0))
    tau_f = ops.where(moving,
                      ops.where(reverses, f_cross, ops.where(crossed, num - den * 0.5 * w0, d0 * F_mov)),
                      ops.where(breaks, push * F_st, drive))
    return w, tau_f


def _step(c: _Coeffs, s: _S, dt_ns: int, ops) -> None:
    """Advance ``dt_ns``: the controller ticks at multiples of its period; intervals split where asked."""
    tick = c.tick_ns
    end = s.t_ns + dt_ns
    while s.t_ns < end:
        phase = s.t_ns % tick
        if phase == 0:
            _control_tick(c, s, ops)
        _advance(c, s, min(tick - phase, end - s.t_ns), ops)


# -- public classes ------------------------------------------------------------------------------------

def _seconds_to_ns(dt: float) -> int:
    if not (dt >= 0.0 and math.isfinite(dt)):
        raise ValueError(f"dt: expected a finite duration >= 0 s, got {dt!r}")
    return int(round(dt * 1e9))


class _Base:
    _ops: Any

    def _init_state(self, c: _Coeffs, T_w0, T_h0, zeros):
        s = _S()
        s.t_ns = 0
        s.i = zeros + 0j
        s.omega = zeros + 0.0
        s.acc = zeros + 0.0
        s.theta = zeros + 0.0
        s.T_w, s.T_h = T_w0, T_h0
        s.v = zeros + 0j
        s.z = zeros + 0j
        s.i_ref = zeros + 0.0
        s.tripped = zeros != 0.0 if isinstance(zeros, np.ndarray) else False
        s.cmd_q = zeros + 0.0
        s.v_cmd = None
        s.tau_ext_out = zeros + 0.0
        s.e_in = s.e_joule = s.e_visc = s.e_fric = s.e_load = s.e_amb = s.e_disc = zeros + 0.0
        return s

    def step(self, dt: float) -> None:
        """Advance the simulation by ``dt`` seconds (any size; rounded to whole ns)."""
        _step(self._c, self._s, _seconds_to_ns(dt), self._ops)

    def step_ns(self, dt_ns: int) -> None:
        _step(self._c, self._s, int(dt_ns), self._ops)

    def _ledger_values(self):
        c, s = self._c, self._s
        return dict(electrical_in=s.e_in, joule=s.e_joule, magnetic=0.5 * c.L * abs(s.i) ** 2,
                    kinetic=0.5 * c.J * s.omega ** 2, viscous=s.e_visc, friction=s.e_fric, load=s.e_load,
                    heat_to_ambient=s.e_amb, discretization=s.e_disc,
                    thermal=c.C_w * (s.T_w - self._T0[0]) + c.C_h * (s.T_h - self._T0[1]))

    def _torque_to_current(self, tau_out):
        c = self._c
        return tau_out / (c.K_ref * c.N)


class Actuator(_Base):
    """One actuator, stepped with Python floats (fast path). Deterministic; no wall clock, no globals.

    >>> act = Actuator(ActuatorParams())
    >>> act.set_current_command(2.0)
    >>> act.step(0.01)
    """

    _ops = _ScalarOps

    def __init__(self, params: ActuatorParams | None = None, state: ActuatorState | None = None):
        self.params = params if params is not None else ActuatorParams()
        self._c = _Coeffs(self.params)
        th = self.params.thermal
        self._T0 = (th.initial_winding_temperature, th.initial_housing_temperature)
        self._s = self._init_state(self._c, *self._T0, 0.0)
        if state is not None:
            self.set_state(state)

    # inputs
    def set_current_command(self, i_q_ref: float) -> None:
        """q-axis current command [A] (limited by ``drive.current_limit`` and thermal derating)."""
        if not math.isfinite(i_q_ref):
            raise ValueError(f"current command: expected a finite q-axis current [A], got {i_q_ref!r}")
        self._s.cmd_q = float(i_q_ref)
        self._s.v_cmd = None

    def set_voltage_command(self, v_d: float, v_q: float) -> None:
        """Open-loop voltage mode [V, d-q power-invariant]: the current controller is bypassed (the
        inverter still limits |v| to the SVPWM circle). A current or torque command ends it."""
        if not (math.isfinite(v_d) and math.isfinite(v_q)):
            raise ValueError(f"voltage command: expected finite d/q voltages [V], got {v_d!r}, {v_q!r}")
        self._s.v_cmd = complex(v_d, v_q)

    def set_torque_command(self, tau_out: float) -> None:
        """Output-side torque command [N·m] → ``i_q_ref = τ / (K_t_q N)`` with the nominal K_t_q."""
        if not math.isfinite(tau_out):
            raise ValueError(f"torque command: expected a finite output torque [N*m], got {tau_out!r}")
        self._s.cmd_q = self._torque_to_current(float(tau_out))
        self._s.v_cmd = None

    def set_load_torque(self, tau_out: float) -> None:
        """Extra external load torque at the output [N·m], added to ``load.load_torque``."""
        if not math.isfinite(tau_out):
            raise ValueError(f"load torque: expected a finite output torque [N*m], got {tau_out!r}")
        self._s.tau_ext_out = float(tau_out)

    def update_params(self, params: ActuatorParams) -> None:
        """Replace the parameters; the state carries on (bus voltage, limits, load, ambient...)."""
        self.params = params
        self._c = _Coeffs(params)

    def reset_fault(self) -> None:
        """Clear a latched over-temperature trip (it trips again at once if still too hot)."""
        self._s.tripped = False

    # state
    @property
    def t(self) -> float:
        return self._s.t_ns * 1e-9

    @property
    def t_ns(self) -> int:
        return self._s.t_ns

    @property
    def state(self) -> ActuatorState:
        s = self._s
        return ActuatorState(t_ns=s.t_ns, i_d=s.i.real, i_q=s.i.imag, omega=s.omega, theta=s.theta,
                             T_winding=s.T_w, T_housing=s.T_h, v_d=s.v.real, v_q=s.v.imag, z_d=s.z.real,
                             z_q=s.z.imag, i_q_ref=s.i_ref, tripped=bool(s.tripped))

    def set_state(self, st: ActuatorState) -> None:
        s = self._s
        s.t_ns, s.i, s.omega, s.theta = int(st.t_ns), complex(st.i_d, st.i_q), float(st.omega), float(st.theta)
        s.T_w, s.T_h, s.v, s.z = float(st.T_winding), float(st.T_housing), complex(st.v_d, st.v_q), complex(st.z_d, st.z_q)
        s.i_ref, s.tripped = float(st.i_q_ref), bool(st.tripped)

    @property
    def energy(self) -> EnergyLedger:
        return EnergyLedger(**self._ledger_values())

    def outputs(self) -> dict[str, float]:
        """Everything a driver or the node publishes, derived from the state."""
        return _outputs(self._c, self._s, self.params.motor.winding, self._ops)

    def run(self, profile, *, record_every: float | None = None) -> "SimResult":
        """Run a command profile (see :mod:`bldc_actuator.profiles`) and return every signal."""
        from .profiles import run_profile

        return run_profile(self, profile, record_every=record_every)


def _outputs(c: _Coeffs, s: _S, winding, ops) -> dict[str, Any]:
    i_d, i_q = s.i.real, s.i.imag
    v_d, v_q = s.v.real, s.v.imag
    K = c.K_ref * effects.flux_factor(s.T_h, c.T_ref, c.beta)
    theta_e = c.pole_pairs * s.theta
    i_a, i_b, i_c = frames.dq_to_abc(i_d, i_q, theta_e)
    i_A, i_B, i_C = frames.phase_to_line_current(i_a, i_b, i_c, winding)
    v_mag = abs(s.v)
    return {
        "t": s.t_ns * 1e-9,
        "i_d": i_d, "i_q": i_q, "i_q_ref": s.i_ref, "v_d": v_d, "v_q": v_q,
        "v_limit_q": c.V_max, "v_magnitude_q": v_mag, "bus_voltage": c.V_bus,
        "voltage_saturated": v_mag >= c.V_max * (1.0 - 1e-9),
        "omega": s.omega, "theta": s.theta,
        "position_out": s.theta / c.N, "velocity_out": s.omega / c.N,
        "torque_em": K * i_q, "effort_out": K * i_q * c.N,
        "i_phase_a": i_a, "i_phase_b": i_b, "i_phase_c": i_c,
        "i_line_a": i_A, "i_line_b": i_B, "i_line_c": i_C,
        "T_winding": s.T_w, "T_housing": s.T_h,
        "resistance_phase": effects.resistance_at(c.R_ref, s.T_w, c.T_ref, c.alpha),
        "joule_power": effects.resistance_at(c.R_ref, s.T_w, c.T_ref, c.alpha) * abs(s.i) ** 2,
        "current_limit_effective": _current_limit_readonly(c, s, ops),
        "tripped": s.tripped,
    }


def _current_limit_readonly(c, s, ops):
    """Effective current limit for the present winding temperature and trip state (no state change)."""
    scale = ops.clip((c.T_trip - s.T_w) / (c.T_trip - c.T_derate), 0.0, 1.0)
    return ops.where(s.tripped, 0.0, c.I_lim * scale)


class BatchActuator(_Base):
    """Many actuators (or one actuator under many parameter sets) stepped together with numpy.

    All share the controller rate; every other parameter may differ. Commands are arrays (or scalars).
    """

    _ops = _ArrayOps

    def __init__(self, params: Sequence[ActuatorParams]):
        self.params = list(params)
        if not self.params:
            raise ValueError("BatchActuator needs at least one parameter set")
        self._c = _Coeffs(self.params)
        zeros = np.zeros(len(self.params))
        T_w0 = np.array([p.thermal.initial_winding_temperature for p in self.params])
        T_h0 = np.array([p.thermal.initial_housing_temperature for p in self.params])
        self._T0 = (T_w0, T_h0)
        self._s = self._init_state(self._c, T_w0.copy(), T_h0.copy(), zeros)
        self._winding = np.array([p.motor.winding for p in self.params])

    def __len__(self) -> int:
        return len(self.params)

    def set_state(self, *, i_d, i_q, omega, theta, T_winding, T_housing, v_d=0.0, v_q=0.0, z_d=0.0, z_q=0.0,
                  i_q_ref=0.0) -> None:
        """Set the state of every element (arrays of length ``len(self)`` or scalars), e.g. to start
        simulation windows from measured states (multiple shooting). The command is set to ``i_q_ref``."""
        n = len(self)
        arr = lambda x: np.broadcast_to(np.asarray(x, dtype=float), (n,)).copy()  # noqa: E731
        s = self._s
        s.i = arr(i_d) + 1j * arr(i_q)
        s.omega, s.theta = arr(omega), arr(theta)
        s.T_w, s.T_h = arr(T_winding), arr(T_housing)
        s.v = arr(v_d) + 1j * arr(v_q)
        s.z = arr(z_d) + 1j * arr(z_q)
        s.i_ref = arr(i_q_ref)
        s.cmd_q = arr(i_q_ref)
        s.acc = np.zeros(n)
        s.v_cmd = None

    def set_current_command(self, i_q_ref) -> None:
        self._s.cmd_q = np.broadcast_to(np.asarray(i_q_ref, dtype=float), (len(self),)).copy()

    def set_torque_command(self, tau_out) -> None:
        self._s.cmd_q = np.broadcast_to(self._torque_to_current(np.asarray(tau_out, dtype=float)), (len(self),)).copy()

    def set_load_torque(self, tau_out) -> None:
        self._s.tau_ext_out = np.broadcast_to(np.asarray(tau_out, dtype=float), (len(self),)).copy()

    @property
    def t(self) -> float:
        return self._s.t_ns * 1e-9

    def outputs(self) -> dict[str, np.ndarray]:
        out = _outputs(self._c, self._s, "wye", self._ops)
        # line currents depend on each actuator's winding
        delta = self._winding == "delta"
        if np.any(delta):
            la, lb, lc = frames.phase_to_line_current(out["i_phase_a"], out["i_phase_b"], out["i_phase_c"], "delta")
            for key, val in zip(("i_line_a", "i_line_b", "i_line_c"), (la, lb, lc)):
                out[key] = np.where(delta, val, out[key])
        return out

    @property
    def energy(self) -> EnergyLedger:
        return EnergyLedger(**self._ledger_values())


@dataclass
class SimResult:
    """Signals sampled over a run: each field an array over sample times (see :func:`Actuator.outputs`)."""

    signals: dict[str, np.ndarray]
    params: ActuatorParams

    def __getitem__(self, key: str) -> np.ndarray:
        return self.signals[key]

    def keys(self):
        return self.signals.keys()


STATE_FIELDS = tuple(f.name for f in fields(ActuatorState))
