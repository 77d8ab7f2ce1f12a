"""Optional physics terms: ONE implementation of each equation, shared by the simulator and diagnosis.

Every function accepts Python floats or numpy arrays (broadcasting) and is pure. Torques are at the
motor side unless the name says ``_out``. Friction and cogging are written as a *basis* (regressor
columns) times coefficients, so the model evaluates ``basis @ coefficients`` and the diagnosis fits
the same columns by least squares.
"""

from __future__ import annotations

import numpy as np


# -- friction -------------------------------------------------------------------------------------

def friction_magnitude(direction, speed, coulomb, asymmetry, stribeck, stribeck_velocity):
    """Kinetic friction magnitude ``F(ω) = max(0, τ_c + d·τ_asym + τ_s·exp(-(ω/ω_s)²))`` [N·m].

    ``direction`` d = sign(ω) (±1; at rest the direction the rotor is pushed), ``speed`` = |ω| [rad/s].
    At ``speed = 0`` this is the breakaway (static) friction. Floats, arrays, and compiled kernel code.
    """
    value = coulomb + direction * asymmetry + stribeck * np.exp(-(speed / stribeck_velocity) ** 2)
    return np.maximum(value, 0.0)


def gear_load_friction(transmitted_torque, coefficient):
    """Friction of a gear that grows with the torque it transmits: ``μ |τ_m|`` [N·m] added to the kinetic AND
    static friction magnitude (:func:`friction_magnitude`), ``τ_m`` = the motor's electromagnetic torque
    ``K i_q`` [N·m, motor side], ``coefficient`` = μ [-] (dimensionless, the same number at the motor or the
    output side: both torques scale by the gear ratio). The load-dependent friction of Rhoban's BAM ("Extended
    friction models for the physics simulation of servo actuators", Duclusaud, Passault et al. 2024, model M3:
    ``τ_fm = K_c + K_v|ω| + K_l |τ_gearbox|``), with the gear's torque taken as the motor's: see
    :mod:`bldc_actuator.diagnosis.effects.torque_dependent_gear_friction` for the choice."""
    return coefficient * np.abs(transmitted_torque)


def friction_basis(omega, stribeck_velocity, smoothing_velocity=0.0):
    """Regressor columns of the friction torque for fitting: ``τ_f = basis @ [τ_c, τ_asym, τ_s]``.

    Columns: ``s``, ``|s|`` (= 1 where moving; the asymmetry multiplies sign·direction = 1), and
    ``s·exp(-(ω/ω_s)²)`` with ``s = sign(ω)`` (or ``tanh(ω/ω_ε)`` when ``smoothing_velocity`` > 0, which
    a fit on noisy velocity needs). The model's :func:`friction_magnitude` times ``sign(ω)`` equals
    ``basis @ coefficients`` wherever the magnitude is positive.
    """
    omega = np.asarray(omega, dtype=float)
    s = np.tanh(omega / smoothing_velocity) if smoothing_velocity > 0 else np.sign(omega)
    return np.column_stack([s, np.abs(s), s * np.exp(-(omega / stribeck_velocity) ** 2)])


def viscous_basis(omega):
    """Columns ``ω`` and ``ω·|ω|`` (viscous and aerodynamic/iron drag)."""
    omega = np.asarray(omega, dtype=float)
    return np.column_stack([omega, omega * np.abs(omega)])


# -- angle-periodic torques -----------------------------------------------------------------------

def cogging_torque(theta, order, cos_coeffs, sin_coeffs):
    """``τ_cog(θ) = Σ_k a_k cos(k N_c θ) + b_k sin(k N_c θ)`` [N·m], θ the rotor mechanical angle [rad].

    ``cos_coeffs``/``sin_coeffs`` are sequences (harmonic k = 1..n); for a batch, each entry may be an
    array over actuators. ``order`` = N_c (0 disables).
    """
    base = np.asarray(order) * theta
    total = 0.0 * base
    for k, (a, b) in enumerate(zip(cos_coeffs, sin_coeffs), start=1):
        total = total + a * np.cos(k * base) + b * np.sin(k * base)
    return total


def cogging_torque_mean(theta_start, dtheta, order, cos_coeffs, sin_coeffs):
    """Mean of :func:`cogging_torque` while θ sweeps uniformly from ``theta_start`` by ``dtheta`` [N·m].

    Each harmonic averages to its value at the mid angle times ``sinc(k N_c Δθ / 2)``; this keeps a
    simulation step accurate when it spans a good part of a cogging period (fast rotation). Scalar angles
    (the simulator's kernel, compiled); ``cos_coeffs``/``sin_coeffs`` are sequences over k = 1..n.
    """
    base = order * (theta_start + 0.5 * dtheta)
    half = 0.5 * order * dtheta
    total = 0.0 * theta_start
    for j in range(len(cos_coeffs)):
        k = j + 1.0
        x = k * half
        sinc = np.sin(x) / x if abs(x) > 1e-8 else 1.0 - x * x / 6.0
        total = total + sinc * (cos_coeffs[j] * np.cos(k * base) + sin_coeffs[j] * np.sin(k * base))
    return total


