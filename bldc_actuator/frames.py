r"""Reference frames of a three-phase BLDC/PMSM motor and the conversions between them.

Pure functions on floats and numpy arrays (no state, no ROS). Every name says which frame it takes and
which it gives. Equation labels refer to Lee et al., *How to Model Brushless Electric Motors for the Design
of Lightweight Robotic Systems* (``shared/reference/seed-paper.tex``); where the paper and the physics
disagree this module follows the physics (see ``docs/paper-discrepancies.md``).

Frames and symbols
------------------
* **phase** (:math:`\phi`): one *winding*. For wye the winding sits between a lead and the neutral, for
  delta between two leads (winding a between leads A and B, b between B and C, c between C and A).
  ``_peak`` is the amplitude :math:`\bar{x}` of the sinusoid, ``_rms`` is :math:`\bar{x}/\sqrt{2}`.
* **line** (:math:`l`): current in one motor lead. **ll** (:math:`ll`): voltage between two leads, also
  called *terminal* quantities (terminal resistance / inductance are measured across two leads with the
  third one floating).
* **q** (:math:`q`): power-invariant d-q transform of the *winding* quantities, paper eq. ``dq_trans``:

  .. math::
      \begin{bmatrix} x_d \\ x_q \end{bmatrix} = \sqrt{\tfrac{2}{3}}
      \begin{bmatrix} \cos\theta & \cos(\theta-\tfrac{2\pi}{3}) & \cos(\theta+\tfrac{2\pi}{3}) \\
      -\sin\theta & -\sin(\theta-\tfrac{2\pi}{3}) & -\sin(\theta+\tfrac{2\pi}{3}) \end{bmatrix}
      \begin{bmatrix} x_a \\ x_b \\ x_c \end{bmatrix}

  so that :math:`\sum_k v_k i_k = v_d i_d + v_q i_q`, :math:`P_{Joule} = R^\phi (i_d^2 + i_q^2)` and the
  q-axis model is :math:`v_q = R^\phi i_q + L^q \, di_q/dt + K_b^q \omega` (eq. ``quad_electric``),
  :math:`\tau = K_t^q i_q` (eq. ``q_axis_torque``) with :math:`K_t^q = K_b^q` in SI units.
* **q amplitude-invariant**: the same transform with :math:`2/3` instead of :math:`\sqrt{2/3}`
  (used by many drives, e.g. ODrive, VESC): :math:`x_q = \bar{x}^\phi` for a balanced set, and power is
  :math:`\tfrac{3}{2}(v_d i_d + v_q i_q)`.

Winding (phase) currents of a sinusoidally commutated motor (paper eq. ``phase_currents``) are
:math:`i_k = -\bar{I}^\phi \sin(\theta - k\,2\pi/3)`, in phase with the back-EMF
:math:`e_k = -\bar{K}_b^\phi \sin(\theta - k\,2\pi/3)\,\omega`; then :math:`i_d = 0` and
:math:`i_q = \sqrt{3/2}\,\bar{I}^\phi` (eq. ``quad_current_conv``).

Torque and back-EMF constants are per **mechanical** rad/s of the rotor (the paper's :math:`K_b` multiplies
:math:`d\theta_r/dt`); the electrical angle is :math:`\theta_e = p\,\theta_r` (``p`` = pole pairs).

Self and mutual inductance: :math:`\psi_a = L_s i_a + M i_b + M i_c` (``M`` signed, usually negative,
about :math:`-L_s/2` for a sinusoidally distributed winding). The q-axis inductance is :math:`L^q = L_s - M`
(paper eq. ``effective_induct``). Driving two leads with the third floating gives
:math:`L^{ll} = 2 L^q` (wye) and :math:`L^{ll} = \tfrac{2}{3} L^q` (delta): the *same* factors as the
resistance, :math:`R^{ll} = 2 R^\phi` (wye) and :math:`\tfrac{2}{3} R^\phi` (delta). The paper's boxed
eqs. ``inductance_wye`` / ``inductance_delta`` (3/2 and 1/2) disagree with this.
"""

from __future__ import annotations

import math
from typing import Literal, Sequence

import numpy as np

__all__ = [
    # types and constants
    "Winding", "WINDINGS", "Conversion", "CURRENT_FRAMES", "VOLTAGE_FRAMES", "BACK_EMF_FRAMES",
    "TORQUE_CONSTANT_FRAMES", "KV_FRAMES",
    # transforms
    "clarke", "inverse_clarke", "park", "inverse_park", "abc_to_dq", "dq_to_abc", "zero_sequence",
    "clarke_amplitude_invariant", "inverse_clarke_amplitude_invariant",
    "abc_to_dq_amplitude_invariant", "dq_to_abc_amplitude_invariant",
    "dq_power_invariant_from_amplitude_invariant", "dq_amplitude_invariant_from_power_invariant",
    "electrical_angle", "electrical_speed", "mechanical_speed",
    # instantaneous winding <-> terminal
    "phase_to_line_current", "line_to_phase_current", "line_to_line_from_phase_voltage",
    "phase_from_line_to_line_voltage",
    # amplitudes
    "phase_voltage_peak_from_line_to_line_peak", "line_to_line_voltage_peak_from_phase_peak",
    "phase_current_peak_from_line_peak", "line_current_peak_from_phase_peak",
    "current_q_from", "current_from_q", "voltage_q_from", "voltage_from_q",
    "line_to_line_voltage_peak_from_dq", "dq_voltage_magnitude_from_line_to_line_peak",
    # impedances
    "phase_resistance_from_terminal", "terminal_resistance_from_phase",
    "q_inductance_from_terminal", "terminal_inductance_from_q", "q_inductance_from_self_mutual",
    # constants
    "rpm_to_rad_per_s", "rad_per_s_to_rpm", "back_emf_constant_from_kv", "kv_from_back_emf_constant",
    "back_emf_constant_ll_peak_from_kv", "kv_ll_peak_from_back_emf_constant_ll_peak",
    "back_emf_constant_q_from", "back_emf_constant_from_q", "back_emf_constant_q_from_kv",
    "kv_from_back_emf_constant_q", "torque_constant_q_from", "torque_constant_from_q",
    "back_emf_constant_q_from_flux_linkage", "flux_linkage_d_from_back_emf_constant_q",
    # voltage limit, speed, torque, loss
    "voltage_limit_q", "line_to_line_voltage_peak_max", "no_load_speed_max",
    "torque_from_line_current_peak", "joule_loss_q", "bus_current_from_q",
]

Winding = Literal["wye", "delta"]
WINDINGS: tuple[str, ...] = ("wye", "delta")

