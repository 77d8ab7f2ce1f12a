"""Parameter schema of the actuator: dataclasses, SI units, explicit reference frames.

One schema serves Python, the ROS node (flat dotted parameter names such as ``motor.phase_resistance``)
and the YAML parameter files (``/**/bldc_actuator: ros__parameters:`` layout).

Electrical quantities are q-axis quantities of the power-invariant d-q transform of the *winding*
(phase) quantities, so that ``P_joule = R_phase (i_d^2 + i_q^2)`` and ``v_d i_d + v_q i_q`` is the
electrical power. Datasheet values with their own frames can be given in a ``datasheet`` block and are
converted by :mod:`bldc_actuator.frames` (see :func:`motor_from_datasheet`).

Temperatures are in degC; angles in rad; the motor side is the rotor, the output side is after the gear.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping

INF = math.inf

#: node name key for parameter files; ``/**`` makes it match any namespace and remapped node names
YAML_NODE_KEY = "/**/bldc_actuator"


class ParameterError(ValueError):
    """A parameter is missing, of the wrong type or out of range. ``field`` names it (dotted)."""

    def __init__(self, field_name: str, message: str):
        super().__init__(f"{field_name}: {message}")
        self.field = field_name


class ParameterWarning(UserWarning):
    """A value outside a field's usual (sanity) range: accepted, since real systems have such values, but
    worth a look (a unit slip is the common cause)."""


def _limits(lo: float, hi: float, lo_open: bool, unit: str) -> tuple[float, float, bool]:
    """The physical limits implied by a sanity range: its sign constraints only (a resistance, inertia or
    friction cannot be negative; a field bounded above by 0 cannot be positive); temperatures above absolute
    zero. Everything else the sanity range says is a warning, not a refusal."""
    h_lo = 0.0 if lo >= 0 else (-273.15 if unit == "degC" else -INF)
    h_hi = 0.0 if hi <= 0 else INF
    return h_lo, h_hi, bool(lo >= 0 and (lo_open or lo > 0))


def _p(default, unit: str, description: str, lo: float = -INF, hi: float = INF, *,
       runtime: bool = False, lo_open: bool = False, choices: tuple = (), limits: tuple | None = None):
    """Field with metadata: unit, description, usual range (sanity: outside it warns), physical limits (outside
    them is an error; derived from the range's sign constraints unless ``limits`` = (lo, hi, lo_open) is given),
    whether it may change at run time."""
    meta = {"unit": unit, "description": description, "range": (lo, hi), "lo_open": lo_open,
            "runtime": runtime, "choices": choices, "limits": limits or _limits(lo, hi, lo_open, unit)}
    if isinstance(default, (list, tuple)):
        return field(default_factory=lambda d=tuple(default): d, metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class MotorParams:
    """q-axis ("brushed" equivalent) model of a non-salient PMSM, L_d = L_q.

    Electrical: ``L_q di_q/dt = v_q - R_phase i_q - p ω L_q i_d - K_t_q ω`` and
    ``L_q di_d/dt = v_d - R_phase i_d + p ω L_q i_q``; torque ``τ = K_t_q i_q`` (K_t_q = K_b_q in SI).
    """

    winding: str = _p("wye", "", "winding connection: wye or delta (sets the SVPWM voltage limit)",
                      choices=("wye", "delta"))
    pole_pairs: int = _p(21, "", "magnet pole pairs p (theta_e = p theta)", 1, 200)
    phase_resistance: float = _p(0.17, "ohm", "R_phase: resistance of one winding at reference_temperature "
                                 "(= q-axis resistance)", 0.0, 100.0, lo_open=True)
    q_inductance: float = _p(5.7e-5, "H", "L_q = L_d = L_s - M: q-axis inductance (power-invariant, winding frame)",
                             0.0, 1.0, lo_open=True)
    torque_constant_q: float = _p(0.091, "N*m/A", "K_t_q = K_b_q [V*s/rad]: torque per q-axis ampere "
                                  "(power-invariant), motor side", 0.0, 100.0, lo_open=True)
    rotor_inertia: float = _p(6.0e-5, "kg*m^2", "J: inertia seen by the rotor (rotor + gear + load reflected "
                              "to the motor side)", 0.0, 100.0, lo_open=True)
    viscous_damping: float = _p(1.0e-5, "N*m*s/rad", "b: viscous friction at the motor side", 0.0, 100.0)
    reference_temperature: float = _p(25.0, "degC", "temperature at which phase_resistance and "
                                      "torque_constant_q hold", -60.0, 250.0)
    resistance_temperature_enabled: bool = _p(True, "", "copper resistance rises with winding temperature")
    copper_temperature_coefficient: float = _p(0.00393, "1/K", "alpha_Cu: R = R_ref (1 + alpha (T_w - T_ref))",
                                               0.0, 0.01)
    magnet_temperature_enabled: bool = _p(False, "", "magnet flux (K_t_q = K_b_q) falls with rotor temperature")
    magnet_temperature_coefficient: float = _p(-0.0012, "1/K", "beta: K = K_ref (1 + beta (T_magnet - T_ref)); "
                                               "NdFeB about -0.0012", -0.01, 0.0)


@dataclass(frozen=True)
class DriveParams:
    """Field-oriented drive: discrete d/q PI current loop, SVPWM inverter, limits, thermal protection."""

    bus_voltage: float = _p(24.0, "V", "DC bus voltage V_bus", 0.0, 1000.0, runtime=True, lo_open=True)
    current_limit: float = _p(20.0, "A", "limit on |i_q_ref| (q-axis A)", 0.0, 1000.0, runtime=True, lo_open=True)
    current_loop_rate: float = _p(10000.0, "Hz", "rate of the discrete current controller; also the physics "
                                  "sub-step (voltage is held between ticks)", 1000.0, 200000.0)
    current_loop_bandwidth: float = _p(1000.0, "Hz", "closed-loop bandwidth the PI gains are tuned for "
                                       "(K_p = 2 pi f L_q, K_i = 2 pi f R_phase)", 1.0, 20000.0)
    decoupling_enabled: bool = _p(True, "", "feed-forward of the omega*L cross-coupling and back-EMF, "
                                  "j (p omega L_ctl i + K_ctl omega) [V], added to the PI output (pi) or to the "
                                  "disturbance estimate (complex_vector: motulator's u_ff, which its "
                                  "CurrentVectorController leaves at 0)")
    current_controller: str = _p("pi", "", "the current controller's law: pi (d/q PI, K_p = 2 pi f L_q, K_i = 2 pi "
                                 "f R_phase, back-calculation anti-windup) or complex_vector (2DOF complex-vector PI "
                                 "as motulator's CurrentVectorController: active resistance and reference gain "
                                 "a L_q with a = 2 pi f, integrator (a + j p omega)/s driven by the realized "
                                 "voltage, the mean of the previous and ongoing periods' voltages rotated back by "
                                 "the present angle; K_i unused; in the steady state the current falls short of "
                                 "its reference by (1 - cos(p omega T_c/2)) |v| / (a L_q) [A])",
                                 choices=("pi", "complex_vector"))
    controller_resistance: float = _p(0.0, "ohm", "R_phase the drive's current loop is tuned with (K_i = 2 pi f R): "
                                      "what the drive believes, not the motor's; 0 = motor.phase_resistance",
                                      0.0, 100.0)
    controller_inductance: float = _p(0.0, "H", "L_q the drive's current loop is tuned with (K_p = 2 pi f L) and "
                                      "feeds forward (p omega L i); 0 = motor.q_inductance", 0.0, 1.0)
    controller_torque_constant: float = _p(0.0, "N*m/A", "K_b_q (q-axis, power-invariant) of the drive's back-EMF "
                                           "feed-forward (K omega); 0 = motor.torque_constant_q", 0.0, 100.0)
    derate_temperature: float = _p(100.0, "degC", "winding temperature where the current limit starts to "
                                   "fall linearly", -40.0, 300.0, runtime=True)
    trip_temperature: float = _p(120.0, "degC", "winding temperature where the drive trips (zero current, "
                                 "latched until reset)", -40.0, 300.0, runtime=True)
    modulation_limit: float = _p(1.0, "1", "m: |v_dq| <= m x the SVPWM limit of the winding (a drive's duty cap, "
                                 "e.g. 0.9); 1 = full SVPWM", 0.0, 1.0, lo_open=True,
                                 limits=(0.0, 1.0, True))
    current_sensor_offset_a: float = _p(0.0, "A", "offset of the phase-a current sensor (the controller acts on "
                                        "the measured current: ripple at the electrical frequency)", -100.0, 100.0)
    current_sensor_offset_b: float = _p(0.0, "A", "offset of the phase-b current sensor (c = -(a + b))",
                                        -100.0, 100.0)
    current_sensor_gain_a: float = _p(1.0, "1", "gain of the phase-a current sensor (a mismatch between the "
                                      "phases gives ripple at twice the electrical frequency)", 0.5, 1.5)
    current_sensor_gain_b: float = _p(1.0, "1", "gain of the phase-b current sensor", 0.5, 1.5)
    dead_time: float = _p(0.0, "s", "inverter dead time t_d: each leg's average voltage falls short by "
                          "t_d f_pwm V_bus against its line current (wye or delta)", 0.0, 1e-5)
    pwm_frequency: float = _p(20000.0, "Hz", "PWM switching frequency f_pwm (sets the dead-time voltage)",
                              1000.0, 200000.0)
    dead_time_current_band: float = _p(0.0, "A", "line current below which a leg's dead-time error is "
                                       "proportional to the current (the switching ripple, or the current loop's "
                                       "sample-to-sample chatter, reverses it within a period): -V_dt clip(i/band, "
                                       "-1, 1); 0 = the ideal sign", 0.0, 100.0)
    dead_time_sign: str = _p("clamp", "", "when each leg's current direction is taken for its dead-time error: "
                             "clamp (over each plant interval, a line current its own error would drive through "
                             "zero is held there: the Filippov average of the sign, zero-current clamping) or "
                             "period_start (the sign of the line current at the interval's start, held over it, "
                             "as a switching-cycle averaged converter that samples the current direction once "
                             "per control period: the current chatters through zero instead of sticking)",
                             choices=("clamp", "period_start"))
    current_loop_delay: float = _p(0.0, "s", "computation delay: the voltage computed from the sample at a "
                                   "controller tick is applied this long after it (0 .. one loop period)",
                                   0.0, 1e-3)
    voltage_limit_mode: str = _p("proportional", "", "what the drive does when the PI asks for more voltage than "
                                 "the inverter has: proportional (scale the whole d/q vector onto the circle; "
                                 "i_d may go negative), d_priority (keep v_d, v_q gets the rest: ODrive, VESC), "
                                 "q_priority (keep v_q, v_d gets the rest), field_weakening (proportional, plus a "
                                 "negative i_d reference up to field_weakening_current_max)",
                                 choices=("proportional", "d_priority", "q_priority", "field_weakening"))
    field_weakening_current_max: float = _p(0.0, "A", "largest |i_d| the field-weakening regulator commands "
                                            "(voltage_limit_mode field_weakening; the current limit bounds "
                                            "sqrt(i_d^2 + i_q^2))", 0.0, 1000.0)


@dataclass(frozen=True)
class GearParams:
    """Gear and transmission. Rigid by default (``transmission_stiffness = 0`` means rigid: the rotor and the
    output move as one, ``motor.rotor_inertia`` holds the load reflected to the motor side).

    With ``transmission_stiffness`` k > 0 the output is a second mass (``load_inertia`` J_l) behind a torsional
    spring and damper (a shaft, belt, harmonic drive or series-elastic spring), all at the OUTPUT side, with an
    optional dead zone (``backlash``) in the spring's deflection ``delta = theta/N - theta_load``::

        tau_spring_out = k dz(delta) + c d(delta)/dt   (0 inside the dead zone, |delta| <= backlash/2)
        J   d(omega)/dt      = K i_q - ... - tau_spring_out / N       (motor side; motor.rotor_inertia: rotor only)
        J_l d(omega_load)/dt = tau_spring_out - tau_load(theta_load)   (output side; the load.* torques act here)

    Two-mass resonance (rigid-free): ``omega_r = sqrt(k (1/(J N^2) + 1/J_l))``, anti-resonance
    ``omega_a = sqrt(k/J_l)``.
    """

    gear_ratio: float = _p(1.0, "", "N: motor angle / output angle (ideal, lossless gear)", 1.0, 1000.0)
    transmission_stiffness: float = _p(0.0, "N*m/rad", "k: torsional stiffness between the gear and the load, "
                                       "output side; 0 = rigid (no second mass)", 0.0, 1e7)
    transmission_damping: float = _p(0.0, "N*m*s/rad", "c: damping of the transmission spring, output side "
                                     "(acts on the deflection rate; none inside the backlash)", 0.0, 1e5)
    load_inertia: float = _p(0.0, "kg*m^2", "J_load: inertia behind the transmission, output side (with "
                             "transmission_stiffness > 0; motor.rotor_inertia is then the rotor side alone)",
                             0.0, 1e4)
    backlash: float = _p(0.0, "rad", "total width of the dead zone in the transmission's deflection, output side "
                         "(with transmission_stiffness > 0)", 0.0, 0.5)
    encoder_side: str = _p("motor", "", "which angle position/velocity (joint_states, outputs position_out, a "
                           "recording's position channel) report: motor (the rotor encoder, divided by "
                           "gear_ratio) or load (an encoder behind the transmission); the same when rigid",
                           choices=("motor", "load"))


@dataclass(frozen=True)
class ThermalParams:
    """Two-node thermal network: winding <-> housing <-> ambient.

    ``C_w dT_w/dt = P_joule - (T_w - T_h)/R_wh`` and ``C_h dT_h/dt = (T_w - T_h)/R_wh - (T_h - T_a)/R_ha``.
    """

    ambient_temperature: float = _p(25.0, "degC", "ambient temperature T_a", -60.0, 200.0, runtime=True)
    winding_to_housing_resistance: float = _p(1.0, "K/W", "R_wh", 0.0, 1000.0, lo_open=True)
    housing_to_ambient_resistance: float = _p(2.0, "K/W", "R_ha", 0.0, 1000.0, lo_open=True)
    winding_heat_capacity: float = _p(30.0, "J/K", "C_w", 0.0, 1e6, lo_open=True)
    housing_heat_capacity: float = _p(300.0, "J/K", "C_h", 0.0, 1e7, lo_open=True)
    initial_winding_temperature: float = _p(25.0, "degC", "T_w at t = 0", -60.0, 300.0)
    initial_housing_temperature: float = _p(25.0, "degC", "T_h at t = 0", -60.0, 300.0)


@dataclass(frozen=True)
class EffectsParams:
    """Optional physics terms, all off (zero) by default. Torques are at the MOTOR side.

    Friction: ``τ_f = sign(ω)·[τ_c + sign(ω)·τ_asym + τ_s·exp(-(ω/ω_s)^2)]`` with static friction
    ``τ_c + τ_s`` (+asymmetry) at rest (stick-slip handled by the integrator, no bristle state); a geared
    actuator's load-dependent friction adds ``μ |K i_q|`` to both (``gear_load_friction``).
    Cogging: ``τ_cog = Σ_k a_k cos(k N_c θ) + b_k sin(k N_c θ)``.
    """

    coulomb_friction: float = _p(0.0, "N*m", "tau_c: Coulomb friction", 0.0, 100.0)
    friction_asymmetry: float = _p(0.0, "N*m", "tau_asym: added to Coulomb friction for omega > 0, "
                                   "subtracted for omega < 0", -100.0, 100.0)
    stribeck_friction: float = _p(0.0, "N*m", "tau_s: extra static friction decaying with speed", 0.0, 100.0)
    stribeck_velocity: float = _p(0.1, "rad/s", "omega_s: Stribeck velocity", 0.0, 1e4, lo_open=True)
    gear_load_friction: float = _p(0.0, "1", "mu: gear friction growing with the transmitted torque, kinetic and "
                                   "static friction + mu |K i_q| (the motor's electromagnetic torque; BAM's K_l); "
                                   ">= 1 is a self-locking gear", 0.0, 2.0)
    cogging_order: int = _p(0, "", "N_c: cogging periods per mechanical revolution (lcm(slots, 2p)); 0 = off",
                            0, 10000)
    cogging_cos: tuple = _p((), "N*m", "a_k: cosine amplitudes of harmonics k = 1..n of N_c theta")
    cogging_sin: tuple = _p((), "N*m", "b_k: sine amplitudes of harmonics k = 1..n of N_c theta")
    iron_loss_hysteresis: float = _p(0.0, "N*m", "tau_h: hysteresis iron-loss drag (power tau_h |omega|), "
                                     "its heat goes into the winding node", 0.0, 100.0)
    iron_loss_eddy: float = _p(0.0, "N*m*s/rad", "c_e: eddy-current iron-loss drag c_e omega (power c_e omega^2), "
                               "its heat goes into the winding node", 0.0, 100.0)
    kt_saturation: float = _p(0.0, "1/A", "k_sat: magnetic saturation, K(i_q) = K (1 - k_sat |i_q| (|i_q| / 1 A)^(n-1)) "
                              "(floored at 0.2 K) in torque and back-EMF alike: the fractional drop per ampere at "
                              "1 A (n = 1: K (1 - k_sat |i_q|))", 0.0, 1.0)
    kt_saturation_exponent: float = _p(1.0, "1", "n: exponent of the saturation law in |i_q| (1 = linear; real "
                                       "curves 0.5..4)", 0.5, 4.0, limits=(0.0, 16.0, True))


@dataclass(frozen=True)
class LoadParams:
    """External load at the OUTPUT side: ``τ_load = τ_0 + τ_g sin(θ_out + φ_g) + k (θ_out - θ_k)``."""

    load_torque: float = _p(0.0, "N*m", "tau_0: constant load torque at the output (opposes positive motion)",
                            -1e4, 1e4, runtime=True)
    gravity_torque: float = _p(0.0, "N*m", "tau_g: amplitude of a gravity-like load sin(theta_out + phi)",
                               -1e4, 1e4, runtime=True)
    gravity_phase: float = _p(0.0, "rad", "phi_g", -2 * math.pi, 2 * math.pi, runtime=True)
    spring_stiffness: float = _p(0.0, "N*m/rad", "k: spring at the output", 0.0, 1e6, runtime=True)
    spring_zero: float = _p(0.0, "rad", "theta_k: spring rest angle at the output", -1e6, 1e6, runtime=True)


@dataclass(frozen=True)
class ActuatorParams:
    motor: MotorParams = field(default_factory=MotorParams)
    drive: DriveParams = field(default_factory=DriveParams)
    gear: GearParams = field(default_factory=GearParams)
    thermal: ThermalParams = field(default_factory=ThermalParams)
    effects: EffectsParams = field(default_factory=EffectsParams)
    load: LoadParams = field(default_factory=LoadParams)

    def __post_init__(self):
        validate(self)

    # -- convenience -------------------------------------------------------------------------
    def replace(self, **flat: Any) -> "ActuatorParams":
        """Copy with some dotted fields changed, e.g. ``p.replace(**{"drive.bus_voltage": 48.0})``."""
        values = to_flat(self)
        for key, value in flat.items():
            if key not in values:
                raise ParameterError(key, f"unknown parameter (known: {', '.join(sorted(values))})")
            values[key] = value
        return from_flat(values)

    def to_flat(self) -> dict[str, Any]:
        return to_flat(self)


SECTIONS = {f.name: f.default_factory for f in dataclasses.fields(ActuatorParams)}


@dataclass(frozen=True)
class ParameterSpec:
    """One flat parameter: what the ROS node declares and what validation checks."""

    name: str
    type: type
    default: Any
    unit: str
    description: str
    range: tuple[float, float]
    lo_open: bool
    runtime: bool
    choices: tuple
    limits: tuple = (-INF, INF, False)   #: physical limits (lo, hi, lo_open): outside them is an error


def parameter_specs() -> Iterator[ParameterSpec]:
    for section, factory in SECTIONS.items():
        cls = factory
        for f in dataclasses.fields(cls):
            default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
            ftype = {"str": str, "int": int, "float": float, "bool": bool, "tuple": tuple}[str(f.type)]
            m = f.metadata
            yield ParameterSpec(f"{section}.{f.name}", ftype, default, m["unit"], m["description"],
                                m["range"], m["lo_open"], m["runtime"], m["choices"], m["limits"])


SPECS: dict[str, ParameterSpec] = {s.name: s for s in parameter_specs()}


def to_flat(params: ActuatorParams) -> dict[str, Any]:
    out = {}
    for section in SECTIONS:
        sub = getattr(params, section)
        for f in dataclasses.fields(sub):
            out[f"{section}.{f.name}"] = getattr(sub, f.name)
    return out


def _coerce(spec: ParameterSpec, value: Any) -> Any:
    name, unit = spec.name, f" [{spec.unit}]" if spec.unit else ""
    if spec.type is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false"):
            return value.lower() == "true"
        raise ParameterError(name, f"expected true/false, got {value!r}")
    if spec.type is str:
        if not isinstance(value, str):
            raise ParameterError(name, f"expected a string, got {value!r}")
        return value
    if spec.type is tuple:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = (value,)
        try:
            return tuple(float(v) for v in value)
        except (TypeError, ValueError):
            raise ParameterError(name, f"expected a list of numbers{unit}, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        try:
            value = float(value) if spec.type is float else int(value)
        except (TypeError, ValueError):
            raise ParameterError(name, f"expected a number{unit}, got {value!r}") from None
    if spec.type is int:
        if float(value) != int(value):
            raise ParameterError(name, f"expected an integer, got {value!r}")
        return int(value)
    return float(value)


def _interval(lo: float, hi: float, lo_open: bool) -> str:
    return f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if math.isinf(hi) else ']'}"


def check_value(spec: ParameterSpec, value: Any) -> Any:
    """Coerce and check one value against the field's PHYSICAL limits; raise ParameterError naming the field,
    the limits, the usual range and the unit. A value outside the usual range only is accepted
    (:func:`sanity_warnings` lists it)."""
    value = _coerce(spec, value)
    if spec.choices and value not in spec.choices:
        raise ParameterError(spec.name, f"expected one of {', '.join(spec.choices)}, got {value!r}")
    if spec.type in (int, float):
        lo, hi, lo_open = spec.limits
        if not math.isfinite(value) or value > hi or value < lo or (lo_open and value == lo):
            raise ParameterError(spec.name, f"{value!r} is outside {_interval(lo, hi, lo_open)} {spec.unit}".rstrip()
                                 + f" (physical limit; usual range {_interval(*spec.range, spec.lo_open)})")
    return value


def outside_usual_range(spec: ParameterSpec, value: Any) -> bool:
    """True for a number outside the field's usual (sanity) range."""
    if spec.type not in (int, float) or isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    lo, hi = spec.range
    return value > hi or value < lo or (spec.lo_open and value == lo)


def sanity_warnings(params: "ActuatorParams") -> list[str]:
    """Every field whose value lies outside its usual range, in words (accepted: bounds are sanity limits), and
    a complex-vector current loop the motor can outrun (:func:`current_loop_warning`)."""
    out = []
    for name, value in to_flat(params).items():
        spec = SPECS[name]
        if outside_usual_range(spec, value):
            out.append(f"{name} = {value:g} {spec.unit} is outside its usual range "
                       f"{_interval(*spec.range, spec.lo_open)} (accepted; check the unit if unexpected)".replace("  ", " "))
    loop = current_loop_warning(params)
    if loop:
        out.append(loop)
    return out


def current_loop_limit(params: "ActuatorParams"):
    """The stable speed range of the drive's current loop, :class:`.current_loop_stability.SpeedLimit` (the
    eigenvalues of the kernel's tick-to-tick closed loop with its computation delay), for
    ``drive.current_controller: complex_vector``; None for ``pi`` (stable far beyond: not analysed here)."""
    d, m = params.drive, params.motor
    if d.current_controller != "complex_vector":
        return None
    from . import current_loop_stability

    return current_loop_stability.speed_limit(
        pole_pairs=m.pole_pairs, phase_resistance=m.phase_resistance, q_inductance=m.q_inductance,
        controller_inductance=controller_motor(params)[1], bandwidth=d.current_loop_bandwidth,
        rate=d.current_loop_rate, delay=d.current_loop_delay, feedforward=d.decoupling_enabled,
        bus_voltage=d.bus_voltage, winding=m.winding, torque_constant_q=m.torque_constant_q,
        modulation_limit=d.modulation_limit, gear_ratio=params.gear.gear_ratio)


def current_loop_warning(params: "ActuatorParams") -> str | None:
    """In words, when the motor's no-load speed at the bus voltage lies beyond the complex-vector current loop's
    stable range (:func:`current_loop_limit`): the fields, the limit in rad/s and rpm, what to change. Accepted (a
    drive may never run that fast), but a simulation that gets there diverges."""
    lim = current_loop_limit(params)
    return None if lim is None or lim.stable else lim.message()


def from_flat(values: dict[str, Any], *, base: ActuatorParams | None = None) -> ActuatorParams:
    """Build parameters from a flat dotted dict; unknown keys are an error (typos must not pass silently)."""
    merged = to_flat(base) if base is not None else {n: s.default for n, s in SPECS.items()}
    for key, value in values.items():
        if key not in SPECS:
            raise ParameterError(key, "unknown parameter")
        merged[key] = check_value(SPECS[key], value)
    sections: dict[str, dict[str, Any]] = {s: {} for s in SECTIONS}
    for key, value in merged.items():
        section, name = key.split(".", 1)
        sections[section][name] = value
    return ActuatorParams(**{s: SECTIONS[s](**kw) for s, kw in sections.items()})


def validate(params: ActuatorParams) -> None:
    """Range checks of every field plus cross-field consistency."""
    for name, value in to_flat(params).items():
        check_value(SPECS[name], value)
    e, d, g = params.effects, params.drive, params.gear
    if g.transmission_stiffness > 0.0 and not g.load_inertia > 0.0:
        raise ParameterError("gear.load_inertia", f"must be > 0 kg*m^2 with gear.transmission_stiffness "
                             f"{g.transmission_stiffness:g} N*m/rad (the mass behind the spring), got {g.load_inertia:g}")
    if g.transmission_stiffness == 0.0:
        for name, unit in (("load_inertia", "kg*m^2"), ("transmission_damping", "N*m*s/rad"), ("backlash", "rad")):
            if getattr(g, name) != 0.0:
                raise ParameterError(f"gear.{name}", f"{getattr(g, name):g} {unit} needs gear.transmission_stiffness "
                                     f"> 0 N*m/rad (0 = rigid: a rigid load's inertia belongs in motor.rotor_inertia); "
                                     f"expected 0 with a rigid transmission")
    if len(e.cogging_cos) != len(e.cogging_sin):
        raise ParameterError("effects.cogging_sin", f"needs as many entries as effects.cogging_cos "
                             f"({len(e.cogging_cos)}), got {len(e.cogging_sin)}")
    if d.trip_temperature <= d.derate_temperature:
        raise ParameterError("drive.trip_temperature", f"must be above drive.derate_temperature "
                             f"({d.derate_temperature:g} degC), got {d.trip_temperature:g} degC")
    if d.current_loop_delay > 1.0 / d.current_loop_rate * (1 + 1e-9):
        raise ParameterError("drive.current_loop_delay",
                             f"{d.current_loop_delay:g} s is longer than one loop period "
                             f"({1.0 / d.current_loop_rate:g} s at {d.current_loop_rate:g} Hz); expected 0 .. one period")
    if d.current_loop_bandwidth * 2 * math.pi / d.current_loop_rate > 1.0:
        raise ParameterError("drive.current_loop_bandwidth",
                             f"{d.current_loop_bandwidth:g} Hz is too fast for a {d.current_loop_rate:g} Hz loop "
                             f"(need 2*pi*bandwidth/rate <= 1, i.e. <= {d.current_loop_rate / (2 * math.pi):.0f} Hz)")


# -- the drive's model of the motor ----------------------------------------------------------------

#: drive field -> the motor field it stands for when 0 (what the drive's current loop believes about the motor)
CONTROLLER_FIELDS = {"drive.controller_resistance": "motor.phase_resistance",
                     "drive.controller_inductance": "motor.q_inductance",
                     "drive.controller_torque_constant": "motor.torque_constant_q"}


def controller_motor(params: ActuatorParams) -> tuple[float, float, float]:
    """(R_phase [ohm], L_q [H], K_q [V*s/rad]) the drive's current loop is tuned with and feeds forward: the
    ``drive.controller_*`` fields, each 0 standing for the motor's own value."""
    d, m = params.drive, params.motor
    return (d.controller_resistance or m.phase_resistance, d.controller_inductance or m.q_inductance,
            d.controller_torque_constant or m.torque_constant_q)


def keep_controller_of(params: ActuatorParams, nominal: ActuatorParams) -> ActuatorParams:
    """``params`` with the drive's model of the motor pinned to ``nominal``'s: a finding that changes the motor
    (R, L, K) does not retune the recorded drive, which was tuned on the nominal values. Each controller field
    whose effective value differs from ``nominal``'s is set explicitly to it; ``params`` itself when none does."""
    new, old = controller_motor(params), controller_motor(nominal)
    changes = {f: o for f, n, o in zip(CONTROLLER_FIELDS, new, old) if n != o}
    return params.replace(**changes) if changes else params


# -- datasheet block ------------------------------------------------------------------------------

DATASHEET_KEYS = {
    "winding": "wye | delta (unknown is refused here: use `bldc-actuator convert` to see both answers)",
    "terminal_resistance": "ohm, line-to-line (two leads, third floating)",
    "terminal_inductance": "H, line-to-line",
    "kv": "rpm/V, line-to-line peak back-EMF convention (no-load rpm per volt of V_ll peak)",
    "torque_constant": "N*m/A in the frame given by torque_constant_frame",
    "torque_constant_frame": "phase_peak | line_peak | phase_rms | line_rms | q_power_invariant | "
                             "q_amplitude_invariant",
}


def motor_from_datasheet(ds: dict[str, Any]) -> dict[str, Any]:
    """Convert a ``datasheet`` block (values with their frames) to flat ``motor.*`` q-axis values.

    Torque constant given explicitly wins over Kv (Kv is a no-load back-EMF measure); both are reported
    by ``bldc-actuator convert`` when they disagree.
    """
    from . import frames  # local import: frames is the single home of every conversion

    for key in ds:
        if key not in DATASHEET_KEYS:
            raise ParameterError(f"datasheet.{key}", f"unknown datasheet key (known: {', '.join(DATASHEET_KEYS)})")
    winding = ds.get("winding")
    if winding not in ("wye", "delta"):
        raise ParameterError("datasheet.winding", f"expected wye or delta, got {winding!r}")
    out: dict[str, Any] = {"motor.winding": winding}

    def num(key):
        try:
            v = float(ds[key])
        except (TypeError, ValueError):
            raise ParameterError(f"datasheet.{key}", f"expected a number [{DATASHEET_KEYS[key]}], "
                                 f"got {ds[key]!r}") from None
        if not (v > 0 and math.isfinite(v)):
            raise ParameterError(f"datasheet.{key}", f"must be > 0 [{DATASHEET_KEYS[key]}], got {v!r}")
        return v

    if "terminal_resistance" in ds:
        out["motor.phase_resistance"] = frames.phase_resistance_from_terminal(num("terminal_resistance"), winding)
    if "terminal_inductance" in ds:
        out["motor.q_inductance"] = frames.q_inductance_from_terminal(num("terminal_inductance"), winding)
    if "torque_constant" in ds:
        frame = ds.get("torque_constant_frame")
        if frame is None:
            raise ParameterError("datasheet.torque_constant_frame",
                                 f"required with datasheet.torque_constant ({DATASHEET_KEYS['torque_constant_frame']})")
        out["motor.torque_constant_q"] = _value(frames.torque_constant_q_from(num("torque_constant"), frame, winding))
    elif "kv" in ds:
        out["motor.torque_constant_q"] = _value(frames.back_emf_constant_q_from_kv(num("kv"), winding))
    return out


def _value(x):
    return float(getattr(x, "value", x))


# -- YAML -----------------------------------------------------------------------------------------

def flatten_tree(tree: Mapping, prefix: str = "") -> dict[str, Any]:
    """Nested mapping → flat dotted names (``{"motor": {"winding": "wye"}}`` → ``{"motor.winding": "wye"}``)."""
    out = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten_tree(value, name + "."))
        else:
            out[name] = value
    return out


