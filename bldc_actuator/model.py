"""The actuator: q-axis PMSM + field-oriented drive + gear + two-node thermal network.

Continuous-time plant (motor side, power-invariant d-q of the winding quantities, ``i = i_d + j i_q``)::

    L_q di/dt  = v - R(T_w) i - j p ω L_q i - j K(T_m) ω              [V]
    J dω/dt    = K(T_m) i_q - b ω - τ_f(ω) - τ_cog(θ) - τ_load(θ/N)/N   [N·m]
    dθ/dt      = ω                                                     [rad/s]
    C_w dT_w/dt = R(T_w)|i|² - (T_w - T_h)/R_wh                        [W]
    C_h dT_h/dt = (T_w - T_h)/R_wh - (T_h - T_a)/R_ha                  [W]

Drive: a discrete PI current controller (d and q, pole-zero cancelling gains, decoupling feed-forward,
back-calculation anti-windup; or, ``drive.current_controller: complex_vector``, motulator's 2DOF complex-vector PI
with its realized-voltage integrator, see :func:`bldc_actuator.kernel.control_tick`) runs at
``drive.current_loop_rate``; its voltage, limited to the circle
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

Prescribed motion (:meth:`Actuator.prescribe_motion`, for a multibody that integrates the mechanics, see
:mod:`bldc_actuator.mujoco`): the mechanical equation is replaced by a given speed ramp ``ω0 + a t``; the
electrical, drive and thermal equations are the same, and the kernel accumulates the torque impulse ``∫K i_q dt``
(the mean torque a body receives) and the magnetic work ``∫K ω i_q dt``.

One kernel (:mod:`bldc_actuator.kernel`: :func:`~bldc_actuator.kernel.advance`,
:func:`~bldc_actuator.kernel.control_tick`, ...) serves both :class:`Actuator` and :class:`BatchActuator`
(many actuators or parameter sets). It is written once, per actuator, and compiled with numba when numba is
installed (:data:`COMPILED`); without numba the same source runs as plain Python, with identical results.
"""

from __future__ import annotations

import cmath
import math
import struct
import warnings
from collections import namedtuple
from dataclasses import dataclass, fields
from types import SimpleNamespace
from typing import Any, Sequence

import numpy as np

from . import effects, frames, kernel
from .kernel import COMPILED, COEF_DTYPE, STATE_DTYPE, warm_up  # noqa: F401  (public)
from .params import ActuatorParams, ParameterWarning, controller_motor, current_loop_warning
from .profiles import SimResult  # noqa: F401  (public: Actuator.run returns it)

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
        # a batch repeats its sets (a replay: one set per window): each field is read once per distinct set
        first: dict[int, int] = {}
        where = np.array([first.setdefault(id(p), len(first)) for p in plist], dtype=int)
        distinct = list({id(p): p for p in plist}.values())
        col = ((lambda f: np.array([f(p) for p in distinct], dtype=float)[where]) if batch
               else (lambda f: float(f(plist[0]))))
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
                      if batch else frames.voltage_limit_q(self.V_bus, wind[0])) * d("modulation_limit")
        self.I_lim = d("current_limit")
        rates = {p.drive.current_loop_rate for p in plist}
        if len(rates) != 1:
            raise ValueError("drive.current_loop_rate must be the same for every actuator of a batch")
        self.tick_ns = int(round(1e9 / rates.pop()))
        delays = {int(round(p.drive.current_loop_delay * 1e9)) for p in plist}
        if len(delays) != 1:
            raise ValueError("drive.current_loop_delay must be the same for every actuator of a batch")
        self.delay_ns = min(delays.pop(), self.tick_ns)
        self.T_c = self.tick_ns * 1e-9
        # the drive's current loop is tuned with, and feeds forward, what IT believes about the motor
        # (drive.controller_*; 0 = the motor's own value), not the true motor
        ctl = lambda k: col(lambda p: controller_motor(p)[k])  # noqa: E731
        self.R_ctl, self.L_ctl, self.K_ctl = ctl(0), ctl(1), ctl(2)
        w_c = TWO_PI * d("current_loop_bandwidth")
        self.Kp = w_c * self.L_ctl
        self.Ki = w_c * self.R_ctl
        self.decouple = d("decoupling_enabled")
        self.cc_form = col(lambda p: kernel.CURRENT_CONTROLLERS.index(p.drive.current_controller))
        self.v_lim_mode = col(lambda p: kernel.VOLTAGE_LIMIT_MODES.index(p.drive.voltage_limit_mode))
        self.I_fw = d("field_weakening_current_max")
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
        self.fe_h = e("iron_loss_hysteresis")
        self.fe_e = e("iron_loss_eddy")
        self.mu_gear = e("gear_load_friction")         # friction per N*m the motor transmits to the gear
        self.has_friction = bool(np.any(self.tau_c) or np.any(self.tau_asym) or np.any(self.tau_s)
                                 or np.any(self.fe_h) or np.any(self.mu_gear))
        self.sens_off_a, self.sens_off_b = d("current_sensor_offset_a"), d("current_sensor_offset_b")
        self.sens_gain_a, self.sens_gain_b = d("current_sensor_gain_a"), d("current_sensor_gain_b")
        self.v_dt = d("dead_time") * d("pwm_frequency") * self.V_bus
        self.dt_delta = col(lambda p: p.motor.winding == "delta")   # how the leg errors reach the windings
        self.dt_band = d("dead_time_current_band")                  # linear below it (switching ripple), 0 = sign
        self.dt_start = col(lambda p: kernel.DEAD_TIME_SIGNS.index(p.drive.dead_time_sign))  # 1: sign at start
        self.has_sensor_error = bool(np.any(self.sens_off_a) or np.any(self.sens_off_b)
                                     or np.any(self.sens_gain_a != 1.0) or np.any(self.sens_gain_b != 1.0))
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
        self.k_sat = e("kt_saturation")
        self.sat_n = e("kt_saturation_exponent")
        g = lambda name: col(lambda p: getattr(p.gear, name))  # noqa: E731
        # transmission (output side); gear.transmission_stiffness = 0 means rigid (the kernel's rigid path)
        self.k_tr = g("transmission_stiffness")
        self.c_tr = g("transmission_damping")
        self.J_l = g("load_inertia")
        self.bl_half = 0.5 * g("backlash")
        self.has_compliance = col(lambda p: p.gear.transmission_stiffness > 0.0)
        self.compliant = bool(np.any(self.has_compliance))
        self.enc_load = col(lambda p: p.gear.encoder_side == "load")
        self.n_cog = len(self.cog_cos)
        if self.n_cog > kernel.MAX_COGGING_HARMONICS:
            raise ValueError(f"effects.cogging_cos: at most {kernel.MAX_COGGING_HARMONICS} harmonics, "
                             f"got {self.n_cog}")

    def pack(self, n: int) -> np.ndarray:
        """The kernel's coefficient records (:data:`kernel.COEF_DTYPE`), one per actuator."""
        cs = np.zeros(n, COEF_DTYPE)
        for name in kernel._COEF_SCALARS:  # noqa: SLF001 - the layout belongs to the kernel
            cs[name] = np.broadcast_to(np.asarray(getattr(self, name), dtype=float), (n,))
        cs["tick_ns"] = self.tick_ns
        cs["delay_ns"] = self.delay_ns
        cs["n_cog"] = self.n_cog
        for k in range(self.n_cog):
            cs["cog_cos"][:, k] = self.cog_cos[k]
            cs["cog_sin"][:, k] = self.cog_sin[k]
        th = kernel.thermal_matrices(cs["R_wh"], cs["R_ha"], cs["C_w"], cs["C_h"], self.tick_ns * 1e-9)
        cs["th_tick"] = np.column_stack(th)
        return cs