SQRT2 = math.sqrt(2.0)
SQRT3 = math.sqrt(3.0)
SQRT3_2 = math.sqrt(1.5)  #: sqrt(3/2), phase amplitude -> power-invariant q
SQRT2_3 = math.sqrt(2.0 / 3.0)
TWO_PI_3 = 2.0 * math.pi / 3.0

#: current frames (what a datasheet's "A" means). ``q`` is an alias of ``q_power_invariant``.
CURRENT_FRAMES = ("phase_peak", "phase_rms", "line_peak", "line_rms", "q_power_invariant",
                  "q_amplitude_invariant", "drive_amplitude_invariant", "drive_power_invariant")
#: ``q_amplitude_invariant`` / ``q_power_invariant`` are d-q transforms of the WINDING (phase) currents. A drive
#: (ODrive, VESC, most FOC firmware) measures and transforms the currents in the motor LEADS (line currents)
#: without knowing the winding: ``drive_amplitude_invariant`` is its amplitude-invariant i_q (= line-current
#: amplitude), ``drive_power_invariant`` its power-invariant one. On a wye motor they equal the q_ frames; on
#: a delta motor the line currents are sqrt(3) x the winding currents, so a drive's K_t = torque / its i_q is
#: sqrt(3) BELOW the per-phase-amplitude value.
#: voltage frames (and back-EMF constant frames: volts of that frame per mechanical rad/s)
VOLTAGE_FRAMES = ("phase_peak", "phase_rms", "ll_peak", "ll_rms", "q_power_invariant", "q_amplitude_invariant")
BACK_EMF_FRAMES = VOLTAGE_FRAMES
#: torque-constant frames: total motor torque per ampere of the named current. ``per_phase_amplitude`` is the
#: paper's per-phase constant amplitude \bar{K}_t^phi (= \bar{K}_b^phi, torque of ONE winding per ampere at
#: alignment), which is 2/3 of the ``phase_peak`` datasheet value. ``bus`` = per DC bus ampere.
TORQUE_CONSTANT_FRAMES = CURRENT_FRAMES + ("per_phase_amplitude", "bus")
#: Kv frames: no-load rpm per volt of the named voltage; ``bus`` = per DC bus volt (SVPWM assumed)
KV_FRAMES = VOLTAGE_FRAMES + ("bus",)

_FRAME_ALIASES = {"q": "q_power_invariant", "line_to_line_peak": "ll_peak", "line_to_line_rms": "ll_rms"}


# ------------------------------------------------------------------------------------------------
# Result object
# ------------------------------------------------------------------------------------------------

class Conversion(float):
    """A converted scalar that carries its unit, frame, explained steps and warnings.

    It *is* a float (``Conversion(...) * 2`` works, ``float(c)`` and ``c.value`` give the number), so it can
    be used wherever a number is expected, while ``c.frame`` says what the number means.

    Attributes
    ----------
    value : float
        The number.
    unit : str
        SI unit, e.g. ``"N*m/A"``.
    frame : str
        Frame of the result, e.g. ``"q_power_invariant"``.
    steps : list[str]
        Human-readable derivation: formula, numbers, source equation.
    warnings : list[str]
        Assumptions the result depends on (empty if none).
    """

    unit: str
    frame: str
    steps: list
    warnings: list

    def __new__(cls, value: float, unit: str, frame: str, steps: Sequence[str] = (),
                warnings: Sequence[str] = ()):
        obj = super().__new__(cls, float(value))
        obj.unit = unit
        obj.frame = frame
        obj.steps = list(steps)
        obj.warnings = list(warnings)
        return obj

    def __getnewargs__(self):  # pickling / copying
        return (float(self), self.unit, self.frame, self.steps, self.warnings)

    @property
    def value(self) -> float:
        return float(self)

    def __repr__(self) -> str:
        return (f"Conversion(value={float(self)!r}, unit={self.unit!r}, frame={self.frame!r}, "
                f"steps={self.steps!r}, warnings={self.warnings!r})")

    def explain(self) -> str:
        """Multi-line text: each step, then each warning."""
        lines = [f"  {s}" for s in self.steps]
        lines += [f"  WARNING: {w}" for w in self.warnings]
        return "\n".join(lines)


# ------------------------------------------------------------------------------------------------
# Validation helpers
# ------------------------------------------------------------------------------------------------

def _winding(winding: str) -> str:
    if winding not in WINDINGS:
        raise ValueError(f"winding must be 'wye' or 'delta', got {winding!r}")
    return winding


def _frame(frame: str, allowed: Sequence[str], what: str) -> str:
    frame = _FRAME_ALIASES.get(frame, frame)
    if frame not in allowed:
        raise ValueError(f"{what} frame must be one of {', '.join(allowed)}; got {frame!r}")
    return frame


def _g(x: float) -> str:
    """Compact number formatting for explanation strings."""
    return f"{float(x):.6g}"


# ------------------------------------------------------------------------------------------------
# Transforms (power-invariant, paper eqs. clarke, park, dq_trans)
# ------------------------------------------------------------------------------------------------

def clarke(a, b, c):
    r"""Power-invariant Clarke transform (paper eq. ``clarke``).

    .. math:: x_\alpha = \sqrt{2/3}\,(a - b/2 - c/2), \quad x_\beta = \sqrt{2/3}\,\tfrac{\sqrt3}{2}(b - c)

    Parameters
    ----------
    a, b, c : float | ndarray
        Winding (phase) quantities, any unit.

    Returns
    -------
    (alpha, beta) : tuple of float | ndarray
        Stationary-frame components, same unit.
    """
    alpha = SQRT2_3 * (a - 0.5 * b - 0.5 * c)
    beta = SQRT2_3 * (0.5 * SQRT3) * (b - c)
    return alpha, beta


def inverse_clarke(alpha, beta):
    r"""Inverse of :func:`clarke` for zero zero-sequence (:math:`a + b + c = 0`)."""
    a = SQRT2_3 * alpha
    b = SQRT2_3 * (-0.5 * alpha + 0.5 * SQRT3 * beta)
    c = SQRT2_3 * (-0.5 * alpha - 0.5 * SQRT3 * beta)
    return a, b, c


def park(alpha, beta, theta_e):
    r"""Park rotation (paper eq. ``park``): :math:`d = \alpha\cos\theta + \beta\sin\theta`,
    :math:`q = -\alpha\sin\theta + \beta\cos\theta`.

    Parameters
    ----------
    alpha, beta : float | ndarray
        Stationary-frame components.
    theta_e : float | ndarray
        Electrical angle :math:`\theta_e = p\,\theta_r` (rad).
    """
    c, s = np.cos(theta_e), np.sin(theta_e)
    return alpha * c + beta * s, -alpha * s + beta * c