def params_from_dict(tree: dict, *, base: ActuatorParams | None = None) -> ActuatorParams:
    """Nested or flat dict (optionally in the ROS layout) → parameters. A ``datasheet`` block is converted
    first; q-axis values given explicitly override it."""
    if len(tree) == 1:
        (key, value), = tree.items()
        if isinstance(value, dict) and "ros__parameters" in value:
            tree = value["ros__parameters"]
    if "ros__parameters" in tree:
        tree = tree["ros__parameters"]
    flat = flatten_tree(tree)
    datasheet = {k.split(".", 1)[1]: v for k, v in flat.items() if k.startswith("datasheet.")}
    flat = {k: v for k, v in flat.items() if not k.startswith("datasheet.") and k.split(".")[0] in SECTIONS}
    unknown = [k for k in flatten_tree(tree) if k.split(".")[0] not in SECTIONS and not k.startswith("datasheet.")
               and k not in NON_MODEL_KEYS and k.split(".")[0] not in NON_MODEL_SECTIONS]
    if unknown:
        raise ParameterError(unknown[0], f"unknown parameter (sections: {', '.join(SECTIONS)}, datasheet)")
    values = motor_from_datasheet(datasheet) if datasheet else {}
    values.update(flat)
    return from_flat(values, base=base)


