"""Where the complex-vector current controller (``drive.current_controller: complex_vector``) stays stable.

The law is :func:`bldc_actuator.kernel.control_tick`'s (motulator's 2DOF complex-vector PI with the integrator
driven by the realized voltage); this module does not run it, it writes the same update equations as a linear
map from one controller tick to the next, at a constant rotor speed and below the voltage limit (the limits and
the constant back-EMF drop out of the deviation dynamics). Per tick ``k`` (``a = K_p / L_ctl = 2 pi f_bw``,
``theta = p omega T_c`` the electrical angle the rotor turns in one period, ``c = j p omega L_ctl`` with the
feed-forward, else 0)::

    v_dist[k] = z[k] - K_p i[k] + c i[k]
    v[k]      = K_p (i_ref - i[k]) + v_dist[k]                      (computed at tick k)
    u[k]      = (v_on e^{+j theta/2} + v_before e^{-j theta/2}) / 2  (the realized voltage the integrator sees)
    z[k+1]    = z[k] + T_c (a + j p omega) (u[k] - v_dist[k])
    i[k+1]    = e^{-s} i[k] + (held voltages over the period, exact for L di/dt = v - (R + j p omega L) i)

with ``s = (R/L + j p omega) T_c``. With a whole period of computation delay (motulator's) the period after tick
``k`` holds ``v[k-1]``, ``v_on = v[k-1]``, ``v_before = v[k-2]``; a partial delay ``D`` holds ``v[k-1]`` up to
``D`` and ``v[k]`` after it (the controller's ``v_on``/``v_before`` as with a whole period); without delay the
period holds ``v[k]``, ``v_on = v[k]``, ``v_before = v[k-1]``. State ``x = (i, z, v[k-1], v[k-2])``; divided by
``K_p`` every voltage is dimensionless and the map depends on ``theta``, ``a T_c``, ``R T_c / L``, ``L_ctl / L``,
the feed-forward flag and the delay fraction ``D / T_c`` only. The loop is stable while every eigenvalue of its
matrix lies inside the unit circle; :func:`angle_limit` is the first ``theta`` where one leaves it (the map at
``-theta`` is the complex conjugate: the range is symmetric in the direction of rotation).

For the parameter file's motor (:func:`speed_limit`): the limit in rotor rad/s and rpm, against the highest speed
the motor can reach, its no-load speed at the bus voltage (``frames.no_load_speed_max`` x the modulation limit),
and what would make the loop stable there (a faster loop rate, or a lower loop bandwidth when one exists). The
drive's plain d/q ``pi`` law is far more tolerant (about 1.17 rad at ``a T_c = 0.31`` against 0.38 rad) and is not
covered here.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from . import frames

#: the grid the first crossing of the unit circle is searched on (then refined by brentq), over 0 .. pi
_GRID = 360
#: the largest electrical angle per period searched [rad]: beyond half a turn per period nothing is sampled right
ANGLE_MAX = math.pi


def state_matrices(theta, a: float, r: float, l_ratio: float = 1.0, feedforward: bool = False,
                   delay_fraction: float = 1.0) -> np.ndarray:
    """The closed loop's tick-to-tick matrices (shape ``theta.shape + (4, 4)``, complex) for the electrical angles
    per period ``theta`` [rad]; ``a`` = ``2 pi f_bw T_c``, ``r`` = ``R T_c / L``, ``l_ratio`` = ``L_ctl / L``,
    ``delay_fraction`` = computation delay / ``T_c`` in [0, 1]. State ``(i, z/K_p, v[k-1]/K_p, v[k-2]/K_p)``."""
    th = np.atleast_1d(np.asarray(theta, float))
    s = r + 1j * th
    with np.errstate(invalid="ignore", divide="ignore"):
        def gain(f):                         # K_p x (current change per volt held over f T_c from rest)
            if f <= 0.0:
                return np.zeros_like(s)
            return l_ratio * a * np.where(np.abs(s) > 1e-12, -np.expm1(-s * f) / s, f)
    dlt = min(max(float(delay_fraction), 0.0), 1.0)
    if dlt >= 1.0:
        g_held, g_new = gain(1.0), np.zeros_like(s)
    elif dlt <= 0.0:
        g_held, g_new = np.zeros_like(s), gain(1.0)
    else:
        g_held, g_new = np.exp(-s * (1.0 - dlt)) * gain(dlt), gain(1.0 - dlt)
    ff = 1j * th / a if feedforward else 0.0 * th
    c_v = -2.0 + ff                          # v[k] = c_v i + z
    c_d = -1.0 + ff                          # v_dist[k] = c_d i + z
    rot = np.exp(0.5j * th)
    gz = a + 1j * th                         # T_c (a + j p omega)
    n = len(th)
    one, zero = np.ones(n, complex), np.zeros(n, complex)
    i_row = np.stack([np.exp(-s) + g_new * c_v, g_new, g_held, zero], -1)
    v_row = np.stack([c_v, one, zero, zero], -1)
    v1_row = np.stack([zero, zero, one, zero], -1)
    if dlt > 0.0:                            # the integrator sees v[k-1] (held at the tick) and v[k-2]
        u_row = np.stack([zero, zero, 0.5 * rot, 0.5 / rot], -1)
    else:                                    # ... or v[k] (applied at once) and v[k-1]
        u_row = 0.5 * rot[:, None] * v_row + np.stack([zero, zero, 0.5 / rot, zero], -1)
    z_row = np.stack([zero, one, zero, zero], -1) + gz[:, None] * (u_row - np.stack([c_d, one, zero, zero], -1))
    m = np.stack([i_row, z_row, v_row, v1_row], -2)
    return m.reshape(np.shape(theta) + (4, 4))


def spectral_radius(theta, a: float, r: float, l_ratio: float = 1.0, feedforward: bool = False,
                    delay_fraction: float = 1.0) -> np.ndarray:
    """Largest eigenvalue magnitude of :func:`state_matrices` at each ``theta``: < 1 stable, > 1 divergent
    (a deviation grows by this factor per period)."""
    m = state_matrices(theta, a, r, l_ratio, feedforward, delay_fraction)
    return np.max(np.abs(np.linalg.eigvals(m)), axis=-1)


@functools.lru_cache(maxsize=256)
def angle_limit(a: float, r: float, l_ratio: float = 1.0, feedforward: bool = False,
                delay_fraction: float = 1.0) -> float:
    """The smallest electrical angle per period ``p |omega| T_c`` [rad] where the loop stops being stable (0 when it
    is not stable at standstill; ``inf`` when it stays stable up to :data:`ANGLE_MAX`). Cached: a parameter set is
    checked where it is loaded, where an actuator is built from it and where the diagnosis replays it (~40 ms each
    uncached)."""
    args = (a, r, l_ratio, feedforward, delay_fraction)
    th = np.linspace(0.0, ANGLE_MAX, _GRID + 1)
    rho = spectral_radius(th, *args)
    bad = np.nonzero(rho >= 1.0)[0]
    if not len(bad):
        return math.inf
    k = int(bad[0])
    if k == 0:
        return 0.0
    return float(brentq(lambda t: float(spectral_radius(t, *args)) - 1.0, th[k - 1], th[k], xtol=1e-9))


@dataclass(frozen=True)
class SpeedLimit:
    """The complex-vector loop's stable speed range for one parameter set (rotor side unless said otherwise)."""

    angle_limit: float       #: [rad] p |omega| T_c where the loop turns unstable
    speed_limit: float       #: [rad/s] rotor speed where it turns unstable
    max_speed: float         #: [rad/s] the motor's no-load speed at the bus voltage (the most it can reach)
    pole_pairs: int
    gear_ratio: float
    rate: float              #: [Hz] drive.current_loop_rate
    bandwidth: float         #: [Hz] drive.current_loop_bandwidth
    delay_fraction: float    #: computation delay / loop period
    bus_voltage: float       #: [V]
    r_over_l: float          #: [1/s] R / L of the motor
    l_ratio: float           #: L_ctl / L
    feedforward: bool

    @property
    def stable(self) -> bool:
        """Stable over every speed the motor can reach."""
        return self.max_speed < self.speed_limit

    @property
    def speed_limit_rpm(self) -> float:
        return self.speed_limit * 60.0 / (2.0 * math.pi)

    @property
    def max_speed_rpm(self) -> float:
        return self.max_speed * 60.0 / (2.0 * math.pi)

    def stable_at(self, omega) -> bool:
        """Stable at every rotor speed [rad/s] of ``omega`` (array-like; non-finite entries ignored)."""
        w = np.abs(np.asarray(omega, float)).ravel()
        w = w[np.isfinite(w)]
        return bool(not len(w) or float(np.max(w)) < self.speed_limit)

    def _angle_limit(self, rate: float, bandwidth: float) -> float:
        return angle_limit(2.0 * math.pi * bandwidth / rate, self.r_over_l / rate, self.l_ratio, self.feedforward,
                           self.delay_fraction)

    def rate_needed(self, speed: float | None = None) -> float:
        """[Hz] the slowest drive.current_loop_rate stable up to ``speed`` (default: :attr:`max_speed`), the
        bandwidth and the delay as a fraction of the period kept (``p w T_c`` falls and the limit rises with the
        rate); inf beyond a thousand times today's rate."""
        speed = self.max_speed if speed is None else speed
        need = lambda f: self._angle_limit(f, self.bandwidth) - self.pole_pairs * speed / f  # noqa: E731
        if need(self.rate) > 0.0:
            return self.rate
        hi = 2.0 * self.rate
        while need(hi) <= 0.0:
            if hi > 1e3 * self.rate:
                return math.inf
            hi *= 2.0
        return float(brentq(need, hi / 2.0, hi, xtol=1.0))

    def bandwidth_allowed(self, speed: float | None = None) -> float:
        """[Hz] the fastest drive.current_loop_bandwidth stable up to ``speed`` (default: :attr:`max_speed`) at
        this rate (the limit rises as the bandwidth falls, up to about 0.7 rad per period with a whole period of
        delay); 0 when no bandwidth is."""
        speed = self.max_speed if speed is None else speed
        th_need = self.pole_pairs * speed / self.rate
        if self._angle_limit(self.rate, self.bandwidth) > th_need:
            return self.bandwidth
        lo = 1e-3 * self.bandwidth
        if not self._angle_limit(self.rate, lo) > th_need:
            return 0.0
        return float(brentq(lambda b: self._angle_limit(self.rate, b) - th_need, lo, self.bandwidth,
                            xtol=1e-3 * self.bandwidth))

    def unstable_above(self, law: str = "drive.current_controller: complex_vector") -> str:
        """The one sentence every user of this limit prints (the parameter warning, the diagnosis's drive-form and
        voltage-limit-mode checks): ``law`` (how the caller names the controller) is unstable above the rotor
        speed limit, with the angle per period and the fields it comes from."""
        return (f"{law} is unstable above {self.speed_limit:.4g} rad/s ({self.speed_limit_rpm:.0f} rpm) in this "
                f"simulator (p*omega*T_c = {self.angle_limit:.3g} rad with drive.current_loop_bandwidth "
                f"{self.bandwidth:g} Hz at drive.current_loop_rate {self.rate:g} Hz and drive.current_loop_delay "
                f"{self.delay_fraction:.3g} period(s))")

    def message(self, speed: float | None = None, what: str | None = None) -> str:
        """What a user must read when ``speed`` [rad/s] (default: the motor's no-load speed, ``what`` says
        where it comes from) outruns the loop: the fields, the limit in rad/s and rpm, what to change."""
        rpm = lambda w: w * 60.0 / (2.0 * math.pi)  # noqa: E731
        if speed is None:
            speed = self.max_speed
            what = what or f"the motor's no-load speed on drive.bus_voltage {self.bus_voltage:g} V is"
        out = (self.unstable_above()
               + (f"; at the output {self.speed_limit / self.gear_ratio:.4g} rad/s" if self.gear_ratio != 1.0 else "")
               + f": the current loop diverges above it, and {what or 'the speed is'} {speed:.4g} rad/s "
               f"({rpm(speed):.0f} rpm). Keep the speed below the limit, or set drive.current_loop_rate >= "
               f"{self.rate_needed(speed):.0f} Hz" + (f" (drive.current_loop_delay scaled with it: "
                                                      f"{self.delay_fraction:.3g} period(s))" if self.delay_fraction
                                                     else ""))
        bw = self.bandwidth_allowed(speed)
        if bw > 0.0:
            out += f", or drive.current_loop_bandwidth <= {bw:.0f} Hz"
        return out + ", or drive.current_controller: pi"