def inverse_park(d, q, theta_e):
    r"""Inverse of :func:`park`: :math:`\alpha = d\cos\theta - q\sin\theta`,
    :math:`\beta = d\sin\theta + q\cos\theta`."""
    c, s = np.cos(theta_e), np.sin(theta_e)
    return d * c - q * s, d * s + q * c


def abc_to_dq(a, b, c, theta_e):
    r"""Power-invariant d-q transform :math:`\mathbf{P}\mathbf{C}` of winding quantities (paper eq. ``dq_trans``).

    Parameters
    ----------
    a, b, c : float | ndarray
        Winding (phase) quantities, e.g. currents (A) or voltages (V).
    theta_e : float | ndarray
        Electrical angle (rad).

    Returns
    -------
    (d, q) : tuple of float | ndarray
        Power-invariant d and q components: :math:`\sum_k v_k i_k = v_d i_d + v_q i_q`
        (plus the zero-sequence product, see :func:`zero_sequence`).
    """
    th = theta_e
    d = SQRT2_3 * (a * np.cos(th) + b * np.cos(th - TWO_PI_3) + c * np.cos(th + TWO_PI_3))
    q = -SQRT2_3 * (a * np.sin(th) + b * np.sin(th - TWO_PI_3) + c * np.sin(th + TWO_PI_3))
    return d, q


def dq_to_abc(d, q, theta_e):
    r"""Inverse power-invariant d-q transform (transpose of eq. ``dq_trans``), zero zero-sequence.

    :math:`x_k = \sqrt{2/3}\,[d\cos(\theta - k\,2\pi/3) - q\sin(\theta - k\,2\pi/3)]`, k = 0, 1, 2 (a, b, c).
    With ``d = 0`` this gives the paper's commutated currents :math:`-\bar{I}^\phi\sin(\theta - k\,2\pi/3)` with
    :math:`\bar{I}^\phi = \sqrt{2/3}\,I^q`.
    """
    th = theta_e
    a = SQRT2_3 * (d * np.cos(th) - q * np.sin(th))
    b = SQRT2_3 * (d * np.cos(th - TWO_PI_3) - q * np.sin(th - TWO_PI_3))
    c = SQRT2_3 * (d * np.cos(th + TWO_PI_3) - q * np.sin(th + TWO_PI_3))
    return a, b, c


def zero_sequence(a, b, c):
    r"""Power-invariant zero-sequence component :math:`x_0 = (a + b + c)/\sqrt{3}`.

    Completes :func:`abc_to_dq` to an orthonormal transform: :math:`\sum_k v_k i_k = v_d i_d + v_q i_q + v_0 i_0`.
    """
    return (a + b + c) / SQRT3


def clarke_amplitude_invariant(a, b, c):
    r"""Amplitude-invariant Clarke transform: :math:`\tfrac{2}{3}` instead of :math:`\sqrt{2/3}`.

    A balanced set of amplitude :math:`\bar{x}` maps to a vector of length :math:`\bar{x}`. Power is
    :math:`\tfrac32(v_\alpha i_\alpha + v_\beta i_\beta)`.
    """
    alpha, beta = clarke(a, b, c)
    return alpha * SQRT2_3, beta * SQRT2_3


def inverse_clarke_amplitude_invariant(alpha, beta):
    """Inverse of :func:`clarke_amplitude_invariant` (zero zero-sequence)."""
    return inverse_clarke(alpha * SQRT3_2, beta * SQRT3_2)


def abc_to_dq_amplitude_invariant(a, b, c, theta_e):
    r"""Amplitude-invariant d-q transform: :math:`x_q = \bar{x}^\phi` for commutated winding quantities.

    Equals :func:`abc_to_dq` times :math:`\sqrt{2/3}` (paper footnote on the amplitude-invariant form).
    """
    d, q = abc_to_dq(a, b, c, theta_e)
    return d * SQRT2_3, q * SQRT2_3


def dq_to_abc_amplitude_invariant(d, q, theta_e):
    """Inverse of :func:`abc_to_dq_amplitude_invariant` (zero zero-sequence)."""
    return dq_to_abc(d * SQRT3_2, q * SQRT3_2, theta_e)


def dq_power_invariant_from_amplitude_invariant(x_amplitude_invariant):
    r"""Current or voltage: power-invariant d/q = :math:`\sqrt{3/2}` × amplitude-invariant d/q."""
    return x_amplitude_invariant * SQRT3_2


def dq_amplitude_invariant_from_power_invariant(x_power_invariant):
    r"""Current or voltage: amplitude-invariant d/q = :math:`\sqrt{2/3}` × power-invariant d/q."""
    return x_power_invariant * SQRT2_3


def electrical_angle(theta_mech, pole_pairs):
    r""":math:`\theta_e = p\,\theta_r` (rad) from the rotor mechanical angle (rad)."""
    return pole_pairs * theta_mech


def electrical_speed(omega_mech, pole_pairs):
    r""":math:`\omega_e = p\,\omega_r` (rad/s)."""
    return pole_pairs * omega_mech


def mechanical_speed(omega_e, pole_pairs):
    r""":math:`\omega_r = \omega_e / p` (rad/s)."""
    return omega_e / pole_pairs


# ------------------------------------------------------------------------------------------------
# Instantaneous winding <-> terminal quantities
# ------------------------------------------------------------------------------------------------

def phase_to_line_current(i_a, i_b, i_c, winding: Winding):
    r"""Line (lead) currents from winding currents.

    Wye: :math:`i_A = i_a` etc. (eq. ``wye_voltage2``). Delta (winding a between leads A and B, b between B
    and C, c between C and A; winding current positive from the first to the second lead):
    :math:`i_A = i_a - i_c,\; i_B = i_b - i_a,\; i_C = i_c - i_b`, amplitude :math:`\sqrt3\,\bar{I}^\phi`
    (eq. ``delta_voltage2``) and 30° behind the winding currents.

    Parameters
    ----------
    i_a, i_b, i_c : float | ndarray
        Winding currents (A).
    winding : {"wye", "delta"}

    Returns
    -------
    (i_A, i_B, i_C) : line currents (A), positive into the motor.
    """
    if _winding(winding) == "wye":
        return i_a, i_b, i_c
    return i_a - i_c, i_b - i_a, i_c - i_b