#: keys a parameter file may hold for other consumers (the ROS node, ROS itself) — not model parameters
NON_MODEL_KEYS = {"use_sim_time"}
NON_MODEL_SECTIONS = {"node", "preset", "qos_overrides"}


def load_yaml(path: str | Path, *, base: ActuatorParams | None = None) -> ActuatorParams:
    """Load a parameter file (ROS layout ``/**/bldc_actuator: ros__parameters:`` or a plain mapping)."""
    import yaml

    path = Path(path)
    try:
        tree = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        raise ParameterError(str(path), f"YAML parse error at{where}: {exc}") from None
    except OSError as exc:
        raise ParameterError(str(path), f"cannot read parameter file: {exc.strerror}") from None
    if not isinstance(tree, dict):
        raise ParameterError(str(path), "expected a mapping at the top level")
    if len(tree) == 1 and isinstance(next(iter(tree.values())), dict) \
            and "ros__parameters" in next(iter(tree.values())):
        key = next(iter(tree))
        if not (key.endswith("bldc_actuator") or key in ("/**", "**")):
            raise ParameterError(str(path), f"node key {key!r} does not match bldc_actuator "
                                 f"(use {YAML_NODE_KEY!r})")
    try:
        params = params_from_dict(tree, base=base)
    except ParameterError as exc:
        raise ParameterError(exc.field, f"{exc.args[0].split(': ', 1)[1]} (in {path})") from None
    import warnings

    for msg in sanity_warnings(params):
        warnings.warn(f"{path}: {msg}", ParameterWarning, stacklevel=2)
    return params


