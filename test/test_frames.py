"""frames.py: transforms, power invariance, winding and datasheet-frame conversions (pure math checks).

Physics checks against a circuit live in test_abc_verification.py.
"""

import math
import pickle

import numpy as np
import pytest

from bldc_actuator import frames as fr

RNG = np.random.default_rng(20240601)
S32 = math.sqrt(1.5)
WINDINGS = ("wye", "delta")


def balanced(amplitude, theta, phase=0.0):
    """Paper eq. phase_currents: x_k = -A sin(theta - k 2pi/3 + phase)."""
    return tuple(-amplitude * np.sin(theta - k * 2 * np.pi / 3 + phase) for k in range(3))


# -- transforms ------------------------------------------------------------------------------------

def test_dq_matrix_is_the_papers_boxed_matrix_and_park_times_clarke():
    th = 0.7321
    paper = math.sqrt(2 / 3) * np.array([
        [math.cos(th), math.cos(th - 2 * math.pi / 3), math.cos(th + 2 * math.pi / 3)],
        [-math.sin(th), -math.sin(th - 2 * math.pi / 3), -math.sin(th + 2 * math.pi / 3)]])
    cols = np.array([fr.abc_to_dq(*e, th) for e in np.eye(3)]).T
    np.testing.assert_allclose(cols, paper, rtol=0, atol=1e-15)
    clarke = math.sqrt(2 / 3) * np.array([[1, -0.5, -0.5], [0, math.sqrt(3) / 2, -math.sqrt(3) / 2]])
    park = np.array([[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]])
    np.testing.assert_allclose(park @ clarke, paper, atol=1e-15)
    cols_c = np.array([fr.clarke(*e) for e in np.eye(3)]).T
    np.testing.assert_allclose(cols_c, clarke, atol=1e-15)
    # orthonormal rows: Q Q^T = I (power invariance)
    np.testing.assert_allclose(paper @ paper.T, np.eye(2), atol=1e-15)


def test_round_trips_arrays():
    n = 1000
    th = RNG.uniform(-20, 20, n)
    d, q = RNG.normal(size=(2, n)) * 10
    a, b, c = fr.dq_to_abc(d, q, th)
    np.testing.assert_allclose(a + b + c, 0.0, atol=1e-12)
    d2, q2 = fr.abc_to_dq(a, b, c, th)
    np.testing.assert_allclose(d2, d, atol=1e-12)
    np.testing.assert_allclose(q2, q, atol=1e-12)
    al, be = fr.clarke(a, b, c)
    np.testing.assert_allclose(np.array(fr.inverse_clarke(al, be)), np.array([a, b, c]), atol=1e-12)
    np.testing.assert_allclose(np.array(fr.inverse_park(*fr.park(al, be, th), th)), np.array([al, be]), atol=1e-12)
    # amplitude invariant
    a3, b3, c3 = fr.dq_to_abc_amplitude_invariant(d, q, th)
    np.testing.assert_allclose(np.array(fr.abc_to_dq_amplitude_invariant(a3, b3, c3, th)), np.array([d, q]),
                               atol=1e-12)
    np.testing.assert_allclose(np.array(fr.inverse_clarke_amplitude_invariant(
        *fr.clarke_amplitude_invariant(a3, b3, c3))), np.array([a3, b3, c3]), atol=1e-12)


def test_scalar_inputs_give_floats():
    d, q = fr.abc_to_dq(1.0, -0.5, -0.5, 0.0)
    assert isinstance(float(d), float) and d == pytest.approx(math.sqrt(1.5)) and q == pytest.approx(0.0, abs=1e-15)