def line_to_phase_current(i_A, i_B, i_C, winding: Winding):
    r"""Winding currents from line currents (inverse of :func:`phase_to_line_current`).

    For delta the line currents do not see a circulating current :math:`i_0` around the loop; this returns
    the solution without it: :math:`i_a = (i_A - i_B)/3` etc. (exact when :math:`\sum_k i_k = 0`, which
    holds for balanced sinusoidal back-EMF in steady state).
    """
    if _winding(winding) == "wye":
        return i_A, i_B, i_C
    return (i_A - i_B) / 3.0, (i_B - i_C) / 3.0, (i_C - i_A) / 3.0


def line_to_line_from_phase_voltage(v_a, v_b, v_c, winding: Winding):
    r"""Line-to-line voltages :math:`(v_{AB}, v_{BC}, v_{CA})` from winding (phase) voltages.

    Wye: :math:`v_{AB} = v_a - v_b` (phase voltage = lead to neutral), amplitude :math:`\sqrt3\,\bar{V}^\phi`
    (eq. ``wye_voltage1``). Delta: :math:`v_{AB} = v_a` (eq. ``delta_voltage1``).
    """
    if _winding(winding) == "wye":
        return v_a - v_b, v_b - v_c, v_c - v_a
    return v_a, v_b, v_c


def phase_from_line_to_line_voltage(v_ab, v_bc, v_ca, winding: Winding):
    r"""Winding voltages from line-to-line voltages (inverse of :func:`line_to_line_from_phase_voltage`).

    For wye the neutral's zero-sequence voltage is not visible at the leads; this returns the solution with
    :math:`v_a + v_b + v_c = 0`: :math:`v_a = (v_{AB} - v_{CA})/3`.
    """
    if _winding(winding) == "wye":
        return (v_ab - v_ca) / 3.0, (v_bc - v_ab) / 3.0, (v_ca - v_bc) / 3.0
    return v_ab, v_bc, v_ca


# ------------------------------------------------------------------------------------------------
# Amplitude conversions (paper table tab:q-conversion rows V^phi, I^phi, V^q, I^q)
# ------------------------------------------------------------------------------------------------

def phase_voltage_peak_from_line_to_line_peak(v_ll_peak, winding: Winding):
    r""":math:`\bar{V}^\phi = \bar{V}^{ll}/\sqrt3` (wye) or :math:`\bar{V}^{ll}` (delta); eqs. ``wye_voltage1``,
    ``delta_voltage1``."""
    return v_ll_peak / SQRT3 if _winding(winding) == "wye" else v_ll_peak * 1.0


def line_to_line_voltage_peak_from_phase_peak(v_phase_peak, winding: Winding):
    r""":math:`\bar{V}^{ll} = \sqrt3\,\bar{V}^\phi` (wye) or :math:`\bar{V}^\phi` (delta)."""
    return v_phase_peak * SQRT3 if _winding(winding) == "wye" else v_phase_peak * 1.0


def phase_current_peak_from_line_peak(i_line_peak, winding: Winding):
    r""":math:`\bar{I}^\phi = \bar{I}^l` (wye) or :math:`\bar{I}^l/\sqrt3` (delta); eqs. ``wye_voltage2``,
    ``delta_voltage2``."""
    return i_line_peak * 1.0 if _winding(winding) == "wye" else i_line_peak / SQRT3


def line_current_peak_from_phase_peak(i_phase_peak, winding: Winding):
    r""":math:`\bar{I}^l = \bar{I}^\phi` (wye) or :math:`\sqrt3\,\bar{I}^\phi` (delta)."""
    return i_phase_peak * 1.0 if _winding(winding) == "wye" else i_phase_peak * SQRT3


def _current_factor(frame: str, winding: str) -> tuple[float, str, str]:
    """(f, formula, source) with I_q = f * I_frame for sinusoidal commutation (|i_dq| in general)."""
    w = _winding(winding)
    table = {
        "phase_peak": (SQRT3_2, "I^q = sqrt(3/2) * I^phi_peak", "eq. quad_current_conv"),
        "phase_rms": (SQRT3, "I^q = sqrt(3/2) * sqrt(2) * I^phi_rms = sqrt(3) * I^phi_rms",
                      "eq. quad_current_conv with I_peak = sqrt(2) I_rms; tab:signals footnote"),
        "line_peak": ((SQRT3_2, "I^q = sqrt(3/2) * I^l_peak", "eq. current_wye") if w == "wye" else
                      (1.0 / SQRT2, "I^q = sqrt(1/2) * I^l_peak", "eq. current_delta")),
        "line_rms": ((SQRT3, "I^q = sqrt(3) * I^l_rms", "eq. current_wye with I_peak = sqrt(2) I_rms")
                     if w == "wye" else
                     (1.0, "I^q = I^l_rms", "eq. current_delta with I_peak = sqrt(2) I_rms")),
        "q_power_invariant": (1.0, "I^q = I^q", "definition"),
        "q_amplitude_invariant": (SQRT3_2, "I^q = sqrt(3/2) * I^q_amplitude_invariant",
                                  "amplitude-invariant I^q of the WINDING currents equals I^phi_peak (footnote in "
                                  "sec. d-q transformation)"),
    }
    line = table["line_peak"]
    # a drive transforms the LINE currents it measures: its amplitude-invariant i_q is the line-current
    # amplitude, its power-invariant i_q sqrt(3/2) times that
    table["drive_amplitude_invariant"] = (
        line[0], f"{line[1]} (a drive's amplitude-invariant i_q = line-current amplitude)",
        f"{line[2]}; drives transform the currents in the motor leads")
    table["drive_power_invariant"] = (
        line[0] / SQRT3_2, f"I^q = {'1' if w == 'wye' else 'sqrt(1/3)'} * I^q_drive (drive's power-invariant i_q "
        "= sqrt(3/2) x line-current amplitude)", f"{line[2]}; drives transform the currents in the motor leads")
    return table[frame]


