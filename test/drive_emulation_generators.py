"""Generated recordings of a drive this project's emulation cannot express (issue #24, symptom 7): a d/q PI current
controller with the back-EMF and cross-coupling feed-forward (as the parameter file says), whose inverse Park
transform advances the angle by ``advance_periods`` sampling periods (PWM delay compensation) while its voltage is
applied ``delay_periods`` after the sample and held in STATOR coordinates for one period. The kernel holds its
voltage in rotor coordinates, so a compensation that does not match the drive's own delay (here 1.5 periods
advance for a voltage applied at once: a mean rotation of (1.5 - 0 - 0.5) p omega T) is a drive it has no form for.
A speed loop (PI) around the current loop, as a speed-controlled drive runs. Written here, independent of the
kernel: the plant is the d/q PMSM (surface magnet, L_d = L_q) integrated in sub-steps with its voltage turning in
rotor coordinates as the rotor turns; logged like the drive logs (its computed voltage, ``command`` timing)."""

from __future__ import annotations

import cmath
import math

import numpy as np

from bldc_actuator import frames, voltage_timing
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.params import ActuatorParams


def speed_reference(duration: float, seed: int, peak: float = 113.0):
    """[rad/s] a seeded four-tone multisine that reverses often (ramped in over 0.3 s), tones summing to ``peak``."""
    rng = np.random.default_rng(seed)
    f = np.array([0.35, 0.9, 2.1, 4.3]) * rng.uniform(0.85, 1.15, 4)
    a = np.array([60.0, 30.0, 15.0, 8.0]) * (peak / 113.0)
    ph = rng.uniform(0, 2 * np.pi, 4)
    return lambda t: min(1.0, t / 0.3) * float(np.sum(a * np.sin(2 * np.pi * f * t + ph)))


def current_steps(duration: float, seed: int, level: float = 4.0):
    """[A] seeded steps of the q current command: levels uniform in +-``level``, each held 40-120 ms."""
    rng = np.random.default_rng(seed + 1000)
    edges, levels, t = [0.0], [0.0], 0.0
    while t < duration:
        t += rng.uniform(0.04, 0.12)
        edges.append(t)
        levels.append(rng.uniform(-level, level))
    edges, levels = np.asarray(edges), np.asarray(levels)
    return lambda t: float(levels[np.searchsorted(edges, t, side="right") - 1])


def record(truth: ActuatorParams, nominal: ActuatorParams, *, duration: float = 20.0, rate: float = 1000.0,
           seed: int = 0, advance_periods: float = 1.5, delay_periods: int = 0, speed_bandwidth_hz: float = 20.0, peak_speed: float = 113.0,
           noise_i: float = 0.03, noise_v: float = 0.02, enc_bits: int = 14, substeps: int = 4,
           steps: bool = False) -> Signals:
    """The speed-controlled drive (tuned with ``nominal``) on the motor ``truth``, logged at ``rate``; with
    ``steps`` the drive is current-commanded instead: seeded steps of the q current command (:func:`current_steps`)."""
    m, d = truth.motor, nominal.drive
    mn = nominal.motor
    p, R, L, K, J, b = m.pole_pairs, m.phase_resistance, m.q_inductance, m.torque_constant_q, m.rotor_inertia, \
        m.viscous_damping
    T = 1.0 / d.current_loop_rate
    h = T / substeps
    a_c = 2 * math.pi * d.current_loop_bandwidth
    Kp, Ki = a_c * mn.q_inductance, a_c * mn.phase_resistance
    V_max = frames.voltage_limit_q(d.bus_voltage, m.winding)
    i_lim = d.current_limit
    wc = 2 * math.pi * speed_bandwidth_hz
    kp_w, ki_w = mn.rotor_inertia * wc / mn.torque_constant_q, mn.rotor_inertia * wc * wc / (4 * mn.torque_constant_q)
    ref = speed_reference(duration, seed, peak_speed)
    steps_of = current_steps(duration, seed) if steps else None
    rng = np.random.default_rng(seed)
    every = int(round(1.0 / (rate * T)))
    n_ticks = int(round(duration / T))
    n = n_ticks // every
    names = ("current_command", "current", "current_d", "position", "velocity", "voltage_q", "voltage_d")
    out = {k: np.zeros(n) for k in names}
    q_enc = 2 * math.pi / 2 ** enc_bits
    i = 0j
    w = th = 0.0
    z = 0j
    z_w = 0.0
    i_cmd = 0.0
    pending = [0j] * delay_periods           # stator-frame voltages waiting to be applied
    prev_pos, k_log = 0.0, 0
    for k in range(n_ticks):
        t = k * T
        if k % every == 0 and k_log < n:          # the logged sample and the speed loop (at the log rate)
            pos = round(th / q_enc) * q_enc
            vel = (pos - prev_pos) * rate if k_log else 0.0
            prev_pos = pos
            if steps_of is not None:
                i_cmd = steps_of(t)
            else:
                e_w = ref(t) - vel
                u = kp_w * e_w + z_w
                i_cmd = min(max(u, -i_lim), i_lim)
                z_w += ki_w / rate * e_w + 0.5 * (i_cmd - u)
        # the current controller at the tick: d/q PI + feed-forward with the drive's own model (nominal)
        err = 1j * i_cmd - i
        v_ff = 1j * (p * w * mn.q_inductance * i + mn.torque_constant_q * w)
        v_un = Kp * err + z + v_ff
        v = v_un * min(1.0, V_max / abs(v_un)) if abs(v_un) > 0 else v_un
        z += Ki * T * err + (v - v_un)
        if k % every == 0 and k_log < n:
            out["current_command"][k_log] = i_cmd
            out["current"][k_log] = i.imag + noise_i * rng.standard_normal()
            out["current_d"][k_log] = i.real + noise_i * rng.standard_normal()
            out["position"][k_log], out["velocity"][k_log] = pos, vel
            out["voltage_q"][k_log] = v.imag + noise_v * rng.standard_normal()
            out["voltage_d"][k_log] = v.real + noise_v * rng.standard_normal()
            k_log += 1
        # inverse Park with the delay compensation's angle advance; applied delay_periods later
        pending.append(v * cmath.exp(1j * (p * th + advance_periods * p * w * T)))
        v_s = pending.pop(0)
        for _ in range(substeps):                 # plant: the stator voltage held, turning in rotor coordinates
            v_r = v_s * cmath.exp(-1j * p * th)
            di = (v_r - (R + 1j * p * w * L) * i - 1j * K * w) / L
            tau = K * i.imag - b * w
            i_mid = i + 0.5 * h * di
            w_mid = w + 0.5 * h * tau / J
            th_mid = th + 0.5 * h * w
            v_r = v_s * cmath.exp(-1j * p * th_mid)
            di = (v_r - (R + 1j * p * w_mid * L) * i_mid - 1j * K * w_mid) / L
            i += h * di
            th += h * w_mid
            w += h * (K * i_mid.imag - b * w_mid) / J
    timing = voltage_timing.declaration(voltage_timing.VoltageTiming(
        "command", voltage_timing.command_offset(T, delay_periods * T)))
    tt = np.arange(n) / rate
    return Signals(tt, out, source="synthetic", meta={"voltage_timing": voltage_timing.from_metadata(
        timing, "drive_emulation_generators")})