def warn_current_loop(params: Sequence[ActuatorParams]) -> None:
    """A ``ParameterWarning`` when the motor can outrun the complex-vector current loop
    (:func:`~bldc_actuator.params.current_loop_warning`): what a user of an actuator (``simulate``, the node's
    plant, the MuJoCo coupling, the Python API) must notice before a run at high speed diverges. Once per
    distinct warning among ``params`` (a batch of a thousand copies of one set says it once), at the caller's
    line (the same batch built again there: Python's default filter prints it once)."""
    distinct = {id(p): p for p in params}.values()
    for msg in dict.fromkeys(m for m in map(current_loop_warning, distinct) if m):
        warnings.warn(msg, ParameterWarning, stacklevel=3)


def thermal_step_matrices(thermal, h: float):
    """Exact discretisation of the two-node thermal network (:class:`~bldc_actuator.params.ThermalParams`)
    over ``h`` seconds for constant Joule power P, with ``y`` = temperatures above ambient:
    ``y_w' = p11 y_w + p12 y_h + G1 P``, ``y_h' = p21 y_w + p22 y_h + G2 P``. Returns
    ``(p11, p12, p21, p22, G1, G2)``: the same matrices the simulator uses (floats or, for array
    parameters, arrays)."""
    return _thermal_matrices(thermal.winding_to_housing_resistance, thermal.housing_to_ambient_resistance,
                             thermal.winding_heat_capacity, thermal.housing_heat_capacity, h)[:6]


def _thermal_matrices(R_wh, R_ha, C_w, C_h, h, ops=None):
    """:func:`bldc_actuator.kernel.thermal_matrices` (``ops`` is accepted for older callers and ignored)."""
    out = kernel.thermal_matrices(R_wh, R_ha, C_w, C_h, h)
    if not isinstance(R_wh, np.ndarray) and not isinstance(h, np.ndarray):
        out = tuple(float(x) for x in out)
    return out


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
    z_d: float = 0.0            #: PI integrator, d [V] (complex_vector: its integrator u_i, see kernel.control_tick)
    z_q: float = 0.0            #: PI integrator, q [V]
    i_q_ref: float = 0.0        #: q-axis current reference after limits [A]
    tripped: bool = False       #: over-temperature trip (latched)
    i_d_ref: float = 0.0        #: d-axis current reference of the field-weakening regulator [A] (<= 0)
    #: the load behind a compliant transmission (gear.transmission_stiffness > 0), OUTPUT side: angle [rad] and
    #: speed [rad/s]; None = the rigid position theta / N, omega / N (what a rigid transmission always has)
    theta_load_out: float | None = None
    omega_load_out: float | None = None

    @property
    def t(self) -> float:
        return self.t_ns * 1e-9