def test_power_invariance_with_and_without_zero_sequence():
    n = 500
    th = RNG.uniform(0, 2 * np.pi, n)
    v = RNG.normal(size=(3, n))
    i = RNG.normal(size=(3, n))
    vd, vq = fr.abc_to_dq(*v, th)
    id_, iq = fr.abc_to_dq(*i, th)
    p_abc = np.sum(v * i, axis=0)
    np.testing.assert_allclose(p_abc, vd * id_ + vq * iq + fr.zero_sequence(*v) * fr.zero_sequence(*i), atol=1e-12)
    # zero-sum (three-wire) currents: zero sequence drops out
    i0 = i - i.mean(axis=0)
    id0, iq0 = fr.abc_to_dq(*i0, th)
    np.testing.assert_allclose(np.sum(v * i0, axis=0), vd * id0 + vq * iq0, atol=1e-12)
    # amplitude-invariant: 3/2 factor
    vd2, vq2 = fr.abc_to_dq_amplitude_invariant(*v, th)
    id2, iq2 = fr.abc_to_dq_amplitude_invariant(*i0, th)
    np.testing.assert_allclose(np.sum(v * i0, axis=0), 1.5 * (vd2 * id2 + vq2 * iq2), atol=1e-12)


def test_commutated_currents_map_to_pure_q():
    th = np.linspace(0, 4 * np.pi, 97)
    amp = 3.7
    d, q = fr.abc_to_dq(*balanced(amp, th), th)
    np.testing.assert_allclose(d, 0.0, atol=1e-13)
    np.testing.assert_allclose(q, S32 * amp, rtol=1e-14)                  # eq. quad_current_conv
    d2, q2 = fr.abc_to_dq_amplitude_invariant(*balanced(amp, th), th)
    np.testing.assert_allclose(q2, amp, rtol=1e-14)                      # amplitude invariant: q = peak
    # and dq_to_abc with d = 0 gives back the paper's commutation pattern
    np.testing.assert_allclose(np.array(fr.dq_to_abc(0.0, S32 * amp, th)), np.array(balanced(amp, th)), atol=1e-13)
    # tab:signals footnote: I_q = sqrt(sum of squared phase currents)
    np.testing.assert_allclose(np.sqrt(np.sum(np.array(balanced(amp, th)) ** 2, axis=0)), q, rtol=1e-14)
    assert fr.dq_power_invariant_from_amplitude_invariant(amp) == pytest.approx(S32 * amp)
    assert fr.dq_amplitude_invariant_from_power_invariant(S32 * amp) == pytest.approx(amp)


def test_angles():
    assert fr.electrical_angle(0.5, 21) == pytest.approx(10.5)
    assert fr.electrical_speed(2.0, 7) == pytest.approx(14.0)
    assert fr.mechanical_speed(14.0, 7) == pytest.approx(2.0)
    assert fr.rpm_to_rad_per_s(60.0) == pytest.approx(2 * math.pi)
    assert fr.rad_per_s_to_rpm(2 * math.pi) == pytest.approx(60.0)


# -- winding relations ------------------------------------------------------------------------------