def nominal_params(loop_rate: float = 10000.0) -> ActuatorParams:
    """The parameter file of these cases: the project's default motor and drive, the current loop at ``loop_rate``
    (the angle the voltage turns by in one period grows with the period), its bandwidth a tenth of it."""
    return ActuatorParams().replace(**{"drive.current_loop_rate": loop_rate,
                                       "drive.current_loop_bandwidth": loop_rate / 10.0})


def resistance_case(r_ratio: float = 1.3, *, advance_periods: float = 1.5, delay_periods: int = 0,
                    duration: float = 20.0, seed: int = 4, peak_speed: float = 150.0, loop_rate: float = 10000.0):
    """(recording, nominal, truth): the winding resistance ``r_ratio`` x the nominal's, behind that drive."""
    nominal = nominal_params(loop_rate)
    truth = nominal.replace(**{"motor.phase_resistance": nominal.motor.phase_resistance * r_ratio})
    return record(truth, nominal, duration=duration, seed=seed, advance_periods=advance_periods,
                  delay_periods=delay_periods, peak_speed=peak_speed), nominal, truth


def null_case(*, advance_periods: float = 1.5, delay_periods: int = 0, duration: float = 20.0, seed: int = 5,
              peak_speed: float = 150.0, loop_rate: float = 10000.0):
    """(recording, nominal, truth): the motor as the file says, behind that drive."""
    nominal = nominal_params(loop_rate)
    return record(nominal, nominal, duration=duration, seed=seed, advance_periods=advance_periods,
                  delay_periods=delay_periods, peak_speed=peak_speed), nominal, nominal


#: a viscous brake the file knows (J/b = 30 ms): current steps of a few amperes hold the speed below the voltage limit
BRAKE = 0.002


def steps_null_case(*, advance_periods: float = 1.5, delay_periods: int = 0, duration: float = 20.0, seed: int = 6,
                    loop_rate: float = 10000.0):
    """(recording, nominal, truth): current steps into a known viscous brake, the motor as the file says."""
    nominal = nominal_params(loop_rate).replace(**{"motor.viscous_damping": BRAKE})
    return record(nominal, nominal, duration=duration, seed=seed, advance_periods=advance_periods,
                  delay_periods=delay_periods, steps=True), nominal, nominal


def speed_loop_command(nominal: ActuatorParams, duration: float, seed: int, peak_speed: float = 113.0,
                       bandwidth_hz: float = 20.0, rate: float = 1000.0):
    """``command(t, pos, vel)`` -> q current [A]: a PI speed loop at ``rate`` (tuned with ``nominal``) following
    :func:`speed_reference`, for :func:`issue24_generators.record`."""
    m = nominal.motor
    wc = 2 * math.pi * bandwidth_hz
    kp, ki = m.rotor_inertia * wc / m.torque_constant_q, m.rotor_inertia * wc * wc / (4 * m.torque_constant_q)
    ref = speed_reference(duration, seed, peak_speed)
    lim = nominal.drive.current_limit
    z = [0.0]

    def command(t, pos, vel):
        e = ref(t) - vel
        u = kp * e + z[0]
        c = min(max(u, -lim), lim)
        z[0] += ki / rate * e + 0.5 * (c - u)
        return c
    return command


def other_gains_case(r_ratio: float = 1.0, *, bandwidth_hz: float = 250.0, duration: float = 20.0, seed: int = 7):
    """(recording, nominal, truth) through the project's own kernel: a speed-controlled drive whose current loop is
    tuned for ``bandwidth_hz`` while the parameter file says 1000 Hz (a form of the drive the file misstates and no
    drive form the diagnosis tries covers), the winding resistance ``r_ratio`` x the nominal's."""
    import issue24_generators as G

    nominal = ActuatorParams()
    truth = nominal.replace(**{"motor.phase_resistance": nominal.motor.phase_resistance * r_ratio,
                               "drive.current_loop_bandwidth": bandwidth_hz,
                               "drive.controller_resistance": nominal.motor.phase_resistance})
    sig = G.record(truth, speed_loop_command(nominal, duration, seed), duration=duration, seed=seed)
    return sig, nominal, truth