def _voltage_factor(frame: str, winding: str) -> tuple[float, str, str]:
    """(f, formula, source) with V_q = f * V_frame (|v_dq| in general)."""
    w = _winding(winding)
    table = {
        "phase_peak": (SQRT3_2, "V^q = sqrt(3/2) * V^phi_peak", "eq. dq_trans applied to a balanced set"),
        "phase_rms": (SQRT3, "V^q = sqrt(3) * V^phi_rms", "eq. dq_trans with V_peak = sqrt(2) V_rms"),
        "ll_peak": ((1.0 / SQRT2, "V^q = V^ll_peak / sqrt(2)",
                     "tab:q-conversion rows V^q, K_t^q; eqs. voltage_wye, Kt_conversion_wye")
                    if w == "wye" else
                    (SQRT3_2, "V^q = sqrt(3/2) * V^ll_peak",
                     "tab:q-conversion rows V^q, K_t^q; eqs. voltage_delta, Kt_conversion_delta")),
        "ll_rms": ((1.0, "V^q = V^ll_rms", "eq. voltage_wye with V_peak = sqrt(2) V_rms") if w == "wye" else
                   (SQRT3, "V^q = sqrt(3) * V^ll_rms", "eq. voltage_delta with V_peak = sqrt(2) V_rms")),
        "q_power_invariant": (1.0, "V^q = V^q", "definition"),
        "q_amplitude_invariant": (SQRT3_2, "V^q = sqrt(3/2) * V^q_amplitude_invariant",
                                  "amplitude-invariant V^q equals V^phi_peak"),
    }
    return table[frame]


def current_q_from(current, frame: str, winding: Winding):
    r"""Power-invariant q-axis current :math:`I^q` (A) from a sinusoidal current given in ``frame``.

    Factors (tab:q-conversion row :math:`I^q`, eqs. ``current_wye``, ``current_delta``):

    ==========================  ==================  ===================
    frame                       wye                 delta
    ==========================  ==================  ===================
    ``phase_peak``              :math:`\sqrt{3/2}`  :math:`\sqrt{3/2}`
    ``phase_rms``               :math:`\sqrt3`      :math:`\sqrt3`
    ``line_peak``               :math:`\sqrt{3/2}`  :math:`\sqrt{1/2}`
    ``line_rms``                :math:`\sqrt3`      1
    ``q_amplitude_invariant``   :math:`\sqrt{3/2}`  :math:`\sqrt{3/2}`
    ==========================  ==================  ===================

    Valid for sinusoidal commutation (gives :math:`|i_{dq}|` if :math:`i_d \neq 0`).
    """
    frame = _frame(frame, CURRENT_FRAMES, "current")
    return current * _current_factor(frame, winding)[0]


def current_from_q(i_q, frame: str, winding: Winding):
    """Inverse of :func:`current_q_from`: the current in ``frame`` (A) for q-axis current ``i_q`` (A)."""
    frame = _frame(frame, CURRENT_FRAMES, "current")
    return i_q / _current_factor(frame, winding)[0]


def voltage_q_from(voltage, frame: str, winding: Winding):
    r"""Power-invariant q-axis voltage magnitude :math:`|v_{dq}|` (V) from a sinusoidal voltage in ``frame``.

    ``ll_peak``: :math:`V^q = \bar{V}^{ll}/\sqrt2` (wye), :math:`\sqrt{3/2}\,\bar{V}^{ll}` (delta) — tab:q-conversion
    row :math:`V^q`, eqs. ``voltage_wye``, ``voltage_delta``. ``phase_peak``: :math:`\sqrt{3/2}\,\bar{V}^\phi`.
    """
    frame = _frame(frame, VOLTAGE_FRAMES, "voltage")
    return voltage * _voltage_factor(frame, winding)[0]


def voltage_from_q(v_q, frame: str, winding: Winding):
    """Inverse of :func:`voltage_q_from`."""
    frame = _frame(frame, VOLTAGE_FRAMES, "voltage")
    return v_q / _voltage_factor(frame, winding)[0]


def line_to_line_voltage_peak_from_dq(v_d, v_q, winding: Winding):
    r"""Line-to-line voltage amplitude :math:`\bar{V}^{ll}` (V) from power-invariant :math:`v_d, v_q` (V).

    :math:`\bar{V}^{ll} = \sqrt2\,|v_{dq}|` (wye) or :math:`\sqrt{2/3}\,|v_{dq}|` (delta). The paper's eqs.
    ``voltage_wye`` / ``voltage_delta`` write :math:`V^q`; that is exact only while :math:`v_d = 0` (no load or
    negligible :math:`\omega_e L^q i_q`). Under load :math:`v_d = -\omega_e L^q i_q` adds in quadrature.
    """
    mag = np.hypot(v_d, v_q)
    return mag * (SQRT2 if _winding(winding) == "wye" else SQRT2_3)


def dq_voltage_magnitude_from_line_to_line_peak(v_ll_peak, winding: Winding):
    r""":math:`|v_{dq}|` (V) from :math:`\bar{V}^{ll}` (V): :math:`/\sqrt2` (wye), :math:`\times\sqrt{3/2}` (delta)."""
    return v_ll_peak / SQRT2 if _winding(winding) == "wye" else v_ll_peak * SQRT3_2


# ------------------------------------------------------------------------------------------------
# Resistance and inductance
# ------------------------------------------------------------------------------------------------

def phase_resistance_from_terminal(r_terminal, winding: Winding):
    r"""Winding (phase) resistance :math:`R^\phi` (Ω) from terminal resistance :math:`R^{ll}` (Ω).

    Two leads driven, third floating: wye :math:`R^{ll} = 2R^\phi`; delta: one winding in parallel with two in
    series, :math:`R^{ll} = R^\phi \| 2R^\phi = \tfrac23 R^\phi`. Hence :math:`R^\phi = \tfrac12 R^{ll}` (wye,
    eq. ``resistance_wye``) and :math:`\tfrac32 R^{ll}` (delta, eq. ``resistance_delta``). :math:`R^\phi` is the
    q-axis resistance: :math:`P_{Joule} = R^\phi I_q^2` (eq. ``power_quad``).
    """
    return r_terminal * (0.5 if _winding(winding) == "wye" else 1.5)


def terminal_resistance_from_phase(r_phase, winding: Winding):
    r""":math:`R^{ll} = 2R^\phi` (wye) or :math:`\tfrac23 R^\phi` (delta).

    Inverse of :func:`phase_resistance_from_terminal`."""
    return r_phase * (2.0 if _winding(winding) == "wye" else 2.0 / 3.0)