@pytest.mark.parametrize("winding", WINDINGS)
def test_instantaneous_winding_terminal_round_trips(winding):
    th = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    i_w = np.array(balanced(2.0, th, 0.3))
    i_l = np.array(fr.phase_to_line_current(*i_w, winding))
    np.testing.assert_allclose(i_l.sum(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.array(fr.line_to_phase_current(*i_l, winding)), i_w, atol=1e-12)
    amp_ratio = np.max(np.abs(i_l[0])) / 2.0
    assert amp_ratio == pytest.approx(1.0 if winding == "wye" else math.sqrt(3), rel=1e-3)  # 64 samples
    v_w = np.array(balanced(5.0, th, -0.2))
    v_ll = np.array(fr.line_to_line_from_phase_voltage(*v_w, winding))
    np.testing.assert_allclose(np.array(fr.phase_from_line_to_line_voltage(*v_ll, winding)), v_w, atol=1e-12)


@pytest.mark.parametrize("winding", WINDINGS)
def test_delta_line_currents_lag_winding_currents_by_30_degrees(winding):
    th = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    i_l = np.array(fr.phase_to_line_current(*balanced(1.0, th), winding))
    if winding == "wye":
        np.testing.assert_allclose(i_l, np.array(balanced(1.0, th)), atol=1e-12)
    else:
        np.testing.assert_allclose(i_l, np.array(balanced(math.sqrt(3), th, -np.pi / 6)), atol=1e-12)


@pytest.mark.parametrize("winding", WINDINGS)
def test_amplitude_helpers(winding):
    k = 1 / math.sqrt(3) if winding == "wye" else 1.0
    assert fr.phase_voltage_peak_from_line_to_line_peak(3.0, winding) == pytest.approx(3.0 * k)
    assert fr.line_to_line_voltage_peak_from_phase_peak(3.0 * k, winding) == pytest.approx(3.0)
    j = 1.0 if winding == "wye" else 1 / math.sqrt(3)
    assert fr.phase_current_peak_from_line_peak(2.0, winding) == pytest.approx(2.0 * j)
    assert fr.line_current_peak_from_phase_peak(2.0 * j, winding) == pytest.approx(2.0)


EXPECTED_CURRENT = {  # I_q / I_frame
    ("phase_peak", "wye"): S32, ("phase_peak", "delta"): S32,
    ("phase_rms", "wye"): math.sqrt(3), ("phase_rms", "delta"): math.sqrt(3),
    ("line_peak", "wye"): S32, ("line_peak", "delta"): math.sqrt(0.5),
    ("line_rms", "wye"): math.sqrt(3), ("line_rms", "delta"): 1.0,
    ("q_power_invariant", "wye"): 1.0, ("q_power_invariant", "delta"): 1.0,
    ("q_amplitude_invariant", "wye"): S32, ("q_amplitude_invariant", "delta"): S32,
}
EXPECTED_VOLTAGE = {  # V_q / V_frame
    ("phase_peak", "wye"): S32, ("phase_peak", "delta"): S32,
    ("phase_rms", "wye"): math.sqrt(3), ("phase_rms", "delta"): math.sqrt(3),
    ("ll_peak", "wye"): math.sqrt(0.5), ("ll_peak", "delta"): S32,
    ("ll_rms", "wye"): 1.0, ("ll_rms", "delta"): math.sqrt(3),
    ("q_power_invariant", "wye"): 1.0, ("q_power_invariant", "delta"): 1.0,
    ("q_amplitude_invariant", "wye"): S32, ("q_amplitude_invariant", "delta"): S32,
}


@pytest.mark.parametrize("frame,winding", sorted(EXPECTED_CURRENT))
def test_current_frames(frame, winding):
    f = EXPECTED_CURRENT[frame, winding]
    assert fr.current_q_from(2.0, frame, winding) == pytest.approx(2.0 * f, rel=1e-15)
    assert fr.current_from_q(fr.current_q_from(2.0, frame, winding), frame, winding) == pytest.approx(2.0)


@pytest.mark.parametrize("frame,winding", sorted(EXPECTED_VOLTAGE))
def test_voltage_frames(frame, winding):
    f = EXPECTED_VOLTAGE[frame, winding]
    assert fr.voltage_q_from(2.0, frame, winding) == pytest.approx(2.0 * f, rel=1e-15)
    assert fr.voltage_from_q(fr.voltage_q_from(2.0, frame, winding), frame, winding) == pytest.approx(2.0)
    # back-EMF constants use the same factors
    assert float(fr.back_emf_constant_q_from(0.3, frame, winding)) == pytest.approx(0.3 * f, rel=1e-15)
    assert fr.back_emf_constant_from_q(0.3 * f, frame, winding) == pytest.approx(0.3)


@pytest.mark.parametrize("frame", fr.TORQUE_CONSTANT_FRAMES)
@pytest.mark.parametrize("winding", WINDINGS)
def test_torque_constant_frames_are_consistent_with_current_frames(frame, winding):
    """K_t(frame) * I_frame = tau = K_t^q * I_q for every current frame."""
    kt = 0.2
    conv = fr.torque_constant_q_from(kt, frame, winding)
    assert isinstance(conv, fr.Conversion) and conv.frame == "q_power_invariant" and conv.unit == "N*m/A"
    assert conv.steps and all(isinstance(s, str) for s in conv.steps)
    if frame in fr.CURRENT_FRAMES:
        i_frame = 3.0
        tau = kt * i_frame
        assert float(conv) * fr.current_q_from(i_frame, frame, winding) == pytest.approx(tau, rel=1e-14)
        assert conv.warnings == []
    elif frame == "per_phase_amplitude":
        assert float(conv) == pytest.approx(S32 * kt)                   # eqs. conversion_kt_wye/delta
    else:  # bus
        assert conv.warnings and "operating point" in conv.warnings[0]
        assert float(conv) == pytest.approx(kt * fr.voltage_limit_q(1.0, winding))
    assert fr.torque_constant_from_q(float(conv), frame, winding) == pytest.approx(kt)


@pytest.mark.parametrize("winding", WINDINGS)
def test_torque_constant_phase_peak_is_three_halves_of_per_phase_amplitude(winding):
    # tau = 3/2 Kbar_t^phi Ibar^phi (eq. torqe_simplified): Kt per phase-peak ampere = 3/2 Kbar_t^phi
    kq = 0.1
    assert fr.torque_constant_from_q(kq, "phase_peak", winding) / \
        fr.torque_constant_from_q(kq, "per_phase_amplitude", winding) == pytest.approx(1.5)


@pytest.mark.parametrize("winding", WINDINGS)
def test_amplitude_invariant_drive_kt_is_three_halves_kb(winding):
    kq = 0.0873
    kt_amp = fr.torque_constant_from_q(kq, "q_amplitude_invariant", winding)
    kb_amp = fr.back_emf_constant_from_q(kq, "q_amplitude_invariant", winding)
    assert kt_amp / kb_amp == pytest.approx(1.5)


def test_bus_modulation_scales():
    full = fr.torque_constant_q_from(0.1, "bus", "wye")
    half = fr.torque_constant_q_from(0.1, "bus", "wye", bus_modulation=0.5)
    assert float(half) == pytest.approx(0.5 * float(full))
    with pytest.raises(ValueError, match="bus_modulation"):
        fr.torque_constant_q_from(0.1, "bus", "wye", bus_modulation=1.5)


@pytest.mark.parametrize("winding", WINDINGS)
def test_bus_kt_at_full_modulation_equals_ll_back_emf_constant(winding):
    # lossless at full modulation: V_bus I_bus = tau omega and V_bus = Kbar_b^ll omega -> K_t(bus) = Kbar_b^ll
    k_ll = 0.0777
    assert float(fr.torque_constant_q_from(k_ll, "bus", winding)) == pytest.approx(
        float(fr.back_emf_constant_q_from(k_ll, "ll_peak", winding)), rel=1e-15)


# -- impedances -----------------------------------------------------------------------------------

@pytest.mark.parametrize("winding,fr_r,fr_l", [("wye", 0.5, 0.5), ("delta", 1.5, 1.5)])
def test_terminal_impedance_factors(winding, fr_r, fr_l):
    assert fr.phase_resistance_from_terminal(0.186, winding) == pytest.approx(fr_r * 0.186)
    assert fr.terminal_resistance_from_phase(fr_r * 0.186, winding) == pytest.approx(0.186)
    assert fr.q_inductance_from_terminal(1.2e-4, winding) == pytest.approx(fr_l * 1.2e-4)
    assert fr.terminal_inductance_from_q(fr_l * 1.2e-4, winding) == pytest.approx(1.2e-4)
    arr = np.array([1.0, 2.0])
    np.testing.assert_allclose(fr.phase_resistance_from_terminal(arr, winding), fr_r * arr)
    # electrical time constant is a property of the circuit: L^q / R^phi = L^ll / R^ll
    assert (fr.q_inductance_from_terminal(1.2e-4, winding) / fr.phase_resistance_from_terminal(0.186, winding)
            == pytest.approx(1.2e-4 / 0.186))


def test_q_inductance_from_self_mutual():
    assert fr.q_inductance_from_self_mutual(1e-4, -0.5e-4) == pytest.approx(1.5e-4)


# -- Kv, speed, voltage limit -------------------------------------------------------------------------

def test_kv_to_kb():
    assert fr.back_emf_constant_ll_peak_from_kv(100.0) == pytest.approx(0.09549296585513720, rel=1e-14)
    assert fr.kv_ll_peak_from_back_emf_constant_ll_peak(0.0954929658551372) == pytest.approx(100.0)
    kd = fr.back_emf_constant_q_from_kv(100.0, "delta")
    kw = fr.back_emf_constant_q_from_kv(100.0, "wye")
    assert float(kd) == pytest.approx(0.0954929658551372 * S32, rel=1e-14)     # eq. Kt_conversion_delta
    assert float(kw) == pytest.approx(0.0954929658551372 / math.sqrt(2), rel=1e-14)  # eq. Kt_conversion_wye
    assert float(kd) / float(kw) == pytest.approx(math.sqrt(3))
    assert kd.unit == "V*s/rad" and kd.frame == "q_power_invariant" and len(kd.steps) == 2 and not kd.warnings
    assert fr.kv_from_back_emf_constant_q(float(kd), "delta") == pytest.approx(100.0)
    rms = fr.back_emf_constant_q_from_kv(100.0, "delta", kv_frame="ll_rms")
    assert float(rms) == pytest.approx(float(kd) * math.sqrt(2))
    bus = fr.back_emf_constant_q_from_kv(100.0, "wye", kv_frame="bus")
    assert float(bus) == pytest.approx(float(kw)) and bus.warnings
    with pytest.raises(ValueError, match="kv"):
        fr.back_emf_constant_q_from_kv(-1.0, "wye")


@pytest.mark.parametrize("winding", WINDINGS)
def test_voltage_limit_and_no_load_speed(winding):
    expected = 24.0 / math.sqrt(2) if winding == "wye" else 24.0 * S32
    assert fr.voltage_limit_q(24.0, winding) == pytest.approx(expected)
    np.testing.assert_allclose(fr.voltage_limit_q(np.array([12.0, 24.0]), winding), [expected / 2, expected])
    # the SVPWM limit is the point where the line-to-line peak equals V_bus
    assert fr.line_to_line_voltage_peak_from_dq(0.0, fr.voltage_limit_q(24.0, winding), winding) == pytest.approx(24.0)
    assert fr.dq_voltage_magnitude_from_line_to_line_peak(24.0, winding) == pytest.approx(expected)
    # no-load speed: winding-agnostic in terms of Kbar_b^ll (V_ll peak = Kbar_b^ll omega = V_bus)
    k_ll = fr.back_emf_constant_ll_peak_from_kv(100.0)
    kq = float(fr.back_emf_constant_q_from(k_ll, "ll_peak", winding))
    w = fr.no_load_speed_max(24.0, kq, winding)
    assert w == pytest.approx(24.0 / k_ll)
    assert fr.rad_per_s_to_rpm(w) == pytest.approx(2400.0)


def test_torque_from_line_current_and_losses():
    assert fr.torque_from_line_current_peak(0.1, 10.0) == pytest.approx(math.sqrt(3) / 2)
    assert fr.joule_loss_q(3.0, 4.0, 0.5) == pytest.approx(12.5)
    assert fr.bus_current_from_q(1.0, 2.0, 3.0, 4.0, 10.0) == pytest.approx(1.4)
    assert fr.flux_linkage_d_from_back_emf_constant_q(0.21, 21) == pytest.approx(0.01)
    assert fr.back_emf_constant_q_from_flux_linkage(0.01, 21) == pytest.approx(0.21 * S32)


# -- API hygiene ------------------------------------------------------------------------------------

def test_bad_winding_and_frame_raise_with_options():
    with pytest.raises(ValueError, match="wye.*delta"):
        fr.phase_resistance_from_terminal(1.0, "star")
    with pytest.raises(ValueError, match="line_rms"):
        fr.torque_constant_q_from(1.0, "line", "wye")
    with pytest.raises(ValueError, match="ll_peak"):
        fr.back_emf_constant_q_from(1.0, "line_peak", "wye")
    with pytest.raises(ValueError, match="> 0"):
        fr.torque_constant_q_from(-1.0, "phase_peak", "wye")


def test_conversion_object_is_a_float_with_provenance():
    c = fr.torque_constant_q_from(0.14, "phase_peak", "delta")
    assert c * 2 == pytest.approx(2 * c.value)
    assert "0.14" in c.explain() and "eq." in c.explain()
    c2 = pickle.loads(pickle.dumps(c))
    assert float(c2) == float(c) and c2.steps == c.steps and c2.frame == c.frame
    assert "Conversion(value=" in repr(c)
    assert fr.torque_constant_q_from(0.14, "q", "wye") == pytest.approx(0.14)  # alias of q_power_invariant


def test_public_api_listed():
    for name in fr.__all__:
        assert hasattr(fr, name), name