def speed_limit(*, pole_pairs: int, phase_resistance: float, q_inductance: float, controller_inductance: float,
                bandwidth: float, rate: float, delay: float, feedforward: bool, bus_voltage: float, winding: str,
                torque_constant_q: float, modulation_limit: float = 1.0, gear_ratio: float = 1.0) -> SpeedLimit:
    """:class:`SpeedLimit` of a drive running the complex-vector law (SI units; ``delay`` [s] is capped at one
    period, as the model does). ``params.current_loop_limit`` fills these from a parameter set."""
    dlt = min(max(delay * rate, 0.0), 1.0)
    lam = controller_inductance / q_inductance
    r_over_l = phase_resistance / q_inductance
    th = angle_limit(2.0 * math.pi * bandwidth / rate, r_over_l / rate, lam, feedforward, dlt)
    w_max = float(frames.no_load_speed_max(bus_voltage, torque_constant_q, winding)) * modulation_limit
    return SpeedLimit(angle_limit=th, speed_limit=th * rate / pole_pairs, max_speed=w_max, pole_pairs=int(pole_pairs),
                      gear_ratio=float(gear_ratio), rate=float(rate), bandwidth=float(bandwidth), delay_fraction=dlt,
                      bus_voltage=float(bus_voltage), r_over_l=r_over_l, l_ratio=lam, feedforward=bool(feedforward))