def q_inductance_from_terminal(l_terminal, winding: Winding):
    r"""q-axis inductance :math:`L^q = L_s - M` (H) from terminal inductance :math:`L^{ll}` (H).

    Two leads driven, third floating, with :math:`\psi_a = L_s i_a + M i_b + M i_c`:

    * wye: :math:`i_a = -i_b = i`, :math:`v_{AB} = 2(L_s - M)\,di/dt` so :math:`L^{ll} = 2L^q`,
      :math:`L^q = \tfrac12 L^{ll}`;
    * delta: winding ab in parallel with bc + ca; KVL around the loop gives :math:`i_{bc} = i_{ca} = -i_{ab}/2`
      for any :math:`R, L_s, M`, so :math:`v_{AB} = (L_s - M)\,di_{ab}/dt` with :math:`i_A = \tfrac32 i_{ab}`:
      :math:`L^{ll} = \tfrac23 L^q`, :math:`L^q = \tfrac32 L^{ll}`.

    These are the resistance factors (the terminal impedance is :math:`2(R^\phi + sL^q)` resp.
    :math:`\tfrac23(R^\phi + sL^q)`, so :math:`L^{ll}/R^{ll} = L^q/R^\phi`). **The paper's boxed eqs.**
    ``inductance_wye`` (:math:`\tfrac32 L^{ll}`) **and** ``inductance_delta`` (:math:`\tfrac12 L^{ll}`) **and
    tab:q-conversion row** :math:`L^q` **disagree**; see ``docs/paper-discrepancies.md``.
    """
    return l_terminal * (0.5 if _winding(winding) == "wye" else 1.5)


def terminal_inductance_from_q(l_q, winding: Winding):
    r""":math:`L^{ll} = 2L^q` (wye) or :math:`\tfrac23 L^q` (delta); inverse of :func:`q_inductance_from_terminal`."""
    return l_q * (2.0 if _winding(winding) == "wye" else 2.0 / 3.0)


def q_inductance_from_self_mutual(l_self, l_mutual):
    r""":math:`L^q = L^d = L_s - M` (H), paper eq. ``effective_induct``; ``l_mutual`` signed (usually < 0)."""
    return l_self - l_mutual


# ------------------------------------------------------------------------------------------------
# Back-EMF and torque constants (per mechanical rad/s)
# ------------------------------------------------------------------------------------------------

def rpm_to_rad_per_s(rpm):
    r""":math:`\omega = 2\pi\,n/60`."""
    return rpm * (2.0 * math.pi / 60.0)


def rad_per_s_to_rpm(omega):
    r""":math:`n = 60\,\omega/(2\pi)`."""
    return omega * (60.0 / (2.0 * math.pi))


def back_emf_constant_from_kv(kv_rpm_per_v):
    r"""Back-EMF constant (V·s/rad, per mechanical rad/s) in the SAME voltage frame as the Kv number.

    :math:`K_b = 1/K_v = 60/(2\pi\,K_v[\mathrm{rpm/V}])`.
    """
    return 60.0 / (2.0 * math.pi * kv_rpm_per_v)


def kv_from_back_emf_constant(k_b):
    r""":math:`K_v` (rpm/V) from a back-EMF constant (V·s/rad) in the same voltage frame."""
    return 60.0 / (2.0 * math.pi * k_b)


def back_emf_constant_ll_peak_from_kv(kv_rpm_per_v):
    r""":math:`\bar{K}_b^{ll}` (V·s/rad) from a Kv number (rpm/V) read as no-load rpm per volt of line-to-line
    **peak** back-EMF (the paper's reading, sec. Torque: :math:`\bar{K}_v^{ll} = 1/\bar{K}_b^{ll}`)."""
    return back_emf_constant_from_kv(kv_rpm_per_v)


def kv_ll_peak_from_back_emf_constant_ll_peak(k_b_ll_peak):
    r""":math:`K_v` (rpm/V, ll-peak convention) from :math:`\bar{K}_b^{ll}` (V·s/rad)."""
    return kv_from_back_emf_constant(k_b_ll_peak)


def back_emf_constant_q_from(k_b, frame: str, winding: Winding) -> Conversion:
    r"""q-axis back-EMF constant :math:`K_b^q` (V·s/rad) from a back-EMF constant in ``frame``.

    ``frame`` is a voltage frame (:data:`BACK_EMF_FRAMES`): the constant is that voltage (peak or rms) per
    mechanical rad/s. :math:`K_b^q = \sqrt{3/2}\,\bar{K}_b^\phi`; :math:`\bar{K}_b^\phi = \bar{K}_b^{ll}/\sqrt3`
    (wye) or :math:`\bar{K}_b^{ll}` (delta), so :math:`K_b^q = \bar{K}_b^{ll}/\sqrt2` (wye, eq. ``Kt_conversion_wye``)
    and :math:`\sqrt{3/2}\,\bar{K}_b^{ll}` (delta, eq. ``Kt_conversion_delta``). :math:`K_t^q = K_b^q` (SI).

    Returns
    -------
    Conversion
        Float subclass with ``unit="V*s/rad"``, ``frame="q_power_invariant"`` and the explained steps.
    """
    frame = _frame(frame, BACK_EMF_FRAMES, "back-EMF constant")
    f, formula, src = _voltage_factor(frame, winding)
    value = k_b * f
    step = (f"K_b^q = {_g(f)} x K_b({frame}) = {_g(f)} x {_g(k_b)} V*s/rad = {_g(value)} V*s/rad   "
            f"[{winding}: {formula} per rad/s; {src}]")
    return Conversion(value, "V*s/rad", "q_power_invariant", [step])


def back_emf_constant_from_q(k_b_q, frame: str, winding: Winding) -> float:
    """Inverse of :func:`back_emf_constant_q_from`: back-EMF constant (V·s/rad) in ``frame``."""
    frame = _frame(frame, BACK_EMF_FRAMES, "back-EMF constant")
    return k_b_q / _voltage_factor(frame, winding)[0]


def back_emf_constant_q_from_kv(kv_rpm_per_v, winding: Winding, kv_frame: str = "ll_peak") -> Conversion:
    r""":math:`K_b^q = K_t^q` (V·s/rad = N·m/A) from a Kv number (rpm/V).

    ``kv_frame`` says which voltage the Kv number divides (:data:`KV_FRAMES`); the default ``"ll_peak"`` is
    the paper's reading (:math:`K_v = 1/\bar{K}_b^{ll}`). ``"bus"`` means no-load rpm per DC bus volt; with a
    SVPWM drive at full modulation the line-to-line peak equals :math:`V_{bus}`, so it is treated as ``ll_peak``
    with a warning (sine-PWM drives reach only :math:`\tfrac{\sqrt3}{2}V_{bus}`, six-step drives a
    fundamental of :math:`\tfrac{2\sqrt3}{\pi}V_{bus}`).

    Returns
    -------
    Conversion
        value in V·s/rad, frame ``"q_power_invariant"``, with steps (Kv -> K_b in the Kv frame -> K_b^q).
    """
    if not (kv_rpm_per_v > 0):
        raise ValueError(f"kv must be > 0 rpm/V, got {kv_rpm_per_v!r}")
    kv_frame = _frame(kv_frame, KV_FRAMES, "Kv")
    warnings = []
    vframe = kv_frame
    if kv_frame == "bus":
        vframe = "ll_peak"
        warnings.append("Kv per bus volt read as line-to-line peak: assumes SVPWM at full modulation "
                        "(V_ll_peak = V_bus), no load, no losses")
    k_b = back_emf_constant_from_kv(kv_rpm_per_v)
    steps = [f"K_b({vframe}) = 60 / (2 pi Kv) = 60 / (2 pi x {_g(kv_rpm_per_v)} rpm/V) = {_g(k_b)} V*s/rad "
             f"[Kv in {kv_frame} convention; sec. Torque, K_v^ll = 1/K_b^ll]"]
    conv = back_emf_constant_q_from(k_b, vframe, winding)
    return Conversion(conv.value, "V*s/rad", "q_power_invariant", steps + conv.steps, warnings)


