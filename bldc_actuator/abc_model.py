r"""Reference three-phase (abc) circuit model of a non-salient PMSM/BLDC motor with explicit wye or delta topology.

Used only to *verify* :mod:`bldc_actuator.frames` and the q-axis model (tests, ``bldc-actuator convert --verify``).
It deliberately does **not** use any conversion formula of :mod:`bldc_actuator.frames`: everything here follows
from Kirchhoff's laws on the winding network, the inductance matrix and the magnet flux linkage.

Windings (k = 0, 1, 2 = a, b, c), per winding
    :math:`v_k = R\,i_k + \tfrac{d\psi_k}{dt}`,
    :math:`\boldsymbol\psi = \mathbf{L}\,\mathbf{i} + \boldsymbol\psi_{PM}(\theta_e)`,
    :math:`\mathbf{L} = \begin{bmatrix}L_s&M&M\\M&L_s&M\\M&M&L_s\end{bmatrix}`,
    :math:`\psi_{PM,k} = \tfrac{\bar{K}_b^\phi}{p}\cos(\theta_e - k\,2\pi/3)`,
so the back-EMF is :math:`e_k = -\bar{K}_b^\phi\,\omega_r\sin(\theta_e - k\,2\pi/3)` (paper eqs. for
:math:`K^\phi_{b,A..C}`), :math:`\theta_e = p\,\theta_r`. Torque from the co-energy (flux derivative)
:math:`\tau = \sum_k i_k\,\partial\psi_{PM,k}/\partial\theta_r` (non-salient: no reluctance torque).

Topology (node-branch incidence matrix ``A``, branch k from node ``src[k]`` to node ``dst[k]``):

* wye: nodes A, B, C, N; winding k between lead k and the neutral N;
* delta: nodes A, B, C; winding a between A and B, b between B and C, c between C and A.

Winding voltage :math:`\mathbf{v} = \mathbf{A}^T\mathbf{u}` (node potentials ``u``), current injected into node
n from outside :math:`(\mathbf{A}\mathbf{i})_n` (line current for a lead, zero for the neutral).

Each lead is *voltage driven* (potential imposed by the inverter), *current driven* (line current imposed) or
*open* (floating, zero line current). With the current-constrained nodes ``I`` (open leads, current-driven
leads, neutral), KCL reads :math:`\mathbf{A}_I\mathbf{i} = \mathbf{j}_I(t)`; its solutions are
:math:`\mathbf{i} = \mathbf{i}_p(t) + \mathbf{N}\mathbf{x}` with :math:`\mathbf{N}` an orthonormal basis of the null
space of :math:`\mathbf{A}_I` (mesh/loop currents, e.g. the delta circulating current) and the independent
currents ``x`` obey (Galerkin projection of KVL, the unknown potentials drop out because
:math:`\mathbf{N}^T\mathbf{A}_I^T = 0`)

.. math:: \mathbf{N}^T\mathbf{L}\mathbf{N}\,\dot{\mathbf{x}} = \mathbf{N}^T(\mathbf{A}_V^T\mathbf{u}_V - R\,\mathbf{i}
          - \mathbf{L}\,\dot{\mathbf{i}}_p - \mathbf{e}).

The potentials of the current-constrained nodes follow afterwards from :math:`\mathbf{A}_I^T\mathbf{u}_I =
\mathbf{v} - \mathbf{A}_V^T\mathbf{u}_V` (consistent by construction). The system is integrated with
:func:`scipy.integrate.solve_ivp`; steady states and terminal measurements that have closed forms in the circuit
(DC, phasor) are solved with linear algebra instead (exact to rounding).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import null_space

__all__ = ["AbcMotor", "Drive", "Mechanics", "AbcResult", "simulate", "steady_state_winding_currents",
           "steady_state_line_currents", "measure_terminal_resistance", "measure_terminal_impedance",
           "measure_terminal_inductance", "measure_terminal_inductance_step", "measure_back_emf_ll",
           "measure_kv", "svpwm_duties", "bus_current", "terminal_potentials_for_winding_voltages"]

TWO_PI_3 = 2.0 * math.pi / 3.0
_SHIFT = np.array([0.0, TWO_PI_3, -TWO_PI_3])  # phase k lags by k*2pi/3: theta - 0, theta - 2pi/3, theta + 2pi/3


# ------------------------------------------------------------------------------------------------
# Motor
# ------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class AbcMotor:
    """Three windings with resistance, self and mutual inductance and sinusoidal magnet flux.

    Parameters
    ----------
    winding : {"wye", "delta"}
        Connection of the three windings.
    r_phase : float
        Resistance of one winding R (Ω).
    l_self : float
        Self inductance of one winding L_s (H).
    l_mutual : float
        Mutual inductance between two windings M (H), signed: psi_a = L_s i_a + M i_b + M i_c.
        Physical range -L_s/2 < M < L_s.
    k_b_phase : float
        Amplitude of the back-EMF constant of one winding, Kbar_b^phi (V·s/rad per mechanical rad/s).
    pole_pairs : int
        p; theta_e = p * theta_r.
    """

    winding: str
    r_phase: float
    l_self: float
    l_mutual: float
    k_b_phase: float
    pole_pairs: int = 1

    def __post_init__(self):
        if self.winding not in ("wye", "delta"):
            raise ValueError(f"winding must be 'wye' or 'delta', got {self.winding!r}")
        if not self.r_phase > 0:
            raise ValueError(f"r_phase must be > 0 ohm, got {self.r_phase!r}")
        if not self.l_self > 0:
            raise ValueError(f"l_self must be > 0 H, got {self.l_self!r}")
        if not (-0.5 * self.l_self < self.l_mutual < self.l_self):
            raise ValueError(f"l_mutual must be in (-l_self/2, l_self) for a positive definite inductance "
                             f"matrix, got {self.l_mutual!r} with l_self={self.l_self!r}")
        if not self.k_b_phase >= 0:
            raise ValueError(f"k_b_phase must be >= 0 V*s/rad, got {self.k_b_phase!r}")
        if int(self.pole_pairs) != self.pole_pairs or self.pole_pairs < 1:
            raise ValueError(f"pole_pairs must be an integer >= 1, got {self.pole_pairs!r}")

    # -- matrices -------------------------------------------------------------------------------
    @property
    def inductance_matrix(self) -> np.ndarray:
        """3x3 winding inductance matrix L (H)."""
        L = np.full((3, 3), float(self.l_mutual))
        np.fill_diagonal(L, self.l_self)
        return L

    @property
    def node_names(self) -> tuple[str, ...]:
        return ("A", "B", "C", "N") if self.winding == "wye" else ("A", "B", "C")

    @property
    def incidence(self) -> np.ndarray:
        """Node x branch incidence matrix: +1 where winding k leaves a node, -1 where it enters."""
        if self.winding == "wye":
            A = np.zeros((4, 3))
            for k in range(3):
                A[k, k] = 1.0
                A[3, k] = -1.0
        else:
            A = np.zeros((3, 3))
            for k in range(3):
                A[k, k] = 1.0
                A[(k + 1) % 3, k] = -1.0
        return A

    # -- magnet ---------------------------------------------------------------------------------
    def pm_flux_linkage(self, theta_e) -> np.ndarray:
        r"""Magnet flux linked by each winding :math:`\psi_{PM,k}` (Wb), shape (3, ...)."""
        th = np.asarray(theta_e, dtype=float)
        return (self.k_b_phase / self.pole_pairs) * np.cos(th[None, ...] - _SHIFT.reshape((3,) + (1,) * th.ndim))

    def torque_coefficients(self, theta_e) -> np.ndarray:
        r"""Torque per winding ampere (N·m/A = V·s/rad), shape (3, ...):
        :math:`\partial\psi_{PM,k}/\partial\theta_r = -\bar{K}_b^\phi\sin(\theta_e - k\,2\pi/3)`, the paper's
        :math:`K^\phi_{t,k}(\theta)`."""
        th = np.asarray(theta_e, dtype=float)
        return -self.k_b_phase * np.sin(th[None, ...] - _SHIFT.reshape((3,) + (1,) * th.ndim))

    def back_emf(self, theta_e, omega_r) -> np.ndarray:
        r"""Winding back-EMF :math:`e_k = d\psi_{PM,k}/dt` (V), shape (3, ...); ``omega_r`` mechanical rad/s."""
        return self.torque_coefficients(theta_e) * np.asarray(omega_r, dtype=float)

    def torque(self, i_w, theta_e) -> np.ndarray:
        r"""Electromagnetic torque :math:`\tau = \sum_k i_k\,\partial\psi_{PM,k}/\partial\theta_r` (N·m)."""
        return np.sum(self.torque_coefficients(theta_e) * np.asarray(i_w, dtype=float), axis=0)

    def joule_loss(self, i_w) -> np.ndarray:
        r""":math:`P = R\sum_k i_k^2` (W)."""
        return self.r_phase * np.sum(np.asarray(i_w, dtype=float) ** 2, axis=0)

    # -- network maps -----------------------------------------------------------------------------
    def line_currents(self, i_w) -> np.ndarray:
        """Line currents into leads A, B, C (A) from winding currents, shape (3, ...)."""
        return np.tensordot(self.incidence[:3], np.asarray(i_w), axes=(1, 0))

    def winding_voltages(self, u_nodes) -> np.ndarray:
        """Winding voltages A^T u (V) from node potentials (all nodes, including the wye neutral)."""
        return np.tensordot(self.incidence.T, np.asarray(u_nodes, dtype=float), axes=(1, 0))

    @staticmethod
    def line_to_line(u_terminals) -> np.ndarray:
        """(u_A - u_B, u_B - u_C, u_C - u_A) (V), shape (3, ...)."""
        u = np.asarray(u_terminals, dtype=float)
        return np.stack([u[0] - u[1], u[1] - u[2], u[2] - u[0]])


# ------------------------------------------------------------------------------------------------
# Drive, mechanics, result
# ------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Drive:
    """What happens at each lead: ``"v"`` potential imposed, ``"i"`` line current imposed, ``"open"`` floating.

    ``voltage(t, theta_e, omega_r) -> array(3)`` gives the lead potentials (V; only "v" leads are used).
    ``current(t, theta_e, omega_r) -> (i_line(3), di_line/dt(3))`` gives the imposed line currents (A, A/s;
    only "i" leads are used; if all three leads are current driven the currents must sum to zero).
    """

    modes: tuple[str, str, str]
    voltage: Optional[Callable] = None
    current: Optional[Callable] = None

    def __post_init__(self):
        if len(self.modes) != 3 or any(m not in ("v", "i", "open") for m in self.modes):
            raise ValueError(f"modes must be three of 'v', 'i', 'open', got {self.modes!r}")
        if "v" in self.modes and self.voltage is None:
            raise ValueError("voltage-driven leads need a voltage function")
        if "i" in self.modes and self.current is None:
            raise ValueError("current-driven leads need a current function")

    @classmethod
    def terminal_voltages(cls, fn: Callable, floating: Sequence[int] = ()) -> "Drive":
        """Leads at potentials ``fn(t, theta_e, omega_r)``, leads in ``floating`` open."""
        return cls(tuple("open" if k in floating else "v" for k in range(3)), voltage=fn)

    @classmethod
    def line_currents(cls, fn: Callable) -> "Drive":
        """All three line currents imposed: ``fn(t, theta_e, omega_r) -> (i_line, di_line_dt)``."""
        return cls(("i", "i", "i"), current=fn)

    @classmethod
    def open_circuit(cls) -> "Drive":
        return cls(("open", "open", "open"))

    @classmethod
    def between_leads(cls, lead_pos: int, lead_neg: int, fn: Callable) -> "Drive":
        """Voltage ``fn(t)`` (V) between two leads (lead_pos at +fn, lead_neg at 0), third lead open."""
        modes = ["open"] * 3
        modes[lead_pos] = modes[lead_neg] = "v"

        def volt(t, theta_e, omega_r):
            u = np.zeros(3)
            u[lead_pos] = fn(t)
            return u
        return cls(tuple(modes), voltage=volt)


@dataclass(frozen=True)
class Mechanics:
    """Rotor dynamics J dω/dt = τ - b ω - τ_load(t, ω) (motor side, SI)."""

    inertia: float
    damping: float = 0.0
    load_torque: Callable[[float, float], float] = field(default=lambda t, w: 0.0)


@dataclass
class AbcResult:
    """Time (or angle) series of every circuit quantity; arrays with a leading axis of 3 are per winding/lead."""

    t: np.ndarray
    theta_e: np.ndarray
    omega: np.ndarray            #: rotor mechanical speed (rad/s)
    i_w: np.ndarray              #: winding currents (A)
    di_w: np.ndarray             #: their time derivatives (A/s)
    i_line: np.ndarray           #: line currents into leads A, B, C (A)
    u_nodes: np.ndarray          #: node potentials (V): A, B, C (+ N for wye)
    v_w: np.ndarray              #: winding voltages (V)
    e: np.ndarray                #: winding back-EMF (V)
    torque: np.ndarray           #: electromagnetic torque (N·m)
    joule: np.ndarray            #: Joule loss (W)

    @property
    def u_terminals(self) -> np.ndarray:
        return self.u_nodes[:3]

    @property
    def v_ll(self) -> np.ndarray:
        """(v_AB, v_BC, v_CA) (V)."""
        return AbcMotor.line_to_line(self.u_nodes[:3])

    @property
    def p_terminal(self) -> np.ndarray:
        """Electrical power into the leads Σ u_k i_line_k (W)."""
        return np.sum(self.u_nodes[:3] * self.i_line, axis=0)

    @property
    def p_winding(self) -> np.ndarray:
        """Σ v_k i_k over the windings (W) (Tellegen: equals p_terminal)."""
        return np.sum(self.v_w * self.i_w, axis=0)


# ------------------------------------------------------------------------------------------------
# Network solver
# ------------------------------------------------------------------------------------------------

class _Network:
    """Partition of the nodes into potential-imposed (V) and current-constrained (I) sets, mesh basis N."""

    def __init__(self, motor: AbcMotor, modes: Sequence[str]):
        A = motor.incidence
        n_nodes = A.shape[0]
        node_modes = list(modes) + (["open"] if n_nodes == 4 else [])  # the neutral is never driven
        self.V = [k for k in range(n_nodes) if node_modes[k] == "v"]
        self.I = [k for k in range(n_nodes) if node_modes[k] != "v"]
        self.cur = [k for k in range(3) if node_modes[k] == "i"]
        self.A, self.A_V, self.A_I = A, A[self.V], A[self.I]
        self.N = null_space(self.A_I) if self.I else np.eye(3)
        self.P = np.linalg.pinv(self.A_I) if self.I else np.zeros((3, 0))
        self.L = motor.inductance_matrix
        self.LN = self.N.T @ self.L @ self.N
        self.n = self.N.shape[1]

    def injections(self, i_line: np.ndarray) -> np.ndarray:
        """Imposed injections into the I nodes (zero for open leads and the neutral)."""
        j = np.zeros(len(self.I))
        for row, node in enumerate(self.I):
            if node in self.cur:
                j[row] = i_line[node]
        return j


@functools.lru_cache(maxsize=64)
def _network(motor: AbcMotor, modes: tuple[str, ...]) -> _Network:
    return _Network(motor, modes)


def _solve_potentials(net: _Network, v_w: np.ndarray, u_V: np.ndarray, n_nodes: int) -> np.ndarray:
    """Node potentials from winding voltages: A_I^T u_I = v_w - A_V^T u_V (least squares, consistent)."""
    u = np.zeros((n_nodes,) + v_w.shape[1:])
    if net.V:
        u[net.V] = u_V
    if net.I:
        rhs = v_w - (net.A_V.T @ u_V if net.V else 0.0)
        sol = np.linalg.lstsq(net.A_I.T, rhs.reshape(3, -1), rcond=None)[0]
        u[net.I] = sol.reshape((len(net.I),) + v_w.shape[1:])
    if not net.V:  # potentials only defined up to a constant: zero mean over the three leads
        u = u - np.mean(u[:3], axis=0)
    return u


def simulate(motor: AbcMotor, drive: Drive, t_eval: np.ndarray, *, omega: float | Callable = 0.0,
             theta0: float = 0.0, mechanics: Mechanics | None = None, x0: np.ndarray | None = None,
             method: str = "DOP853", rtol: float = 1e-10, atol: float = 1e-12,
             max_step: float = np.inf) -> AbcResult:
    """Integrate the circuit (and optionally the rotor) with :func:`scipy.integrate.solve_ivp`.

    Parameters
    ----------
    motor : AbcMotor
    drive : Drive
        Lead conditions and sources.
    t_eval : ndarray
        Output times (s), increasing; integration starts at ``t_eval[0]``.
    omega : float or callable(t) -> float
        Imposed rotor speed (mechanical rad/s) when ``mechanics`` is None; initial speed otherwise.
    theta0 : float
        Initial rotor mechanical angle (rad).
    mechanics : Mechanics, optional
        Integrate the rotor speed instead of imposing it.
    x0 : ndarray, optional
        Initial independent (mesh) currents; default zero (the winding currents start at the particular
        solution of the imposed line currents, i.e. zero for a voltage drive).
    method, rtol, atol, max_step
        Passed to :func:`scipy.integrate.solve_ivp`.

    Returns
    -------
    AbcResult
    """
    net = _network(motor, tuple(drive.modes))
    t_eval = np.asarray(t_eval, dtype=float)
    p = motor.pole_pairs
    R = motor.r_phase
    omega_fn = omega if callable(omega) else (lambda t, w=float(omega): w)
    n = net.n
    LN_inv = np.linalg.inv(net.LN) if n else np.zeros((0, 0))

    def sources(t, theta_r, w):
        th_e = p * theta_r
        u_all = drive.voltage(t, th_e, w) if drive.voltage is not None else np.zeros(3)
        if drive.current is not None:
            i_line, di_line = (np.asarray(a, dtype=float) for a in drive.current(t, th_e, w))
        else:
            i_line, di_line = np.zeros(3), np.zeros(3)
        i_p = net.P @ net.injections(i_line)
        di_p = net.P @ net.injections(di_line)
        u_V = np.asarray(u_all, dtype=float)[net.V] if net.V else np.zeros(0)
        return th_e, u_V, i_p, di_p

    def currents_and_derivative(t, y):
        x, theta_r = y[:n], y[n]
        w = y[n + 1] if mechanics is not None else omega_fn(t)
        th_e, u_V, i_p, di_p = sources(t, theta_r, w)
        i = i_p + net.N @ x
        e = motor.back_emf(th_e, w)
        drive_v = net.A_V.T @ u_V if net.V else np.zeros(3)
        rhs = net.N.T @ (drive_v - R * i - net.L @ di_p - e)
        dx = LN_inv @ rhs
        di = di_p + net.N @ dx
        return x, theta_r, w, th_e, u_V, i, di, e, dx

    def f(t, y):
        x, theta_r, w, th_e, u_V, i, di, e, dx = currents_and_derivative(t, y)
        out = [dx, [w]]
        if mechanics is not None:
            tau = float(motor.torque(i, th_e))
            out.append([(tau - mechanics.damping * w - mechanics.load_torque(t, w)) / mechanics.inertia])
        return np.concatenate(out)

    y0 = np.concatenate([np.zeros(n) if x0 is None else np.asarray(x0, dtype=float), [theta0]]
                        + ([[omega_fn(t_eval[0])]] if mechanics is not None else []))
    sol = solve_ivp(f, (t_eval[0], t_eval[-1]), y0, t_eval=t_eval, method=method, rtol=rtol, atol=atol,
                    max_step=max_step)
    if not sol.success:
        raise RuntimeError(f"abc model integration failed: {sol.message}")

    n_nodes = motor.incidence.shape[0]
    cols = {k: [] for k in ("th", "w", "i", "di", "e", "uV")}
    for j in range(len(sol.t)):
        _, _, w, th_e, u_V, i, di, e, _ = currents_and_derivative(sol.t[j], sol.y[:, j])
        for key, val in zip(("th", "w", "i", "di", "e", "uV"), (th_e, w, i, di, e, u_V)):
            cols[key].append(val)
    i_w, di_w, e = (np.array(cols[k]).T for k in ("i", "di", "e"))
    th = np.array(cols["th"])
    v_w = R * i_w + net.L @ di_w + e
    u_V = np.array(cols["uV"], dtype=float).reshape(len(sol.t), len(net.V)).T
    u = _solve_potentials(net, v_w, u_V, n_nodes)
    return AbcResult(t=sol.t, theta_e=th, omega=np.array(cols["w"]), i_w=i_w, di_w=di_w,
                     i_line=motor.line_currents(i_w), u_nodes=u, v_w=v_w,
                     e=e, torque=motor.torque(i_w, th), joule=motor.joule_loss(i_w))


# ------------------------------------------------------------------------------------------------
# Sinusoidal steady states (closed form in the circuit, exact to rounding)
# ------------------------------------------------------------------------------------------------

def _steady_result(motor: AbcMotor, theta_e, omega_r, i_w, di_w) -> AbcResult:
    theta_e = np.asarray(theta_e, dtype=float)
    e = motor.back_emf(theta_e, omega_r)
    v_w = motor.r_phase * i_w + np.tensordot(motor.inductance_matrix, di_w, axes=(1, 0)) + e
    net = _network(motor, ("i", "i", "i"))
    u = _solve_potentials(net, v_w, np.zeros((0,) + theta_e.shape), motor.incidence.shape[0])
    w_e = motor.pole_pairs * omega_r
    t = theta_e / w_e if w_e != 0 else np.full(theta_e.shape, np.nan)
    return AbcResult(t=t, theta_e=theta_e, omega=np.full(theta_e.shape, float(omega_r)), i_w=i_w, di_w=di_w,
                     i_line=motor.line_currents(i_w), u_nodes=u, v_w=v_w, e=e,
                     torque=motor.torque(i_w, theta_e), joule=motor.joule_loss(i_w))


def steady_state_winding_currents(motor: AbcMotor, i_phase_peak: float, theta_e, omega_r: float,
                                  phase_offset: float = 0.0) -> AbcResult:
    r"""Sinusoidal steady state with commutated winding currents (paper eq. ``phase_currents``).

    :math:`i_k = -\bar{I}^\phi\sin(\theta_e - k\,2\pi/3 + \gamma)` (γ = ``phase_offset``; 0 = in phase with the
    back-EMF), at constant speed ``omega_r`` (mechanical rad/s). Winding voltages from KVL,
    :math:`\mathbf{v} = R\mathbf{i} + \mathbf{L}\,d\mathbf{i}/dt + \mathbf{e}` with
    :math:`d/dt = p\,\omega_r\,d/d\theta_e`;
    lead potentials from :math:`\mathbf{A}^T\mathbf{u} = \mathbf{v}` (zero mean over the leads). For delta
    this requires no circulating current, which is the steady state of the loop for a balanced motor.
    """
    th = np.asarray(theta_e, dtype=float)
    shift = _SHIFT.reshape((3,) + (1,) * th.ndim)
    arg = th[None, ...] - shift + phase_offset
    i_w = -i_phase_peak * np.sin(arg)
    di_w = -i_phase_peak * np.cos(arg) * (motor.pole_pairs * omega_r)
    return _steady_result(motor, th, omega_r, i_w, di_w)


def steady_state_line_currents(motor: AbcMotor, i_line_peak: float, theta_e, omega_r: float,
                               phase_offset: float = 0.0) -> AbcResult:
    r"""Sinusoidal steady state with imposed line currents
    :math:`i_{k}^{l} = -\bar{I}^l\sin(\theta_e - k\,2\pi/3 + \gamma)`.

    Winding currents from KCL (``A i = j``); the delta circulating current is zero in steady state
    (its loop equation :math:`3(L_s + 2M)\,di_0/dt + 3R\,i_0 = -\sum_k e_k = 0` decays). A drive that does not
    know the winding puts the delta winding currents 30° ahead of the line currents, i.e. off the back-EMF;
    the best ``phase_offset`` is found by the caller.
    """
    th = np.asarray(theta_e, dtype=float)
    shift = _SHIFT.reshape((3,) + (1,) * th.ndim)
    arg = th[None, ...] - shift + phase_offset
    i_l = -i_line_peak * np.sin(arg)
    di_l = -i_line_peak * np.cos(arg) * (motor.pole_pairs * omega_r)
    net = _network(motor, ("i", "i", "i"))
    nI = len(net.I)
    inj = np.zeros((nI,) + th.shape)
    dinj = np.zeros((nI,) + th.shape)
    inj[:3], dinj[:3] = i_l, di_l
    i_w = np.tensordot(net.P, inj, axes=(1, 0))
    di_w = np.tensordot(net.P, dinj, axes=(1, 0))
    return _steady_result(motor, th, omega_r, i_w, di_w)


def terminal_potentials_for_winding_voltages(motor: AbcMotor, v_w) -> np.ndarray:
    """Lead potentials (zero mean) that put winding voltages ``v_w`` (3, ...) on the windings.

    Wye: the lead-to-neutral voltages (zero-sequence removed). Delta: requires Σ v_w = 0 (the loop).
    """
    v_w = np.asarray(v_w, dtype=float)
    net = _network(motor, ("i", "i", "i"))
    u = _solve_potentials(net, v_w, np.zeros((0,) + v_w.shape[1:]), motor.incidence.shape[0])
    return u[:3]


# ------------------------------------------------------------------------------------------------
# Terminal measurements (two leads driven, third floating)
# ------------------------------------------------------------------------------------------------

def _two_lead_network(motor: AbcMotor, leads: tuple[int, int]) -> tuple[_Network, np.ndarray]:
    modes = ["open"] * 3
    modes[leads[0]] = modes[leads[1]] = "v"
    net = _network(motor, tuple(modes))
    u_V = np.array([1.0 if node == leads[0] else 0.0 for node in net.V])  # 1 V across the pair
    return net, u_V


def measure_terminal_impedance(motor: AbcMotor, frequency: float, leads: tuple[int, int] = (0, 1),
                               theta_e: float = 0.0) -> complex:
    r"""Complex impedance Z (Ω) between two leads at ``frequency`` (Hz), third lead open, rotor locked.

    Phasor solution of the mesh equations :math:`\mathbf{N}^T(R + j\omega\mathbf{L})\mathbf{N}\,\mathbf{x} =
    \mathbf{N}^T\mathbf{A}_V^T\mathbf{u}_V` (an LCR meter). ``frequency = 0`` gives the DC resistance.
    Non-salient motor: independent of the rotor angle.
    """
    net, u_V = _two_lead_network(motor, leads)
    w = 2.0 * math.pi * frequency
    Z = net.N.T @ (motor.r_phase * np.eye(3) + 1j * w * motor.inductance_matrix) @ net.N
    x = np.linalg.solve(Z, net.N.T @ (net.A_V.T @ u_V))
    i_line = motor.line_currents(net.N @ x)
    return complex(1.0 / i_line[leads[0]])


def measure_terminal_resistance(motor: AbcMotor, leads: tuple[int, int] = (0, 1)) -> float:
    """Terminal (line-to-line) resistance R^ll (Ω): DC voltage across two leads / lead current, third open."""
    return measure_terminal_impedance(motor, 0.0, leads).real


def measure_terminal_inductance(motor: AbcMotor, frequency: float = 1000.0, leads: tuple[int, int] = (0, 1)) -> float:
    """Terminal inductance L^ll (H) = Im(Z)/(2πf) from :func:`measure_terminal_impedance` (rotor locked)."""
    return measure_terminal_impedance(motor, frequency, leads).imag / (2.0 * math.pi * frequency)


def measure_terminal_inductance_step(motor: AbcMotor, leads: tuple[int, int] = (0, 1),
                                     voltage: float = 1.0) -> tuple[float, float]:
    r"""Time-domain terminal test: voltage step across two leads (third open), integrate with solve_ivp.

    Fits :math:`i(t) = I_\infty(1 - e^{-t/\tau})`: :math:`R^{ll} = V/I_\infty` from the end of the record and
    :math:`\tau` from the slope of :math:`\ln(1 - i/I_\infty)`; returns ``(R_ll, L_ll = tau * R_ll)``.
    """
    # a time scale guess that does not use any conversion: the slowest eigenvalue of R L^-1
    tau_guess = max(np.linalg.eigvalsh(motor.inductance_matrix)) / motor.r_phase
    drive = Drive.between_leads(leads[0], leads[1], lambda t: voltage)
    t_end = 40.0 * tau_guess
    t = np.linspace(0.0, t_end, 4001)
    res = simulate(motor, drive, t, omega=0.0, rtol=1e-12, atol=1e-15)
    i = res.i_line[leads[0]]
    i_inf = i[-1]
    r_ll = voltage / i_inf
    mask = (t > 0) & (t < 3.0 * tau_guess) & (i < 0.95 * i_inf)
    slope = np.polyfit(t[mask], np.log(1.0 - i[mask] / i_inf), 1)[0]
    return r_ll, -r_ll / slope


def measure_back_emf_ll(motor: AbcMotor, omega_r: float | None = None,
                        samples: int = 256) -> tuple[float, AbcResult]:
    r"""Open-circuit test: spin at ``omega_r`` (mechanical rad/s), all leads open, record :math:`v_{AB}` over one
    electrical period (simulated: the delta loop current is a state) and return the fundamental amplitude
    per rad/s, :math:`\bar{K}_b^{ll}` (V·s/rad), and the record.

    ``omega_r=None`` picks a speed whose electrical period is 20 time constants of the delta loop
    (:math:`(L_s + 2M)/R`), which keeps the explicit integrator short; the result does not depend on speed.
    """
    if omega_r is None:
        tau0 = (motor.l_self + 2.0 * motor.l_mutual) / motor.r_phase
        omega_r = 2.0 * math.pi / (20.0 * tau0) / motor.pole_pairs
    w_e = motor.pole_pairs * omega_r
    period = 2.0 * math.pi / w_e
    t = np.linspace(0.0, period, samples, endpoint=False)
    res = simulate(motor, Drive.open_circuit(), t, omega=omega_r)
    v_ab = res.v_ll[0]
    amp = 2.0 * abs(np.sum(v_ab * np.exp(-1j * res.theta_e))) / samples
    return amp / omega_r, res


def measure_kv(motor: AbcMotor, omega_r: float | None = None) -> float:
    """Kv (rpm/V) as no-load rpm per volt of line-to-line PEAK back-EMF, from :func:`measure_back_emf_ll`."""
    k_ll, _ = measure_back_emf_ll(motor, omega_r)
    return 60.0 / (2.0 * math.pi * k_ll)


# ------------------------------------------------------------------------------------------------
# Inverter
# ------------------------------------------------------------------------------------------------

def svpwm_duties(u_terminals, bus_voltage: float) -> np.ndarray:
    r"""Average-model SVPWM (min-max zero-sequence injection): duty of each half bridge.

    :math:`d_k = \tfrac12 + (u_k - \tfrac12(\max_j u_j + \min_j u_j))/V_{bus}`. All duties lie in [0, 1] exactly
    when every line-to-line voltage :math:`|u_j - u_k| \le V_{bus}`; values outside mean overmodulation.
    """
    u = np.asarray(u_terminals, dtype=float)
    mid = 0.5 * (np.max(u, axis=0) + np.min(u, axis=0))
    return 0.5 + (u - mid) / bus_voltage


def bus_current(duties, i_line) -> np.ndarray:
    r"""DC bus current of a lossless inverter (average model): :math:`I_{bus} = \sum_k d_k\,i^l_k` (A)."""
    return np.sum(np.asarray(duties) * np.asarray(i_line), axis=0)