def angle_harmonic_basis(theta, order, n_harmonics=1):
    """Columns ``cos(k N θ), sin(k N θ)`` for k = 1..n: the basis of :func:`cogging_torque` (and of
    electrical-angle ripple with ``N = pole_pairs``)."""
    theta = np.asarray(theta, dtype=float)
    cols = []
    for k in range(1, n_harmonics + 1):
        cols += [np.cos(k * order * theta), np.sin(k * order * theta)]
    return np.column_stack(cols)


def position_load_torque_out(theta_out, constant, gravity, gravity_phase, stiffness, spring_zero):
    """External load at the output ``τ_0 + τ_g sin(θ_out + φ_g) + k (θ_out - θ_k)`` [N·m]."""
    return constant + gravity * np.sin(theta_out + gravity_phase) + stiffness * (theta_out - spring_zero)


# -- temperature dependence -----------------------------------------------------------------------

def resistance_at(r_ref, temperature, reference_temperature, alpha, enabled=True):
    """Copper resistance ``R(T) = R_ref (1 + α (T - T_ref))`` [Ω]; α = 0.00393 /K for copper."""
    if not enabled:
        return r_ref + 0.0 * temperature
    return r_ref * (1.0 + alpha * (temperature - reference_temperature))


def flux_factor(temperature, reference_temperature, beta, enabled=True):
    """Magnet flux (K_t_q = K_b_q) relative to its reference value: ``1 + β (T - T_ref)``, β < 0."""
    if not enabled:
        return 1.0 + 0.0 * temperature
    return 1.0 + beta * (temperature - reference_temperature)


# -- drive protection -------------------------------------------------------------------------------

def derate_scale(winding_temperature, derate_temperature, trip_temperature):
    """Thermal derating of the current limit [0..1]: 1 up to ``derate_temperature``, falling linearly to 0
    at ``trip_temperature`` [°C] (where the drive trips and latches)."""
    x = (trip_temperature - winding_temperature) / (trip_temperature - derate_temperature)
    return np.minimum(np.maximum(x, 0.0), 1.0)


# -- magnetic saturation ----------------------------------------------------------------------------

#: the current the saturation law is read at [A]: K(i) = K (1 - k_sat SAT_REF_CURRENT (|i|/SAT_REF_CURRENT)^n)
SAT_REF_CURRENT = 1.0


def saturation_shape(i_q, n):
    """The saturation law's shape [A]: ``|i_q| (|i_q| / 1 A)^(n - 1)``, so K(i)/K = 1 - k_sat * shape (before the
    floor). :func:`saturation_factor` holds the same expression inline (it is compiled for the kernel, which calls
    no uncompiled helper); the diagnosis's regressor column is built from this one."""
    a = np.abs(i_q)
    return a * (np.maximum(a, 1e-300) / SAT_REF_CURRENT) ** (n - 1.0)


def saturation_factor(i_q, k_sat, n=1.0):
    """K(i_q)/K = max(0.2, 1 - k_sat |i_q| (|i_q| / 1 A)^(n - 1)): cross-saturation of the magnet flux by the
    q-axis current [A], a power law in |i_q| with exponent ``n`` (monotone for n > 0; n = 1 is the linear law
    ``1 - k_sat |i_q|`` exactly, the factor (|i|/1 A)^0 being 1.0). ``k_sat`` [1/A] is the fractional drop per
    ampere at 1 A (the drop at a current I is k_sat I (I / 1 A)^(n-1)); the same factor scales torque and
    back-EMF, so the energy exchange stays consistent."""
    a = np.abs(i_q)
    return np.maximum(1.0 - k_sat * a * (np.maximum(a, 1e-300) / SAT_REF_CURRENT) ** (n - 1.0), 0.2)


# -- iron loss -------------------------------------------------------------------------------------

def iron_loss_power(omega, hysteresis, eddy):
    """Iron loss [W] at rotor speed ω [rad/s]: hysteresis ``τ_h |ω|`` + eddy currents ``c_e ω²``; the drag torque
    is ``τ_h sign(ω) + c_e ω`` (the simulator adds it to friction and damping) and the power heats the stator."""
    return hysteresis * np.abs(omega) + eddy * omega * omega


# -- current sensors -------------------------------------------------------------------------------