def yaml_scalar(value: Any) -> str:
    """One YAML scalar as ROS reads it: doubles always carry a '.' in the mantissa (24.0, 6.0e-05)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        text = repr(value)  # PyYAML (YAML 1.1) reads 6e-05 as a string: keep a '.' in the mantissa
        mantissa, e, exponent = text.partition("e")
        if "." not in mantissa and mantissa.lstrip("-").isdigit():
            mantissa += ".0"
        return mantissa + e + exponent
    if isinstance(value, tuple):
        return "[" + ", ".join(yaml_scalar(float(v)) for v in value) + "]"
    return str(value)


def dump_yaml(params: ActuatorParams, path: str | Path | None = None, *, header: str = "") -> str:
    """Write parameters in the node's layout. Doubles always carry a decimal point (ROS needs 24.0, not 24)."""
    lines = [f"# {line}" for line in header.splitlines()]
    lines += [f"{YAML_NODE_KEY}:", "  ros__parameters:"]
    for section in SECTIONS:
        lines.append(f"    {section}:")
        sub = getattr(params, section)
        for f in dataclasses.fields(sub):
            spec = SPECS[f"{section}.{f.name}"]
            value = getattr(sub, f.name)
            if spec.type is float:
                value = float(value)
            comment = f"  # [{spec.unit}] {spec.description}" if spec.unit else f"  # {spec.description}"
            if spec.type is tuple and not value:
                lines.append(f"      {f.name}: []{comment}")
            else:
                lines.append(f"      {f.name}: {yaml_scalar(value)}{comment}")
    text = "\n".join(lines) + "\n"
    if path is not None:
        Path(path).write_text(text)
    return text