@dataclass
class EnergyLedger:
    """Cumulative energies [J] since t = 0 (stored ones are current values)."""

    electrical_in: float = 0.0      #: ∫ (v_d i_d + v_q i_q) dt: power from the inverter
    joule: float = 0.0              #: ∫ R |i|² dt
    magnetic: float = 0.0           #: ½ L |i|² now
    kinetic: float = 0.0            #: ½ J ω² now (+ ½ J_load ω_load² of the load behind a compliant transmission)
    viscous: float = 0.0            #: ∫ b ω² dt
    friction: float = 0.0           #: ∫ τ_f ω dt
    load: float = 0.0               #: work done on the external load and cogging ∫ (τ_load/N + τ_cog) ω dt
    heat_to_ambient: float = 0.0    #: ∫ (T_h - T_a)/R_ha dt
    iron_heat: float = 0.0          #: ∫ (τ_h |ω| + c_e ω²) dt: iron loss into the winding node (its drag work is
    #: in ``friction`` and ``viscous``)
    thermal: float = 0.0            #: C_w (T_w - T_w0) + C_h (T_h - T_h0)
    #: ∫ K ω(t) i_q dt (electrical side) minus the work of the interval-mean torque (mechanical side):
    #: the integrator's own energy error, O(h³) per interval. Reported, never subtracted in residual().
    #: With backlash it also holds the spring's energy error of the steps that cross a backlash edge.
    discretization: float = 0.0
    spring: float = 0.0             #: ½ k dz(δ)² now: the compliant transmission's stored energy
    transmission_damping: float = 0.0   #: ∫ c (dδ/dt)² dt: dissipated in the transmission's damping

    def residual(self, initial: "EnergyLedger") -> float:
        """Electrical energy in minus everything it went to [J] (0 up to round-off)."""
        return (self.electrical_in - self.joule - (self.magnetic - initial.magnetic)
                - (self.kinetic - initial.kinetic) - (self.spring - initial.spring) - self.viscous - self.friction
                - self.load - self.transmission_damping)

    def thermal_residual(self) -> float:
        """Joule heat + iron-loss heat minus (heat stored + heat to ambient) [J]."""
        return self.joule + self.iron_heat - self.thermal - self.heat_to_ambient


# -- public classes ------------------------------------------------------------------------------------

#: one actuator's kernel state as a named tuple (cheap to build every publish period)
_StateView = namedtuple("_StateView", STATE_DTYPE.names)


def _joint_state_struct() -> struct.Struct:
    """Reads ``(i_q, omega, theta, T_h, v_d, v_q)`` straight from one state record's bytes (numpy's
    ``record.item()`` converts all ~25 fields: ten times the cost, and the node reads 12 joints every period)."""
    at = {name: STATE_DTYPE.fields[name][1] for name in ("i", "omega", "theta", "T_h", "v")}
    offsets = [at["i"] + 8, at["omega"], at["theta"], at["T_h"], at["v"], at["v"] + 8]   # (complex: re, im)
    if offsets != sorted(offsets) or STATE_DTYPE.byteorder not in "=|":
        raise AssertionError("kernel.STATE_DTYPE layout changed: update model._joint_state_struct")
    fmt, pos = "=", 0
    for off in offsets:
        fmt += (f"{off - pos}x" if off > pos else "") + "d"
        pos = off + 8
    return struct.Struct(fmt)


_JOINT_STATE = _joint_state_struct()


def _seconds_to_ns(dt: float) -> int:
    if not (dt >= 0.0 and math.isfinite(dt)):
        raise ValueError(f"dt: expected a finite duration >= 0 s, got {dt!r}")
    return int(round(dt * 1e9))