def kv_from_back_emf_constant_q(k_b_q, winding: Winding, kv_frame: str = "ll_peak") -> float:
    """Kv (rpm/V in ``kv_frame``) from :math:`K_b^q` (V·s/rad); inverse of :func:`back_emf_constant_q_from_kv`."""
    kv_frame = _frame(kv_frame, KV_FRAMES, "Kv")
    vframe = "ll_peak" if kv_frame == "bus" else kv_frame
    return kv_from_back_emf_constant(back_emf_constant_from_q(k_b_q, vframe, winding))


def _torque_constant_factor(frame: str, winding: str, bus_modulation: float) -> tuple[float, str, str, list]:
    """(g, formula, source, warnings) with K_t^q = g * K_t(frame)."""
    w = _winding(winding)
    if frame == "per_phase_amplitude":
        return (SQRT3_2, "K_t^q = sqrt(3/2) * Kbar_t^phi (per-phase constant amplitude)",
                "eq. conversion_kt_wye / conversion_kt_delta, eq. quad_kt_conv", [])
    if frame == "bus":
        v_limit_over_bus = 1.0 / SQRT2 if w == "wye" else SQRT3_2
        g = bus_modulation * v_limit_over_bus
        warn = [("Kt per DC bus ampere depends on the operating point: assumed lossless inverter, i_d = 0, "
                 f"V_bus*I_bus = v_q*i_q at modulation v_q/v_q_max = {_g(bus_modulation)} "
                 "(full modulation: K_t(bus) = V_bus/omega = Kbar_b^ll); at lower speed the same motor shows a "
                 "larger Kt per bus ampere")]
        formula = (f"K_t^q = K_t(bus) * v_q/V_bus = K_t(bus) * m * v_q_max/V_bus, v_q_max/V_bus = "
                   f"{'1/sqrt(2)' if w == 'wye' else 'sqrt(3/2)'}")
        return g, formula, "P = V_bus I_bus = v_q i_q; SVPWM limit (eqs. voltage_wye / voltage_delta)", warn
    f, formula, src = _current_factor(frame, w)
    # K_t^q = tau / I^q = K_t(frame) * I_frame / I^q = K_t(frame) / f
    return 1.0 / f, f"K_t^q = K_t({frame}) * I_{frame} / I^q, with {formula}", src, []


def torque_constant_q_from(kt, frame: str, winding: Winding, *, bus_modulation: float = 1.0) -> Conversion:
    r"""q-axis torque constant :math:`K_t^q` (N·m/A per q-axis ampere) from a datasheet torque constant.

    ``frame`` names the current the datasheet divides the **total motor torque** by (:data:`TORQUE_CONSTANT_FRAMES`),
    for sinusoidal commutation: :math:`K_t^q = \tau / I^q = K_t \cdot I_{frame} / I^q`.

    ==========================  ==================  ===================
    frame                       wye                 delta
    ==========================  ==================  ===================
    ``phase_peak``              :math:`\sqrt{2/3}`  :math:`\sqrt{2/3}`
    ``phase_rms``               :math:`1/\sqrt3`    :math:`1/\sqrt3`
    ``line_peak``               :math:`\sqrt{2/3}`  :math:`\sqrt2`
    ``line_rms``                :math:`1/\sqrt3`    1
    ``q_power_invariant``       1                   1
    ``q_amplitude_invariant``   :math:`\sqrt{2/3}`  :math:`\sqrt{2/3}`
    ``per_phase_amplitude``     :math:`\sqrt{3/2}`  :math:`\sqrt{3/2}`
    ``drive_amplitude_invariant`` :math:`\sqrt{2/3}` :math:`\sqrt2`
    ``drive_power_invariant``   1                   :math:`\sqrt3`
    ``bus`` (full modulation)   :math:`1/\sqrt2`    :math:`\sqrt{3/2}`
    ==========================  ==================  ===================

    ``per_phase_amplitude`` is the paper's :math:`\bar{K}_t^\phi` (torque of one winding per ampere at
    alignment, eqs. ``conversion_kt_wye``/``conversion_kt_delta``); a datasheet "Kt with phase-peak current"
    (Maxon, TQ in tab:manufacturers) is :math:`\tau/\bar{I}^\phi = \tfrac32\bar{K}_t^\phi` (eq.
    ``torqe_simplified``) and is ``phase_peak`` here. ``bus`` depends on the operating point; see the returned
    warning (assumed :math:`V_{bus} I_{bus} = v_q i_q` at modulation ``bus_modulation`` = :math:`v_q/v_{q,max}`).
    """
    if not (kt > 0):
        raise ValueError(f"torque constant must be > 0 N*m/A, got {kt!r}")
    frame = _frame(frame, TORQUE_CONSTANT_FRAMES, "torque constant")
    if not (0.0 < bus_modulation <= 1.0):
        raise ValueError(f"bus_modulation must be in (0, 1], got {bus_modulation!r}")
    g, formula, src, warn = _torque_constant_factor(frame, winding, bus_modulation)
    value = kt * g
    step = (f"{formula}  =>  K_t^q = {_g(g)} x {_g(kt)} N*m/A = {_g(value)} N*m/A   [{winding}; {src}]")
    return Conversion(value, "N*m/A", "q_power_invariant", [step], warn)


def torque_constant_from_q(kt_q, frame: str, winding: Winding, *, bus_modulation: float = 1.0) -> float:
    """Inverse of :func:`torque_constant_q_from`: datasheet-style torque constant (N·m/A) in ``frame``."""
    frame = _frame(frame, TORQUE_CONSTANT_FRAMES, "torque constant")
    return kt_q / _torque_constant_factor(frame, winding, bus_modulation)[0]