def phase_current_measurement(i_a, i_b, offset_a, offset_b, gain_a, gain_b):
    """What a drive with two phase-current sensors measures [A]: ``a' = g_a a + o_a``, ``b' = g_b b + o_b``,
    ``c' = -(a' + b')``. Its controller transforms these to d-q: an offset gives ripple at the electrical
    frequency, a gain mismatch at twice it."""
    a_m = gain_a * i_a + offset_a
    b_m = gain_b * i_b + offset_b
    return a_m, b_m, -(a_m + b_m)


# -- inverter dead time ------------------------------------------------------------------------------

def dead_time_winding_error(i_a, i_b, i_c, di_a, di_b, di_c, dead_time_voltage, delta, leg_gain, band=0.0):
    """Voltage error each winding receives from the inverter's dead time [V], averaged over an interval, from the
    winding currents ``i_a, i_b, i_c`` [A] at its start and the change ``di_*`` [A] the other voltages would
    make over it (``delta`` non-zero for a delta winding, zero for wye).

    Each inverter leg drives one lead and its output falls short against the line current it carries:
    ``e_K = -V_dt sign(i_K)``, ``V_dt = t_d f_pwm V_bus`` [V]. Wye: the line current is the winding current and
    each winding sees its leg's error (the neutral's common shift is zero-sequence and drives no current). Delta
    (winding a between leads A and B, b between B and C, c between C and A): the line currents are
    ``i_A = i_a - i_c``, ``i_B = i_b - i_a``, ``i_C = i_c - i_b`` and each winding sees the difference of its two
    legs' errors, ``Δv_a = e_A - e_B``, ``Δv_b = e_B - e_C``, ``Δv_c = e_C - e_A`` (summing to zero round the
    loop: no circulating current).

    ``band`` [A] > 0: within a switching period a line current smaller than its ripple (or than the current
    loop's sample-to-sample chatter) changes sign, and the leg's error averages to a value proportional to the
    current: ``e_K = -V_dt clip(i_K / band, -1, 1)`` (linear inside the band, the full ``V_dt`` outside).
    ``band = 0``: the ideal sign.

    Over a finite interval (``leg_gain`` [A/V] > 0: the change of a line current per volt of its own leg's
    error over the interval) the error is taken at the interval's end, where it is stable for any interval:
    band 0: a line current that would cross zero under the full error is clamped there (the Filippov average of
    the sign): the leg's error is only what brings ``i_K + di_K`` to zero, at most ``V_dt``; a current that stays
    on its side gets the full ``-V_dt sign(i_K)``. Band > 0: ``e = -V_dt clip((i_K + di_K + leg_gain e)/band)``,
    i.e. ``-V_dt x / (band + V_dt leg_gain)`` for ``|x| = |i_K + di_K| <= band + V_dt leg_gain``, else the full
    error; ``band`` -> 0 gives the clamp. ``leg_gain = 0``: the error at the start current."""
    if delta:
        i_A, i_B, i_C = i_a - i_c, i_b - i_a, i_c - i_b
        d_A, d_B, d_C = di_a - di_c, di_b - di_a, di_c - di_b
    else:
        i_A, i_B, i_C = i_a + 0.0, i_b + 0.0, i_c + 0.0
        d_A, d_B, d_C = di_a + 0.0, di_b + 0.0, di_c + 0.0
    V = dead_time_voltage
    if band > 0.0:
        s = band + V * leg_gain
        e_A = -V * np.minimum(np.maximum((i_A + d_A) / s, -1.0), 1.0)
        e_B = -V * np.minimum(np.maximum((i_B + d_B) / s, -1.0), 1.0)
        e_C = -V * np.minimum(np.maximum((i_C + d_C) / s, -1.0), 1.0)
    else:
        e_A, e_B, e_C = -V * np.sign(i_A), -V * np.sign(i_B), -V * np.sign(i_C)
        if leg_gain > 0.0:
            # crosses (or starts at) zero under the full error -> the error that ends it at zero, within +-V_dt
            x_A, x_B, x_C = (i_A + d_A + leg_gain * e_A) * e_A >= 0.0, (i_B + d_B + leg_gain * e_B) * e_B >= 0.0, \
                (i_C + d_C + leg_gain * e_C) * e_C >= 0.0
            e_A = e_A + x_A * (np.minimum(np.maximum(-(i_A + d_A) / leg_gain, -V), V) - e_A)
            e_B = e_B + x_B * (np.minimum(np.maximum(-(i_B + d_B) / leg_gain, -V), V) - e_B)
            e_C = e_C + x_C * (np.minimum(np.maximum(-(i_C + d_C) / leg_gain, -V), V) - e_C)
    if delta:
        return e_A - e_B, e_B - e_C, e_C - e_A
    return e_A, e_B, e_C