class _Base:
    """Holds the kernel's records: coefficients ``_cs`` and state ``_ss`` (structured arrays, one element per
    actuator). Compiled: the kernel steps the arrays in place. Pure Python: it steps :class:`kernel.Record`
    objects (``_rc``, ``_rs``), the working copies of the same fields."""

    _batch: bool

    def _init_kernel(self, plist, T_w0, T_h0) -> None:
        self._c = _Coeffs(plist if self._batch else plist[0])
        n = len(plist)
        self._cs = self._c.pack(n)
        self._ss = np.zeros(n, STATE_DTYPE)
        self._ss["T_w"], self._ss["T_h"] = T_w0, T_h0
        self._T0 = (T_w0, T_h0) if self._batch else (float(T_w0), float(T_h0))
        self._rc = self._rs = None
        self._step_all = kernel.step_all
        if not COMPILED:
            self._rc, self._rs = kernel.to_records(self._cs), kernel.to_records(self._ss)
        else:
            self._step_all = kernel.compiled_entry(kernel.step_all, self._cs, self._ss)
        self._seat_load()

    def _new_coeffs(self, plist) -> None:
        self._c = _Coeffs(plist if self._batch else plist[0])
        self._cs = self._c.pack(len(plist))
        if not COMPILED:
            self._rc = kernel.to_records(self._cs)

    # field access (arrays for a batch, Python scalars for one actuator)
    def _get(self, name: str):
        if self._rs is None:
            col = self._ss[name]
            return col.copy() if self._batch else col[0].item()
        if self._batch:
            return np.array([getattr(r, name) for r in self._rs])
        return getattr(self._rs[0], name)

    def _set(self, name: str, value) -> None:
        if self._rs is None:
            self._ss[name] = value
            return
        for r, v in zip(self._rs, np.broadcast_to(np.asarray(value), (len(self._rs),))):
            setattr(r, name, kernel._python_value(v))  # noqa: SLF001

    def _view(self) -> SimpleNamespace:
        """The state as attributes (arrays for a batch, scalars for one actuator)."""
        if not self._batch:
            values = self._ss[0].item() if self._rs is None else [getattr(self._rs[0], n) for n in STATE_DTYPE.names]
            return _StateView._make(values)
        return SimpleNamespace(**{name: self._get(name) for name in STATE_DTYPE.names})

    def step(self, dt: float) -> None:
        """Advance the simulation by ``dt`` seconds (any size; rounded to whole ns)."""
        if self._rs is None and dt > 0.0 and dt < 1e9:   # the hot path: straight into the compiled kernel
            self._step_all(self._cs, self._ss, int(round(dt * 1e9)))
            return
        self.step_ns(_seconds_to_ns(dt))

    def step_ns(self, dt_ns: int) -> None:
        dt_ns = int(dt_ns)
        if self._rs is None:
            self._step_all(self._cs, self._ss, dt_ns)
        else:
            for c, s in zip(self._rc, self._rs):
                kernel.step(c, s, dt_ns)

    def prescribe_motion(self, omega, acc=0.0, theta=None) -> None:
        """Prescribed-motion mode, for a multibody that integrates the mechanics (:mod:`bldc_actuator.mujoco`):
        the steps that follow advance the drive, electrical and thermal states with the rotor speed given as
        ``omega + acc·t`` [rad/s, rad/s², motor side, from now] and the angle ``theta`` [rad] (kept if None);
        the rotor inertia, damping, friction and load of the parameters are then the body's to apply (the
        kernel's ledger keeps only the electrical and thermal terms meaningful: :attr:`impulse_em`,
        :attr:`magnetic_work`). Call it before every body step; :meth:`release_motion` ends the mode.

        Rigid transmissions only: the body's joint is the rotor through an ideal gear (a compliant one,
        ``gear.transmission_stiffness`` > 0, is refused with a ValueError; model it in the body instead)."""
        if self._c.compliant:
            raise ValueError("gear.transmission_stiffness: prescribed motion (a multibody integrating the mechanics) "
                             "needs a rigid transmission (0 N*m/rad); model the compliance in the body (a joint "
                             "spring) instead")
        self._set("omega", omega)
        self._set("acc", acc)
        if theta is not None:
            self._set("theta", theta)
        self._set("prescribed", True)

    def _seat_load(self, only_new: np.ndarray | bool = True) -> None:
        """Put the load behind a compliant transmission where a rigid one would hold it: angle ``theta / N`` less
        the static deflection under the constant load, speed ``omega / N`` (where ``only_new`` is True)."""
        c = self._c
        if not c.compliant:
            return
        k = np.where(c.has_compliance, c.k_tr, 1.0)
        static = (c.load0 + self._get("tau_ext_out")) / k * c.has_compliance
        th_l = self._get("theta") / c.N - static
        w_l = self._get("omega") / c.N
        keep = np.logical_not(only_new)
        self._set("theta_l", np.where(keep, self._get("theta_l"), th_l))
        self._set("omega_l", np.where(keep, self._get("omega_l"), w_l))

    def set_rotor_torque(self, tau_motor) -> None:
        """External torque acting on the rotor [N*m, MOTOR side] (positive drives the rotor forward), besides the
        motor's own: e.g. a torque the motor's current produces, applied from outside (the diagnosis' replay driven
        by the measured current). With a rigid transmission it is ``-N`` times an output load."""
        tau = np.asarray(tau_motor, dtype=float)
        if not np.all(np.isfinite(tau)):
            raise ValueError(f"rotor torque: expected a finite motor-side torque [N*m], got {tau_motor!r}")
        self._set("tau_ext_m", tau if self._batch else float(tau))

    def release_motion(self) -> None:
        """End :meth:`prescribe_motion`: the actuator's own mechanical equation moves the rotor again."""
        self._set("prescribed", False)

    @property
    def impulse_em(self):
        """∫ τ_em dt since t = 0 [N·m·s, motor side]: its increase over a step divided by the step's length is the
        step's mean electromagnetic torque (what a coupled body receives)."""
        return self._get("imp_em")

    @property
    def magnetic_work(self):
        """∫ K ω i_q dt since t = 0 [J]: the electrical energy converted to mechanical work (at the speed the
        kernel saw: its own, or the prescribed one)."""
        return self._get("e_em")

    def _ledger_values(self):
        c, g = self._c, self._get
        kinetic = 0.5 * c.J * g("omega") ** 2
        spring = 0.0 * kinetic
        if c.compliant:
            w_l = g("omega_l")
            kinetic = kinetic + 0.5 * c.J_l * w_l * w_l * c.has_compliance
            defl = g("theta") / c.N - g("theta_l")
            x = np.sign(defl) * np.maximum(np.abs(defl) - c.bl_half, 0.0)     # the dead zone of the backlash
            spring = 0.5 * c.k_tr * x * x * c.has_compliance
            if not self._batch:
                kinetic, spring = float(kinetic), float(spring)
        return dict(electrical_in=g("e_in"), joule=g("e_joule"), magnetic=0.5 * c.L * abs(g("i")) ** 2,
                    kinetic=kinetic, spring=spring, transmission_damping=g("e_tdamp"),
                    viscous=g("e_visc"), friction=g("e_fric"),
                    load=g("e_load"), heat_to_ambient=g("e_amb"), discretization=g("e_disc"), iron_heat=g("e_iron"),
                    thermal=c.C_w * (g("T_w") - self._T0[0]) + c.C_h * (g("T_h") - self._T0[1]))

    def _torque_to_current(self, tau_out):
        c = self._c
        return tau_out / (c.K_ctl * c.N)        # the drive converts with the K it believes (drive.controller_*)

    @property
    def t(self) -> float:
        return self.t_ns * 1e-9

    @property
    def t_ns(self) -> int:
        return int(self._ss["t_ns"][0]) if self._rs is None else int(self._rs[0].t_ns)

    @property
    def energy(self) -> EnergyLedger:
        return EnergyLedger(**self._ledger_values())