def config_dir() -> Path:
    """Directory holding the preset YAML files (source tree, pip install or colcon install)."""
    import sys

    here = Path(__file__).resolve().parent
    candidates = []
    if (here.parent / "package.xml").exists():          # source checkout / editable install
        candidates.append(here.parent / "config")
    # pip install or colcon install: <prefix>/lib/pythonX.Y/site-packages/bldc_actuator → <prefix>/share
    if len(here.parents) > 3:
        candidates.append(here.parents[3] / "share" / "bldc_actuator" / "config")
    candidates.append(Path(sys.prefix) / "share" / "bldc_actuator" / "config")
    try:  # colcon / apt install
        from ament_index_python.packages import get_package_share_directory

        candidates.append(Path(get_package_share_directory("bldc_actuator")) / "config")
    except Exception:  # noqa: BLE001 - ament index absent in a plain pip venv
        pass
    for c in candidates:
        if c.is_dir() and any(c.glob("*.yaml")):
            return c
    raise FileNotFoundError("preset directory not found; looked in: " + ", ".join(map(str, candidates)))


def list_presets() -> list[str]:
    return sorted(p.stem for p in config_dir().glob("*.yaml"))


def load_preset(name_or_path: str | Path) -> ActuatorParams:
    """A preset by name (``ak80_9``) or a path to a parameter file."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") or path.exists():
        return load_yaml(path)
    candidate = config_dir() / f"{name_or_path}.yaml"
    if not candidate.exists():
        raise ParameterError("preset", f"no preset named {name_or_path!r} (have: {', '.join(list_presets())})")
    return load_yaml(candidate)