def _surd_name(ratio: float) -> str:
    """``ratio`` = sqrt(2^a 3^b) by name: sqrt(3/2), 2/sqrt(3), 3/sqrt(2), sqrt(6), 1/3 ..."""
    a_b = min(((a, b) for a in range(-6, 7) for b in range(-6, 7)),
              key=lambda ab: abs(math.log(ratio) - 0.5 * (ab[0] * math.log(2) + ab[1] * math.log(3))))
    a, b = a_b
    num, den = 2 ** max(a, 0) * 3 ** max(b, 0), 2 ** max(-a, 0) * 3 ** max(-b, 0)
    rn, rd = math.isqrt(num), math.isqrt(den)
    sq_n, sq_d = rn * rn == num, rd * rd == den
    if sq_n and sq_d:
        return f"{rn}" if rd == 1 else f"{rn}/{rd}"
    if sq_d:
        return f"sqrt({num})" + (f"/{rd}" if rd != 1 else "")
    if sq_n:
        return f"{rn}/sqrt({den})"
    return f"sqrt({num}/{den})"


def torque_constant_frame_factors(max_ratio: float = 4.0) -> dict[str, tuple[float, str]]:
    """Every ratio ``K_t_q(true) / K_t_q(entered)`` that a torque constant produces when it is read in one
    frame and entered as another (either winding; also a wye assumption on a delta motor): name ->
    (ratio, one way it arises). This is the list ``torque_constant_error`` in diagnosis matches against; it
    includes the factors of drives on delta motors (a drive's K_t entered as ``q_amplitude_invariant`` on a
    delta motor: sqrt(3))."""
    frames_ = sorted((f for f in TORQUE_CONSTANT_FRAMES if f != "bus"), key=lambda f: not f.startswith("drive_"))
    out: dict[str, tuple[float, str]] = {}
    for w_true, w_entered in (("delta", "delta"), ("wye", "wye"), ("delta", "wye"), ("wye", "delta")):
        for f_true in frames_:
            for f_entered in frames_:
                r = (_torque_constant_factor(f_true, w_true, 1.0)[0]
                     / _torque_constant_factor(f_entered, w_entered, 1.0)[0])
                if abs(r - 1.0) < 1e-9 or not (1.0 / max_ratio <= r <= max_ratio):
                    continue
                name = _surd_name(r)
                if name not in out:
                    how = (f"a {f_true} K_t of a {w_true} motor entered as {f_entered}"
                           + ("" if w_true == w_entered else f" of a {w_entered} motor"))
                    out[name] = (r, how)
    return dict(sorted(out.items(), key=lambda kv: kv[1][0]))


def back_emf_constant_q_from_flux_linkage(psi_pm_phase_peak, pole_pairs):
    r""":math:`K_b^q = \sqrt{3/2}\,p\,\psi_{PM}` (V·s/rad) from the magnet flux linkage amplitude of one winding
    :math:`\psi_{PM}` (Wb, the "flux linkage" of amplitude-invariant drives)."""
    return SQRT3_2 * pole_pairs * psi_pm_phase_peak


def flux_linkage_d_from_back_emf_constant_q(k_b_q, pole_pairs):
    r"""Power-invariant d-axis magnet flux linkage :math:`\psi_d^{PM} = K_b^q / p` (Wb).

    The paper (appendix ``section:appedix_a``) writes :math:`\bar{\Psi}^R = p K_b^q`; from
    :math:`v_q = \ldots + \omega_e \psi_d = \ldots + p\,\omega_r\,\psi_d` and :math:`v_q = \ldots + K_b^q\omega_r`
    it is :math:`K_b^q/p` (see ``docs/paper-discrepancies.md``).
    """
    return k_b_q / pole_pairs


# ------------------------------------------------------------------------------------------------
# Voltage limit, speed, torque, losses
# ------------------------------------------------------------------------------------------------

def line_to_line_voltage_peak_max(bus_voltage):
    r"""Largest sinusoidal line-to-line amplitude a SVPWM (or min-max zero-sequence injection) inverter gives
    without overmodulation: :math:`\bar{V}^{ll}_{max} = V_{bus}`."""
    return bus_voltage * 1.0


def voltage_limit_q(bus_voltage, winding: Winding):
    r"""Largest :math:`|v_{dq}|` (V, power-invariant, winding frame) a SVPWM inverter can apply.

    :math:`\bar{V}^{ll}_{max} = V_{bus}` with :math:`\bar{V}^{ll} = \sqrt2|v_{dq}|` (wye) or
    :math:`\sqrt{2/3}|v_{dq}|` (delta) gives :math:`V_{bus}/\sqrt2` (wye) and :math:`\sqrt{3/2}\,V_{bus}` (delta)
    (eqs. ``voltage_wye``, ``voltage_delta``). Works on floats and numpy arrays.
    """
    return bus_voltage * (1.0 / SQRT2 if _winding(winding) == "wye" else SQRT3_2)


def no_load_speed_max(bus_voltage, k_b_q, winding: Winding):
    r"""Maximum no-load rotor speed :math:`\omega_{r,max}` (mechanical rad/s) for a SVPWM drive.

    At no load :math:`i = 0` so :math:`v_q = K_b^q\omega_r`; with :func:`voltage_limit_q`:
    :math:`\omega_{max} = \sqrt{1/2}\,V_{bus}/K_b^q` (wye), :math:`\sqrt{3/2}\,V_{bus}/K_b^q` (delta) — paper's boxed
    max-speed equations; equivalently :math:`V_{bus}/\bar{K}_b^{ll}` for both windings.
    """
    return voltage_limit_q(bus_voltage, winding) / k_b_q


def torque_from_line_current_peak(k_b_ll_peak, i_line_peak):
    r""":math:`\tau = \tfrac{\sqrt3}{2}\,\bar{K}_b^{ll}\,\bar{I}^l` (N·m), either winding (eq. ``kb_ll_torque``),
    for sinusoidal currents aligned with the back-EMF."""
    return 0.5 * SQRT3 * k_b_ll_peak * i_line_peak


def joule_loss_q(i_d, i_q, r_phase):
    r""":math:`P = R^\phi (i_d^2 + i_q^2)` (W), power-invariant currents (eq. ``power_quad``)."""
    return r_phase * (i_d * i_d + i_q * i_q)


def bus_current_from_q(v_d, i_d, v_q, i_q, bus_voltage):
    r"""DC bus current (A) of a lossless inverter: :math:`I_{bus} = (v_d i_d + v_q i_q)/V_{bus}`."""
    return (v_d * i_d + v_q * i_q) / bus_voltage