class Actuator(_Base):
    """One actuator. Deterministic; no wall clock, no globals.

    >>> act = Actuator(ActuatorParams())
    >>> act.set_current_command(2.0)
    >>> act.step(0.01)
    """

    _batch = False

    def __init__(self, params: ActuatorParams | None = None, state: ActuatorState | None = None, *,
                 warn: bool = True):
        """``warn``: a ``ParameterWarning`` when the motor can outrun a complex-vector current loop
        (:func:`warn_current_loop`); False where the caller has printed it already (the parameter file's reader,
        :func:`~bldc_actuator.params.load_yaml`, says it with the file's name)."""
        self.params = params if params is not None else ActuatorParams()
        if warn:
            warn_current_loop([self.params])
        th = self.params.thermal
        self._init_kernel([self.params], th.initial_winding_temperature, th.initial_housing_temperature)
        self._v_mode = False
        if state is not None:
            self.set_state(state)

    # inputs
    def set_current_command(self, i_q_ref: float) -> None:
        """q-axis current command [A] (limited by ``drive.current_limit`` and thermal derating)."""
        if not math.isfinite(i_q_ref):
            raise ValueError(f"current command: expected a finite q-axis current [A], got {i_q_ref!r}")
        self._set("cmd_q", float(i_q_ref))
        self._current_mode()

    @property
    def current_command(self) -> float:
        """The q-axis current command [A] the drive holds: the last current command, or a torque command converted
        with the drive's torque constant; before the current limit and derating (``outputs()["i_q_ref"]`` is the
        reference after them, as of the last controller tick)."""
        return float(self._get("cmd_q"))

    def _current_mode(self) -> None:
        if self._v_mode:
            self._set("v_mode", False)
            self._v_mode = False

    def set_voltage_command(self, v_d: float, v_q: float) -> None:
        """Open-loop voltage mode [V, d-q power-invariant]: the current controller is bypassed (the
        inverter still limits |v| to the SVPWM circle). A current or torque command ends it."""
        if not (math.isfinite(v_d) and math.isfinite(v_q)):
            raise ValueError(f"voltage command: expected finite d/q voltages [V], got {v_d!r}, {v_q!r}")
        self._set("v_cmd", complex(v_d, v_q))
        self._set("v_mode", True)
        self._v_mode = True

    def set_torque_command(self, tau_out: float) -> None:
        """Output-side torque command [N·m] → ``i_q_ref = τ / (K_t_q N)`` with the nominal K_t_q."""
        if not math.isfinite(tau_out):
            raise ValueError(f"torque command: expected a finite output torque [N*m], got {tau_out!r}")
        self._set("cmd_q", self._torque_to_current(float(tau_out)))
        self._current_mode()

    def set_load_torque(self, tau_out: float) -> None:
        """Extra external load torque at the output [N·m], added to ``load.load_torque``."""
        if not math.isfinite(tau_out):
            raise ValueError(f"load torque: expected a finite output torque [N*m], got {tau_out!r}")
        self._set("tau_ext_out", float(tau_out))

    def update_params(self, params: ActuatorParams) -> None:
        """Replace the parameters; the state carries on (bus voltage, limits, load, ambient...). A transmission
        that turns compliant starts with its load where the rigid one held it (:meth:`_seat_load`)."""
        was = bool(self._c.compliant)
        if params.drive != self.params.drive or params.motor != self.params.motor:
            warn_current_loop([params])
        self.params = params
        self._new_coeffs([params])
        if not was:
            self._seat_load()

    def reset_fault(self) -> None:
        """Clear a latched over-temperature trip (it trips again at once if still too hot)."""
        self._set("tripped", False)

    # state
    @property
    def state(self) -> ActuatorState:
        g = self._get
        i, v, z = complex(g("i")), complex(g("v")), complex(g("z"))
        return ActuatorState(t_ns=int(g("t_ns")), i_d=i.real, i_q=i.imag, omega=float(g("omega")),
                             theta=float(g("theta")), T_winding=float(g("T_w")), T_housing=float(g("T_h")),
                             v_d=v.real, v_q=v.imag, z_d=z.real, z_q=z.imag, i_q_ref=float(g("i_ref")),
                             tripped=bool(g("tripped")), i_d_ref=float(g("i_fw")),
                             theta_load_out=float(g("theta_l")) if self._c.compliant else None,
                             omega_load_out=float(g("omega_l")) if self._c.compliant else None)

    def set_state(self, st: ActuatorState) -> None:
        s = self._set
        s("t_ns", int(st.t_ns))
        s("i", complex(st.i_d, st.i_q))
        s("omega", float(st.omega))
        s("theta", float(st.theta))
        s("T_w", float(st.T_winding))
        s("T_h", float(st.T_housing))
        s("v", complex(st.v_d, st.v_q))
        s("v_next", complex(st.v_d, st.v_q))
        s("v_prev", complex(st.v_d, st.v_q))
        s("z", complex(st.z_d, st.z_q))
        s("i_ref", float(st.i_q_ref))
        s("tripped", bool(st.tripped))
        s("i_fw", float(st.i_d_ref))
        self._seat_load()
        if st.theta_load_out is not None:
            s("theta_l", float(st.theta_load_out))
        if st.omega_load_out is not None:
            s("omega_l", float(st.omega_load_out))

    def outputs(self) -> dict[str, float]:
        """Everything a driver or the node publishes, derived from the state."""
        return _outputs(self._c, self._view(), self.params.motor.winding, _ScalarOps)

    def joint_state(self) -> tuple[float, float, float, bool]:
        """``(position_out [rad], velocity_out [rad/s], effort_out [N*m], voltage_saturated)``: the same
        numbers as those keys of :meth:`outputs` (same formulas), for a fraction of its cost (a node
        publishing joint states every period needs nothing else)."""
        c = self._c
        if self._rs is None:
            i_q, omega, theta, T_h, v_d, v_q = _JOINT_STATE.unpack_from(self._ss)
            v = complex(v_d, v_q)
        else:
            r = self._rs[0]
            i_q, omega, theta, T_h, v = r.i.imag, r.omega, r.theta, r.T_h, r.v
        if c.enc_load and c.compliant:     # an encoder behind a compliant transmission reads the load
            return (self._get("theta_l"), self._get("omega_l"), _torque_constant_q(c, i_q, T_h) * i_q * c.N,
                    _voltage_saturated(c, abs(v)))
        return (theta / c.N, omega / c.N, _torque_constant_q(c, i_q, T_h) * i_q * c.N,
                _voltage_saturated(c, abs(v)))

    def tick_trace(self, capacity: int = 1024) -> "TickTrace":
        """A :class:`TickTrace` of this actuator: step through it to record the state at every current-loop tick
        (its buffers grow as needed; ``capacity`` ticks at first)."""
        return TickTrace(self, capacity)

    def trace_ns(self, dt_ns: int, *, include_start: bool = False) -> np.ndarray:
        """Advance ``dt_ns`` [ns] as :meth:`step_ns` does and return the state (:data:`TRACE_DTYPE`) at every
        current-loop tick instant passed (see :class:`TickTrace`); ``include_start``: the state now first."""
        tr = TickTrace(self, int(dt_ns) // int(self._c.tick_ns) + 2)
        if include_start:
            tr.record_now()
        tr.step_ns(dt_ns)
        return tr.states()

    def tick_signals(self, states: np.ndarray) -> dict[str, np.ndarray]:
        """Signals of traced states (:meth:`trace_ns`) by the formulas of :meth:`outputs`: ``t`` [s], ``i_d``,
        ``i_q`` [A], ``v_magnitude_q`` [V] (the voltage held up to the instant), ``voltage_saturated``,
        ``velocity_out`` [rad/s] (what the encoder reports: the load behind a compliant transmission with
        ``gear.encoder_side: load``), ``T_winding``, ``T_housing`` [degC]."""
        c = self._c
        v_mag = np.abs(states["v"])
        if c.enc_load and c.compliant:
            velocity_out = states["omega_l"].copy()
        else:
            velocity_out = states["omega"] / c.N
        return {"t": states["t_ns"] * 1e-9, "i_d": states["i"].real.copy(), "i_q": states["i"].imag.copy(),
                "v_magnitude_q": v_mag, "voltage_saturated": _voltage_saturated(c, v_mag),
                "velocity_out": velocity_out, "T_winding": states["T_w"].copy(), "T_housing": states["T_h"].copy()}

    def run(self, profile, *, record_every: float | None = None) -> "SimResult":
        """Run a command profile (see :mod:`bldc_actuator.profiles`) and return every signal."""
        from .profiles import run_profile

        return run_profile(self, profile, record_every=record_every)


#: what :class:`TickTrace` records at every tick (fields of :data:`kernel.STATE_DTYPE`)
TRACE_DTYPE = np.dtype([(name, STATE_DTYPE[name]) for name in ("t_ns", "i", "v", "omega", "omega_l", "T_w", "T_h")])
_kernel_step = kernel.step


@kernel.jit
def _trace_ticks(cs, ss, first, n, tick, end, k0, now, t_ns, i, v, omega, omega_l, T_w, T_h):
    """Actuator 0 of ``cs``/``ss``: with ``now`` the state now at index ``k0``; then stepped to each tick instant
    ``first + k tick`` (k < n), the state after each at the next index; then to ``end``. Returns the next index."""
    c = cs[0]
    s = ss[0]
    k1 = k0
    for k in range(-1 if now else 0, n):
        if k >= 0:
            b = first + k * tick
            if b > s.t_ns:
                _kernel_step(c, s, b - s.t_ns)
        t_ns[k1] = s.t_ns
        i[k1] = s.i
        v[k1] = s.v
        omega[k1] = s.omega
        omega_l[k1] = s.omega_l
        T_w[k1] = s.T_w
        T_h[k1] = s.T_h
        k1 += 1
    if end > s.t_ns:
        _kernel_step(c, s, end - s.t_ns)
    return k1


class TickTrace:
    """The state of an :class:`Actuator` at every current-loop tick while it is stepped through this object
    (:meth:`step_ns`): the kernel's own resolution, whatever the caller's steps (a peak between two of the caller's
    samples is recorded). One compiled loop over :func:`kernel.step` per call, into growing column buffers."""

    def __init__(self, actuator: "Actuator", capacity: int = 1024):
        self._act = actuator
        self._cols = [np.empty(max(int(capacity), 1), TRACE_DTYPE[name]) for name in TRACE_DTYPE.names]
        self.n = 0                                  #: states recorded

    def _reserve(self, extra: int) -> None:
        size = len(self._cols[0])
        if self.n + extra > size:
            new = max(self.n + extra, 2 * size)
            self._cols = [np.concatenate([c[:self.n], np.empty(new - self.n, c.dtype)]) for c in self._cols]

    def _run(self, first: int, n: int, end: int, now: bool) -> None:
        a = self._act
        self._reserve(n + int(now))
        cs, ss = (a._cs, a._ss) if a._rs is None else (a._rc, a._rs)  # noqa: SLF001 - the actuator's own records
        self.n = int(_trace_ticks(cs, ss, first, n, int(a._c.tick_ns), end, self.n, now, *self._cols))  # noqa: SLF001

    def record_now(self) -> None:
        """Record the state as it is now (wherever it is: the start of a run)."""
        t = self._act.t_ns
        self._run(t, 0, t, True)

    def step_ns(self, dt_ns: int) -> None:
        """Advance the actuator ``dt_ns`` [ns] (as :meth:`Actuator.step_ns`), recording the state at every tick
        instant passed (``t_ns`` a multiple of the loop period, after the start, up to and including the end)."""
        dt_ns = int(dt_ns)
        if dt_ns < 0:
            raise ValueError(f"dt: expected a duration >= 0 ns, got {dt_ns!r}")
        tick = int(self._act._c.tick_ns)  # noqa: SLF001
        t = self._act.t_ns
        end = t + dt_ns
        first = (t // tick + 1) * tick
        self._run(first, (end - first) // tick + 1 if first <= end else 0, end, False)

    def states(self) -> np.ndarray:
        """The recorded states (:data:`TRACE_DTYPE`), in time order."""
        out = np.empty(self.n, TRACE_DTYPE)
        for name, col in zip(TRACE_DTYPE.names, self._cols):
            out[name] = col[:self.n]
        return out


def _torque_constant_q(c: _Coeffs, i_q, T_h):
    """K_t_q [N*m/A] at the magnet temperature and (with ``effects.kt_saturation``) the current: the one
    formula behind ``torque_em``/``effort_out`` of :meth:`Actuator.outputs` and :meth:`Actuator.joint_state`."""
    K = c.K_ref * effects.flux_factor(T_h, c.T_ref, c.beta)
    if c.batch or c.k_sat:
        K = K * (effects.saturation_factor if c.batch else kernel._saturation_factor)(i_q, c.k_sat, c.sat_n)  # noqa: SLF001
    return K


def _voltage_saturated(c: _Coeffs, v_magnitude_q):
    """Whether the drive's voltage is on the inverter's limit circle (``voltage_saturated``)."""
    return v_magnitude_q >= c.V_max * (1.0 - 1e-9)


def _outputs(c: _Coeffs, s, winding, ops) -> dict[str, Any]:
    i_d, i_q = s.i.real, s.i.imag
    v_d, v_q = s.v.real, s.v.imag
    # the same effects functions as the kernel; for one actuator their compiled forms (numpy ufuncs on Python
    # floats cost ~1 µs each, and the node calls this every period)
    K = _torque_constant_q(c, i_q, s.T_h)
    theta_e = c.pole_pairs * s.theta
    i_a, i_b, i_c = frames.dq_to_abc(i_d, i_q, theta_e)
    i_A, i_B, i_C = frames.phase_to_line_current(i_a, i_b, i_c, winding)
    v_mag = abs(s.v)
    i_meas = (i_d, i_q)
    if c.has_sensor_error:
        i_meas = (np.vectorize(kernel.measured_current_dq)(i_d, i_q, theta_e, c.sens_off_a, c.sens_off_b,
                                                           c.sens_gain_a, c.sens_gain_b)
                  if c.batch else kernel.measured_current_dq(i_d, i_q, theta_e, c.sens_off_a, c.sens_off_b,
                                                             c.sens_gain_a, c.sens_gain_b))
    # the transmission: the load's angle and speed (the rigid ones when rigid), which encoder position_out reports
    th_m_out, w_m_out = s.theta / c.N, s.omega / c.N
    th_l_out, w_l_out, tau_s_out, defl = th_m_out, w_m_out, K * i_q * c.N * 0.0, 0.0 * th_m_out
    if c.compliant:
        rigid = np.logical_not(c.has_compliance)
        th_l_out = ops.where(rigid, th_m_out, s.theta_l)
        w_l_out = ops.where(rigid, w_m_out, s.omega_l)
        defl = th_m_out - th_l_out
        x = np.sign(defl) * np.maximum(np.abs(defl) - c.bl_half, 0.0) * (np.abs(defl) > c.bl_half)
        tau_s_out = c.k_tr * x + c.c_tr * (w_m_out - w_l_out) * (np.abs(defl) > c.bl_half)
        if not c.batch:
            th_l_out, w_l_out, defl, tau_s_out = float(th_l_out), float(w_l_out), float(defl), float(tau_s_out)
    enc_load = np.logical_and(c.enc_load, c.has_compliance) if c.batch else bool(c.enc_load and c.compliant)
    return {
        "t": s.t_ns * 1e-9,
        "i_d": i_d, "i_q": i_q, "i_q_ref": s.i_ref, "v_d": v_d, "v_q": v_q,
        "v_limit_q": c.V_max, "v_magnitude_q": v_mag, "bus_voltage": c.V_bus,
        "voltage_saturated": _voltage_saturated(c, v_mag),
        "omega": s.omega, "theta": s.theta,
        "position_out": ops.where(enc_load, th_l_out, th_m_out), "velocity_out": ops.where(enc_load, w_l_out, w_m_out),
        "position_motor_out": th_m_out, "velocity_motor_out": w_m_out,   # the rotor's angle / N
        "position_load_out": th_l_out, "velocity_load_out": w_l_out,     # the load's (= the rotor's / N when rigid)
        "transmission_deflection_out": defl, "transmission_torque_out": tau_s_out,
        "torque_em": K * i_q, "effort_out": K * i_q * c.N,
        "i_phase_a": i_a, "i_phase_b": i_b, "i_phase_c": i_c,
        "i_line_a": i_A, "i_line_b": i_B, "i_line_c": i_C,
        "T_winding": s.T_w, "T_housing": s.T_h,
        "resistance_phase": effects.resistance_at(c.R_ref, s.T_w, c.T_ref, c.alpha),
        "joule_power": effects.resistance_at(c.R_ref, s.T_w, c.T_ref, c.alpha) * abs(s.i) ** 2,
        "i_d_measured": i_meas[0], "i_q_measured": i_meas[1],
        "current_limit_effective": ops.where(s.tripped, 0.0, c.I_lim * (
            effects.derate_scale if c.batch else kernel._derate_scale)(s.T_w, c.T_derate, c.T_trip)),  # noqa: SLF001
        "tripped": s.tripped,
    }


class BatchActuator(_Base):
    """Many actuators (or one actuator under many parameter sets) stepped together (one compiled call).

    All share the controller rate; every other parameter may differ. Commands are arrays (or scalars).
    """

    _batch = True

    def __init__(self, params: Sequence[ActuatorParams], *, warn: bool = True):
        """``warn``: as :class:`Actuator` does, a ``ParameterWarning`` where the motor can outrun a complex-vector
        current loop, once per distinct warning among the sets; False where the caller has said it already or
        checks the speeds it simulates itself (the diagnosis's window replays)."""
        self.params = list(params)
        if not self.params:
            raise ValueError("BatchActuator needs at least one parameter set")
        if warn:
            warn_current_loop(self.params)
        T_w0 = np.array([p.thermal.initial_winding_temperature for p in self.params])
        T_h0 = np.array([p.thermal.initial_housing_temperature for p in self.params])
        self._init_kernel(self.params, T_w0, T_h0)
        self._winding = np.array([p.motor.winding for p in self.params])

    def __len__(self) -> int:
        return len(self.params)

    def set_state(self, *, i_d, i_q, omega, theta, T_winding, T_housing, v_d=0.0, v_q=0.0, z_d=0.0, z_q=0.0,
                  i_q_ref=0.0, theta_load_out=None, omega_load_out=None) -> None:
        """Set the state of every element (arrays of length ``len(self)`` or scalars), e.g. to start
        simulation windows from measured states (multiple shooting). The command is set to ``i_q_ref``. The load
        behind a compliant transmission (output side) at ``theta_load_out``/``omega_load_out``; None: where a rigid
        transmission would hold it (``theta/N`` less the static deflection under the constant load, ``omega/N``)."""
        n = len(self)
        arr = lambda x: np.broadcast_to(np.asarray(x, dtype=float), (n,)).copy()  # noqa: E731
        s = self._set
        s("i", arr(i_d) + 1j * arr(i_q))
        s("omega", arr(omega))
        s("theta", arr(theta))
        s("T_w", arr(T_winding))
        s("T_h", arr(T_housing))
        s("v", arr(v_d) + 1j * arr(v_q))
        s("v_next", arr(v_d) + 1j * arr(v_q))
        s("v_prev", arr(v_d) + 1j * arr(v_q))
        s("z", arr(z_d) + 1j * arr(z_q))
        s("i_ref", arr(i_q_ref))
        s("cmd_q", arr(i_q_ref))
        s("acc", np.zeros(n))
        s("v_mode", False)
        self._seat_load()
        if theta_load_out is not None:
            s("theta_l", arr(theta_load_out))
        if omega_load_out is not None:
            s("omega_l", arr(omega_load_out))

    def update_params(self, params: Sequence[ActuatorParams]) -> None:
        """Replace every element's parameters (same count); the states carry on (see :meth:`Actuator.update_params`)."""
        params = list(params)
        if len(params) != len(self):
            raise ValueError(f"params: expected {len(self)} parameter sets, got {len(params)}")
        was = np.asarray(self._c.has_compliance, dtype=bool)
        warn_current_loop([p for p, q in zip(params, self.params) if p.drive != q.drive or p.motor != q.motor])
        self.params = params
        self._new_coeffs(params)
        self._winding = np.array([p.motor.winding for p in params])
        self._seat_load(only_new=np.logical_not(was))

    def reset_fault(self, index: int | None = None) -> np.ndarray:
        """Clear the latched over-temperature trip of element ``index`` (all if None); returns the trip flags
        as they were."""
        was = np.asarray(self._get("tripped"), dtype=bool)
        now = was.copy()
        now[slice(None) if index is None else index] = False
        self._set("tripped", now)
        return was

    def field(self, name: str) -> np.ndarray:
        """One raw kernel state field over the batch (a copy): ``i`` (complex ``i_d + j i_q`` [A]),
        ``omega`` [rad/s], ``theta`` [rad], ``T_w``/``T_h`` [°C], ``v``/``z`` (complex [V]), ``i_ref`` [A], ...
        (:data:`kernel.STATE_DTYPE`). Cheaper than :meth:`outputs` inside a stepping loop."""
        if name not in STATE_DTYPE.names:
            raise KeyError(f"field: expected one of {', '.join(STATE_DTYPE.names)}, got {name!r}")
        return self._get(name)

    def set_current_command(self, i_q_ref) -> None:
        if not (isinstance(i_q_ref, np.ndarray) and i_q_ref.shape == (len(self),)):   # (the coupling's hot path)
            i_q_ref = np.broadcast_to(np.asarray(i_q_ref, dtype=float), (len(self),))
        self._set("cmd_q", i_q_ref)
        self._set("v_mode", False)

    def set_torque_command(self, tau_out) -> None:
        self._set("cmd_q", np.broadcast_to(self._torque_to_current(np.asarray(tau_out, dtype=float)), (len(self),)))
        self._set("v_mode", False)

    def set_load_torque(self, tau_out) -> None:
        self._set("tau_ext_out", np.broadcast_to(np.asarray(tau_out, dtype=float), (len(self),)))

    def outputs(self) -> dict[str, np.ndarray]:
        out = _outputs(self._c, self._view(), "wye", _ArrayOps)
        # line currents depend on each actuator's winding
        delta = self._winding == "delta"
        if np.any(delta):
            la, lb, lc = frames.phase_to_line_current(out["i_phase_a"], out["i_phase_b"], out["i_phase_c"], "delta")
            for key, val in zip(("i_line_a", "i_line_b", "i_line_c"), (la, lb, lc)):
                out[key] = np.where(delta, val, out[key])
        return out


STATE_FIELDS = tuple(f.name for f in fields(ActuatorState))
