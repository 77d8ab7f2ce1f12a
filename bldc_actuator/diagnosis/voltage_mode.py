"""Diagnosis of a voltage-mode actuator without a current sensor: the mechanical equation closed by the voltage.

A DC motor (or a BLDC in voltage mode, its q-axis equivalent) driven by a voltage (duty x supply, mapped as
``voltage_q``) whose log holds the voltage and the motion but no current. The winding gives the current from
the voltage, i = (v - K ω)/R, lagged by the electrical time constant τ_e = L/R where the sampling resolves it
(τ_e ≥ 0.1 sample: i = LP_τe[(v - K ω)/R], a first-order lag, else the static form), so on the motor side::

    J dω/dt = (K/R) v_f - (K²/R + b) ω_f - (τ_c + μ |τ_m|) sign(ω) - τ_0,    τ_m = (K/R)(v_f - K ω_f)

(K the q-axis torque constant ``motor.torque_constant_q`` = back-EMF constant, R ``motor.phase_resistance``, b
``motor.viscous_damping``, τ_c ``effects.coulomb_friction``, μ ``effects.gear_load_friction`` (a gear friction
growing with the motor's torque τ_m, :mod:`.effects.torque_dependent_gear_friction`; its column is built from the
current the voltage gives, at the fitted K/R), J ``motor.rotor_inertia``, τ_0 a constant torque:
a load, a voltage offset; ``_f`` the lagged columns). Without current the equation is homogeneous: the data fix
the ratios to J, so with J nominal three COMBINATIONS are identifiable — K/R, K²/R + b and τ_c — and, free of J,
their ratios: the effective back-EMF constant (K²/R + b)/(K/R) = K + b R/K [V*s/rad] and the break-away
voltage τ_c/(K/R) [V]. K and R apart, and b apart from K²/R, are not: b is reported given K nominal.

Search: each combination freed from its nominal value in turn (forward selection, ΔBIC > 10 and a better
held-out equation error on interleaved blocks), samples near standstill (|ω| below 2 % of its 95th percentile)
left out of the fit (there static friction holds whatever the voltage gives). Judge: the frame's window replay
has no voltage-commanded DC drive, so the judge's channel is this route's own ODE — the mechanical equation
integrated under the recorded voltage from the recorded speed at each held-out window's start (exact per
sub-interval for the linear part, stick/slip at zero speed: :func:`simulate_speed`) — and a finding is kept
when leaving it out makes the paired per-window squared speed error worse by more than two standard errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .effects import torque_dependent_gear_friction as gear_friction
from .frame.least_squares import ols
from .signals import Signals, fill_gaps
from .torque_balance import Term

BIC_GATE = 10.0
#: fraction of a sample the electrical time constant must reach for its lag to be modelled
TAU_E_RESOLVED = 0.1
WINDOW_S = 0.5            #: held-out replay window [s]
SUBSTEPS = 4              #: integration sub-intervals per sample in the replay


def _has(sig: Signals, name: str) -> bool:
    v = sig.channels.get(name)
    return v is not None and int(np.isfinite(v).sum()) >= 20


def applicable(sig: Signals) -> bool:
    """Voltage and motion are logged, current is not (nor a current command)."""
    return (_has(sig, "voltage_q") and (_has(sig, "velocity") or _has(sig, "position"))
            and not _has(sig, "current") and not _has(sig, "current_command"))


def effect_for(field_name: str) -> str:
    """The effect that writes the parameter-file field ``field_name``: the effect registry's where it exists,
    else the effect library's name sharing a word with the field (in library order)."""
    try:
        from .effects import registry  # type: ignore[attr-defined]

        hits = registry.by_field(field_name)
        if hits:
            return hits[0].name
    except ImportError:
        pass
    import re

    from .frame.candidates import library

    lib = library()
    leaf = field_name.rsplit(".", 1)[-1]
    if leaf in lib:
        return leaf
    words = set(re.split(r"[._]", field_name))

    def score(c) -> int:
        return len(words & set(re.findall(r"[a-z]+", (c.name.replace("_", " ") + " " + c.description).lower())))

    best = max(lib.values(), key=score)            # the first of equal scores, in library order
    if not score(best):
        raise KeyError(f"no effect writes {field_name}")
    return best.name


# --------------------------------------------------------------------------------------------- records


@dataclass
class VoltageModeResult:
    findings: list[Term]
    rejected: list[Term]
    #: the identified combinations (free fit of all three): name -> value, sd, unit, nominal, how identified
    combinations: dict
    notes: list[str]
    held_out: dict
    simulation: dict             #: nominal vs updated held-out replay (speed RMS) and the judge's channel
    electrical_lag: bool
    n_fit: int = 0
    coefficients: dict = field(default_factory=dict)   #: the final model: k_over_r, damping, coulomb, gear, offset

    def to_dict(self) -> dict:
        def t(x: Term) -> dict:
            return {"effect": x.effect, "parameters": x.parameters, "uncertainty": x.uncertainty, "units": x.units,
                    "held_out": x.held_out, "delta_bic": x.delta_bic, "reason": x.reason, "simulation": x.simulation}

        return {"method": "voltage mode (no current sensor)", "combinations": self.combinations,
                "held_out": self.held_out, "simulation": self.simulation, "findings": [t(x) for x in self.findings],
                "rejected": [t(x) for x in self.rejected], "notes": self.notes}


# --------------------------------------------------------------------------------------------- signals

def _lag_coefficients(a, tau_over_dt):
    """``(b0, b1)`` of the first-order lag for an input linear between samples (:func:`_lag`)."""
    return 1.0 - tau_over_dt * (1.0 - a), tau_over_dt * (1.0 - a) - a


def _lag(x: np.ndarray, a: float, tau_over_dt: float) -> np.ndarray:
    """The first-order lag 1/(1 + τ s) of ``x`` linear between samples (exact for that input), started at x_0:
    y_k = a y_(k-1) + b0 x_k + b1 x_(k-1), a = exp(-dt/τ)."""
    from scipy.signal import lfilter

    if not len(x):
        return x
    b0, b1 = _lag_coefficients(a, tau_over_dt)
    zi = np.array([(1.0 - b0) * x[0]])          # the steady state at x_0
    return lfilter([b0, b1], [1.0, -a], x, zi=zi)[0]


@dataclass
class _Columns:
    t: np.ndarray
    v: np.ndarray          #: voltage as the current sees it (lagged by τ_e where resolved)
    w_f: np.ndarray        #: speed lagged like the voltage (the back-EMF's share of the current)
    w: np.ndarray          #: smoothed speed (window starts, standstill and reversal tests)
    w_raw: np.ndarray      #: the speed as logged (motor side)
    v_raw: np.ndarray      #: the voltage as logged
    seg: np.ndarray        #: segment index per sample
    ok: np.ndarray
    m: int                 #: samples per fitted interval
    th: np.ndarray | None = None   #: motor-side angle from the position channel (None without one)
    #: [s] the velocity channel's lag behind the angle's speed (a drive's filtered speed estimate), 0: none measured
    tau_v: float = 0.0
    #: the motor's speed with that lag taken out (smoothed): its sign, the replay's start
    w_true: np.ndarray | None = None
    #: sign(w_true) lagged like the velocity channel: the friction's direction as the logged speed's equation sees it
    sgn: np.ndarray | None = None
    #: sin and cos of the output angle θ/N, lagged like the velocity channel (a gravity-like load's columns)
    th_sin: np.ndarray | None = None
    th_cos: np.ndarray | None = None


#: a velocity channel's lag is modelled when it exceeds this fraction of a sample ...
TAU_V_RESOLVED = 0.25
#: ... and its gain against the angle's speed is 1 within this (else the two do not measure the same speed)
TAU_V_GAIN_TOLERANCE = 0.1
#: the band [Hz, at most this fraction of the sample rate] the lag is measured in (the angle's quantization above)
TAU_V_BAND_HZ = 10.0
TAU_V_BAND_FRACTION = 0.1


def velocity_lag(sig: Signals) -> tuple[float, float] | None:
    """``(lag [s], gain)`` of the velocity channel ``w`` behind the speed ``ω`` of the angle channel (both logged,
    motor side): least squares on ``ω ≈ (w + δ w') / g`` of the two low-passed alike (zero phase,
    :data:`TAU_V_BAND_HZ`), the inverse of a first-order lag, a drive's filtered speed estimate (a low pass at f has
    δ = 1/(2 pi f)). The noisier angle's speed is the target, the smoother channel and its derivative the columns (the
    other way round the angle's quantization noise in the columns biased δ low: 7.0 ms for a true 8.5). None
    without both channels or motion. The main pipeline measures the same lag (``frame.equation_error._lag``) and takes the
    speed from the angle; here the speed stays the velocity channel's and the equation is lagged alike."""
    from scipy.signal import butter

    from ..zero_phase import sosfiltfilt

    if not (_has(sig, "velocity") and _has(sig, "position")):
        return None
    A, B, C = [], [], []
    for s, e in sig.segments or [(0, len(sig.time))]:
        if e - s < 60:
            continue
        t = sig.time[s:e]
        dt = float(np.median(np.diff(t)))
        f = min(TAU_V_BAND_HZ, TAU_V_BAND_FRACTION / dt)
        sos = butter(2, f * 2.0 * dt, output="sos")
        w = sosfiltfilt(sos, fill_gaps(sig.channels["velocity"][s:e]))
        wt = sosfiltfilt(sos, np.gradient(fill_gaps(sig.channels["position"][s:e]), t))
        edge = min(int(3.0 / (f * dt)), (e - s) // 4)
        sl = slice(edge, e - s - edge)
        A.append(wt[sl]), B.append(w[sl]), C.append(np.gradient(w, t)[sl])
    if not A:
        return None
    a, b, d = np.concatenate(A), np.concatenate(B), np.concatenate(C)
    try:
        (c0, c1), *_ = np.linalg.lstsq(np.column_stack([b, d]), a, rcond=None)
    except np.linalg.LinAlgError:
        return None
    if not (math.isfinite(c0) and c0 > 0 and math.isfinite(c1)):
        return None
    return float(c1 / c0), float(1.0 / c0)


def _columns(sig: Signals, tau_e: float, gear: float = 1.0) -> tuple[_Columns, bool, str]:
    from scipy.signal import savgol_filter

    ch = sig.channels
    n = len(sig.time)
    cols = {k: np.full(n, np.nan) for k in ("v", "w_f", "w", "w_raw", "v_raw")}
    th = np.full(n, np.nan) if _has(sig, "position") else None
    seg = np.full(n, -1)
    lagged = False
    how = "speed channel" if _has(sig, "velocity") else "speed differentiated from the angle"
    dt_all = float(np.median(np.diff(sig.time))) if n > 1 else 1.0
    tau_v = 0.0
    lag = velocity_lag(sig)
    if lag is not None:
        d_v, g_v = lag
        if abs(g_v - 1.0) > TAU_V_GAIN_TOLERANCE:
            how += (f" (its gain against the angle's speed is {g_v:.3g}: not the same speed, so its lag is not "
                    f"measured)")
        elif d_v > TAU_V_RESOLVED * dt_all:
            tau_v = d_v
            how += (f", which lags the angle's speed by {1e3 * d_v:.3g} ms (a filtered speed estimate): the "
                    f"equation's other columns are lagged alike (a first-order lag), the friction's direction "
                    f"taken from the speed with the lag taken out")
        else:
            how += f" (aligned with the angle's speed: lag {1e3 * d_v:.2g} ms)"
    w_true = np.full(n, np.nan)
    sgn = np.full(n, np.nan)
    th_sin = np.full(n, np.nan) if th is not None else None
    th_cos = np.full(n, np.nan) if th is not None else None

    m = max(1, int(round(0.02 / max(dt_all, 1e-9))))
    for k, (s, e) in enumerate(sig.segments or [(0, n)]):
        if e - s < 9:
            continue
        t = sig.time[s:e]
        dt = float(np.median(np.diff(t)))
        v = fill_gaps(ch["voltage_q"][s:e])
        w = fill_gaps(ch["velocity"][s:e]) if _has(sig, "velocity") else np.gradient(fill_gaps(ch["position"][s:e]), t)
        win = min(e - s - (1 - (e - s) % 2), max(5, int(round(0.02 / max(dt, 1e-9))) | 1))
        vf, wf = v, w
        if tau_e >= TAU_E_RESOLVED * dt:
            a_ = math.exp(-dt / tau_e)
            vf, wf = _lag(v, a_, tau_e / dt), _lag(w, a_, tau_e / dt)
            lagged = True
        ws = savgol_filter(w, win, 2)
        wt = ws + tau_v * savgol_filter(w, win, 2, deriv=1, delta=dt) if tau_v > 0 else ws
        lag_v = (lambda x: _lag(x, math.exp(-dt / tau_v), tau_v / dt)) if tau_v > 0 else (lambda x: x)
        cols["v"][s:e], cols["w_f"][s:e], cols["w"][s:e] = lag_v(vf), wf, ws
        cols["w_raw"][s:e], cols["v_raw"][s:e] = w, v
        w_true[s:e], sgn[s:e] = wt, lag_v(np.sign(wt))
        if th is not None:
            th[s:e] = fill_gaps(ch["position"][s:e])
            th_sin[s:e], th_cos[s:e] = lag_v(np.sin(th[s:e] / gear)), lag_v(np.cos(th[s:e] / gear))
        seg[s:e] = k
    ok = np.all([np.isfinite(c) for c in cols.values()], axis=0) & (seg >= 0)
    c = _Columns(sig.time, cols["v"], cols["w_f"], cols["w"], cols["w_raw"], cols["v_raw"], seg, ok, m, th,
                 tau_v=tau_v, w_true=w_true, sgn=sgn, th_sin=th_sin, th_cos=th_cos)
    return c, lagged, how


def _intervals(c: _Columns, w_eps: float, viscous_share: float = 0.0, gear: float = 1.0):
    """The equation integrated over intervals of ``c.m`` samples (no differentiated speed, no filter gain on one
    side only): J Δω/Δt = (K/R) <v> - (K²/R + b) <ω> - τ_c sign(ω) - τ_0, <.> the trapezoid mean. Intervals that
    touch standstill (|ω| <= w_eps) or a reversal are left out. The damping column mixes the back-EMF's lagged
    speed and the viscous torque's own speed by ``viscous_share`` = b/(K²/R + b) (one column when the lag is not
    resolved). With an angle, the columns of a gravity-like load at the output, -sin(θ/N)/N and -cos(θ/N)/N.
    Returns (start index, y, columns, the trapezoid mean over the intervals)."""
    m = c.m
    starts = []
    for k in np.unique(c.seg[c.seg >= 0]):
        idx = np.flatnonzero(c.seg == k)
        starts.extend(range(int(idx[0]), int(idx[-1]) - m + 1, m))
    starts = np.asarray(starts, int)
    if not len(starts):
        return starts, np.zeros(0), {}, None
    span = starts[:, None] + np.arange(m + 1)[None, :]
    good = c.ok[span].all(axis=1)
    ws = c.w[span]
    good &= (np.abs(ws) > w_eps).all(axis=1) & ((np.sign(ws) == np.sign(ws[:, :1])).all(axis=1))
    if c.tau_v > 0:   # the true speed keeps its sign too, and the lagged direction has settled after a reversal
        wt = c.w_true[span]
        good &= (np.sign(wt) == np.sign(wt[:, :1])).all(axis=1) & (np.abs(c.sgn[span]) > 0.95).all(axis=1)
    starts, span = starts[good], span[good]
    T = c.t[span[:, -1]] - c.t[span[:, 0]]

    def mean(x):
        xs, ts = x[span], c.t[span]
        return np.sum(0.5 * (xs[:, 1:] + xs[:, :-1]) * np.diff(ts, axis=1), axis=1) / T

    y = (c.w_raw[span[:, -1]] - c.w_raw[span[:, 0]]) / T
    w_mix = (1.0 - viscous_share) * mean(c.w_f) + viscous_share * mean(c.w_raw)
    sign = -np.sign(c.w[span[:, m // 2]]) if c.tau_v <= 0 else -mean(c.sgn)
    cols = {"k_over_r": mean(c.v), "damping": -w_mix, "coulomb": sign, "offset": -np.ones(len(starts))}
    if c.th is not None:
        cols["load_sin"] = -mean(c.th_sin) / gear
        cols["load_cos"] = -mean(c.th_cos) / gear
    return starts, y, cols, mean




def _bic(rss: float, n: int, k: int) -> float:
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


def _blocks(n: int, frac: float, nblocks: int = 10) -> np.ndarray:
    """Held-out mask: ``nblocks`` interleaved blocks making a fraction ``frac`` of the samples."""
    mask = np.zeros(n, bool)
    size = n / nblocks
    for b in range(nblocks):
        a = int(b * size)
        mask[a:a + int(round(frac * size))] = True
    return mask


# --------------------------------------------------------------------------------------------- replay

def simulate_speed(J: float, k_over_r: float, damping: float, coulomb: float, offset: float,
                   v: np.ndarray, dt: np.ndarray, w0: np.ndarray, substeps: int = SUBSTEPS, *,
                   theta0: np.ndarray | None = None, load=None, gear_mu: float = 0.0,
                   back_emf: float = 0.0) -> np.ndarray:
    """Motor-side speed of J dω/dt = (K/R) v - (K²/R + b) ω - τ_c sign(ω) - τ_0 under the voltage ``v``
    (windows x samples, linear between samples) from ``w0`` (per window), ``dt`` the sample intervals (windows x
    samples-1). Each sub-interval exactly (the voltage held at its midpoint); a speed crossing zero stops there
    and sticks while |(K/R) v - τ_0| <= τ_c. ``load(theta)``: a motor-side load torque of the motor angle
    (from ``theta0``), held over each sub-interval. ``gear_mu`` = μ: the friction level grows by μ |τ_m|, τ_m =
    (K/R)(v - K_e ω) the motor's torque (``back_emf`` = K_e [V*s/rad]); within a sub-interval τ_m keeps the sign
    it has at its start, so the term is affine in ω and solved exactly with the rest; at rest the breakaway level
    is τ_c + μ |(K/R) v| (:func:`bldc_actuator.kernel.friction`'s rule)."""
    v = np.atleast_2d(v)
    m, k = v.shape
    out = np.empty((m, k))
    w = np.asarray(w0, float).copy()
    th = None if load is None else np.asarray(theta0, float).copy()
    out[:, 0] = w
    lam = max(damping, 1e-300) / J
    for j in range(k - 1):
        h = dt[:, j] / substeps
        for s in range(substeps):
            f = (s + 0.5) / substeps
            drive = k_over_r * ((1 - f) * v[:, j] + f * v[:, j + 1]) - offset
            if th is not None:
                drive = drive - load(th)
            moving = w != 0.0
            sgn = np.where(moving, np.sign(w), np.sign(drive))
            if gear_mu:
                v_mid = (1 - f) * v[:, j] + f * v[:, j + 1]
                sig_m = np.sign(k_over_r * (v_mid - back_emf * w))
                sig_m = np.where(sig_m == 0.0, 1.0, sig_m)
                # friction sgn (c + mu sig_m kr (v - K_e w)): its speed part joins the damping
                stuck = ~moving & (np.abs(drive) <= coulomb + gear_mu * np.abs(k_over_r * v_mid))
                u = drive - sgn * (coulomb + gear_mu * sig_m * k_over_r * v_mid)
                dmp = np.maximum(damping - sgn * gear_mu * sig_m * k_over_r * back_emf, 1e-9 * max(damping, 1e-300))
                w_inf = u / dmp
                e = np.exp(-dmp / J * h)
            else:
                stuck = ~moving & (np.abs(drive) <= coulomb)
                u = drive - coulomb * sgn
                w_inf = u / max(damping, 1e-300)
                e = np.exp(-lam * h)
            w_new = w_inf + (w - w_inf) * e
            crossed = moving & (np.sign(w_new) != np.sign(w)) & (coulomb > 0)
            w_next = np.where(stuck | crossed, 0.0, w_new)
            if th is not None:
                th = th + 0.5 * (w + w_next) * h
            w = w_next
        out[:, j + 1] = w
    return out


def _windows(c: _Columns, test: np.ndarray, rows: np.ndarray, length: int) -> list[np.ndarray]:
    """Index ranges of replay windows inside held-out blocks of one segment."""
    idx = rows[test]
    out = []
    i = 0
    while i < len(idx):
        j = i
        while j + 1 < len(idx) and idx[j + 1] == idx[j] + 1 and c.seg[idx[j + 1]] == c.seg[idx[i]]:
            j += 1
        run = idx[i:j + 1]
        for a in range(0, len(run) - length + 1, length):
            out.append(run[a:a + length])
        i = j + 1
    return out


def _replay(c: _Columns, wins: list[np.ndarray], J: float, coef: dict, rest=None, gear: float = 1.0,
            back_emf: float = 0.0) -> np.ndarray:
    """Per-window RMS of the replayed speed against the logged one [rad/s]."""
    if not wins:
        return np.zeros(0)
    W = np.stack(wins)
    load = None
    if c.th is not None:
        def load(th):
            tho = th / gear
            out = coef.get("load_sin", 0.0) * np.sin(tho) + coef.get("load_cos", 0.0) * np.cos(tho)
            return (out + (rest(tho) if rest is not None else 0.0)) / gear
    # started from the speed with the velocity channel's lag taken out (the smoothed speed where it has none)
    sim = simulate_speed(J, coef["k_over_r"], coef["damping"], max(0.0, coef["coulomb"]), coef["offset"],
                         c.v_raw[W], np.diff(c.t[W], axis=1), c.w_true[W[:, 0]],
                         theta0=c.th[W[:, 0]] if c.th is not None else None, load=load,
                         gear_mu=max(0.0, coef.get("gear", 0.0)), back_emf=back_emf)
    if c.tau_v > 0:   # as the velocity channel sees it: the first-order lag, started at the logged speed
        sim = _lag_from(sim, c.w[W[:, 0]], np.diff(c.t[W], axis=1), c.tau_v)
    return np.sqrt(np.mean((sim - c.w_raw[W]) ** 2, axis=1))


def _lag_from(x: np.ndarray, y0: np.ndarray, dt: np.ndarray, tau: float) -> np.ndarray:
    """The first-order lag 1/(1 + τ s) of each row of ``x`` (linear between samples, intervals ``dt``), its output
    started at ``y0``."""
    y = np.empty_like(x)
    y[:, 0] = y0
    for j in range(1, x.shape[1]):
        a = np.exp(-dt[:, j - 1] / tau)
        b0, b1 = _lag_coefficients(a, tau / dt[:, j - 1])
        y[:, j] = a * y[:, j - 1] + b0 * x[:, j] + b1 * x[:, j - 1]
    return y


# --------------------------------------------------------------------------------------------- diagnosis

#: terms fitted as several columns
TERM_COLUMNS = {"load": ("load_sin", "load_cos")}
MIN_LOAD_SPAN = 0.5       #: [rad] output angle a gravity-like load needs to be told from a constant


def _gravity(a: float, b: float, cov: np.ndarray, idx: dict) -> tuple[float, float, float, float]:
    """τ_g sin(θ + φ) = a sin θ + b cos θ: (τ_g, sd, φ, sd) from (a, b) and their covariance."""
    g = math.hypot(a, b)
    ph = math.atan2(b, a)
    i, j = idx["load_sin"], idx["load_cos"]
    C = cov[np.ix_([i, j], [i, j])]
    if g == 0:
        return 0.0, float("nan"), 0.0, float("nan")
    jg = np.array([a / g, b / g])
    jp = np.array([-b / g ** 2, a / g ** 2])
    return g, float(math.sqrt(max(jg @ C @ jg, 0.0))), ph, float(math.sqrt(max(jp @ C @ jp, 0.0)))


COULOMB_FIELD = "effects.coulomb_friction"   #: the parameter-file field of the Coulomb friction (its name there)
GEAR_FIELD = "effects.gear_load_friction"     #: the field of the gear friction growing with the transmitted torque

#: the combinations: key -> (parameter name, unit, what it is)
COMBINATIONS = {
    "k_over_r": ("torque_constant_over_resistance", "N*m/V", "K_t/R: torque per volt at standstill"),
    "damping": ("back_emf_plus_viscous", "N*m*s/rad", "K_t*K_e/R + b: the speed's damping (back-EMF and viscous)"),
    "coulomb": (COULOMB_FIELD.rsplit(".", 1)[-1], "N*m", "tau_c: Coulomb friction at the motor side"),
    "gear": (GEAR_FIELD.rsplit(".", 1)[-1], "", "mu: gear friction per N*m the motor transmits, "
             "(tau_c + mu |K_t i|) sign(omega)"),
}


def _join(sig: Signals, other: Signals) -> tuple[Signals, int]:
    """``sig`` with a second recording appended as segments of their own (its time shifted past sig's end by a
    second: no interval or window spans the two), and the number of sig's samples."""
    n1, n2 = len(sig.time), len(other.time)
    t2 = other.time - (other.time[0] if n2 else 0.0) + (sig.time[-1] + 1.0 if n1 else 0.0)
    names = set(sig.channels) | set(other.channels)
    nan = lambda k: np.full(k, np.nan)  # noqa: E731
    ch = {k: np.concatenate([sig.channels.get(k, nan(n1)), other.channels.get(k, nan(n2))]) for k in names}
    segs = list(sig.segments or [(0, n1)]) + [(a + n1, b + n1) for a, b in (other.segments or [(0, n2)])]
    return Signals(np.concatenate([sig.time, t2]), ch, source=sig.source, segments=segs, meta=dict(sig.meta)), n1


def diagnose(sig: Signals, params, *, holdout: float = 0.3, tolerance: float = 0.05,
             max_relative_uncertainty: float = 0.5, holdout_signals: Signals | None = None) -> VoltageModeResult:
    """The route on ``sig``; the held-out data are interleaved blocks of it (a fraction ``holdout``) or, given,
    the separate recording ``holdout_signals`` (every sample of ``sig`` then fits, every one of it judges)."""
    m, e = params.motor, params.effects
    K, R, J = float(m.torque_constant_q), float(m.phase_resistance), float(m.rotor_inertia)
    tau_e = float(m.q_inductance) / R
    nominal = {"k_over_r": K / R, "damping": K * K / R + float(m.viscous_damping),
               "coulomb": float(e.coulomb_friction), "offset": 0.0, "gear": float(e.gear_load_friction)}
    N = float(sig.meta.get("gear_ratio") or params.gear.gear_ratio)
    ld = params.load
    nominal["load_sin"] = float(ld.gravity_torque) * math.cos(float(ld.gravity_phase))
    nominal["load_cos"] = float(ld.gravity_torque) * math.sin(float(ld.gravity_phase))

    def rest(tho):          # the nominal load's other parts at the output (constant, spring) [N*m]
        return float(ld.load_torque) + float(ld.spring_stiffness) * (tho - float(ld.spring_zero))

    n_train = None
    if holdout_signals is not None and len(holdout_signals.time):
        sig, n_train = _join(sig, holdout_signals)
    c, lagged, how = _columns(sig, tau_e, N)
    notes = [f"no current sensor: the mechanical equation closed by the voltage, i = (v - K ω)/R"
             + (f" lagged by L/R = {1e3 * tau_e:.3g} ms (resolved by the sampling)" if lagged else
                f" (L/R = {1e3 * tau_e:.3g} ms is below {TAU_E_RESOLVED:g} sample: not resolved, static form)")
             + f"; {how}; J = {J:.4g} kg*m^2 taken as nominal (the equation fixes the ratios to J)"]
    wmax = float(np.nanpercentile(np.abs(c.w[c.ok]), 95)) if c.ok.any() else 0.0
    w_eps = max(1e-3, 0.02 * wmax)
    rows = np.flatnonzero(c.ok)
    share = float(m.viscous_damping) / nominal["damping"]
    starts, dw, cols, mean = _intervals(c, w_eps, share, N)
    for _ in range(3 if lagged and len(starts) >= 50 else 0):     # b's share of the damping, fixed point
        X = np.column_stack([cols[k] for k in cols])
        a1, a2 = np.linalg.lstsq(X, J * dw, rcond=None)[0][:2]
        share = float(np.clip((a2 - K * a1) / a2, 0.0, 1.0)) if a2 > 0 else 0.0
        starts, dw, cols, mean = _intervals(c, w_eps, share, N)
    n = len(starts)
    empty = VoltageModeResult([], [], {}, notes, {}, {}, lagged)
    if n < 50:
        notes.append(f"only {n} usable moving intervals: nothing decided")
        return empty
    sgn = -cols["coulomb"]
    both_ways = min(np.mean(sgn > 0), np.mean(sgn < 0)) > 0.05
    # the gear friction's column, -sign(ω) |τ_m|, τ_m = (K/R)(v - K ω) the motor's torque from the voltage, at the
    # K/R the data give (a fixed point: the free fit of every combination, twice)
    v_emf = cols["k_over_r"] + K * cols["damping"]         # <v> - K <ω>: the winding's voltage drop R i
    kr_hat = nominal["k_over_r"]
    for _ in range(3):
        cols["gear"] = cols["coulomb"] * np.abs(kr_hat * v_emf)
        X = np.column_stack([cols[k] for k in cols])
        y0 = J * dw - sum(nominal[k] * cols[k] for k in cols if k != "offset")
        if c.th is not None:
            y0 = y0 + mean(rest(c.th / N)) / N
        co = np.linalg.lstsq(X, y0, rcond=None)[0]
        kr_new = nominal["k_over_r"] + float(co[list(cols).index("k_over_r")])
        if not (kr_new > 0 and math.isfinite(kr_new)) or abs(kr_new - kr_hat) <= 1e-6 * abs(kr_hat):
            break
        kr_hat = kr_new
    braking = float(np.mean(np.sign(v_emf) * sgn < 0))
    notes.append(f"{n} intervals of {c.m} sample(s) fitted (the equation integrated over each: no differentiated "
                 f"speed); intervals touching standstill (|ω| <= {w_eps:.3g} rad/s) or a reversal left out")
    base = J * dw - sum(nominal[k] * cols[k] for k in cols if k != "offset")
    if c.th is not None:
        base = base + mean(rest(c.th / N)) / N
    test = _blocks(n, holdout) if n_train is None else starts >= n_train
    every = np.ones(n, bool) if n_train is None else ~test     # what the BIC and the final fit see
    n_fit = int(every.sum())
    train = ~test

    def keys(free):
        return [kk for k in free for kk in TERM_COLUMNS.get(k, (k,))]

    def fit(free, sel):
        X = np.column_stack([cols[k][sel] for k in keys(free)])
        return ols(X, base[sel])

    def heldout(free):
        coef, _, _ = fit(free, train)
        pred = np.column_stack([cols[k][test] for k in keys(free)]) @ coef
        return float(np.sqrt(np.mean((base[test] - pred) ** 2)))

    def rss(free):
        return float(np.sum(fit(free, every)[2] ** 2))

    # forward selection of the freed combinations (the constant torque is always free: a nuisance)
    free = ["offset"]
    terms = ["k_over_r", "damping"] + (["coulomb"] if both_ways else [])
    if both_ways and braking >= gear_friction.MIN_BRAKING:
        terms.append("gear")
    else:
        notes.append("a gear friction growing with the torque is not tested: " + (
            "motion in one direction only" if not both_ways else
            f"the motor brakes in {100 * braking:.1f} % of the intervals (< {100 * gear_friction.MIN_BRAKING:g} %): "
            f"while motoring it is the K_t/R column (experiment: decelerate it, lower a load)"))
    span_out = float(np.ptp(c.th[rows])) / N if c.th is not None and len(rows) else 0.0
    if span_out >= MIN_LOAD_SPAN and params.gear.output_motion != "linear":
        terms.append("load")
    else:
        notes.append(f"a load of the output angle (gravity) is not tested: " + (
            "gear.output_motion is linear (a slide's weight is the constant torque)"
            if params.gear.output_motion == "linear" else
            "no angle channel" if c.th is None else f"the output angle spans {span_out:.3g} rad < {MIN_LOAD_SPAN:g}"))
    if not both_ways:
        notes.append("motion in one direction only: Coulomb friction and the constant torque are one column "
                     "(experiment: drive it both ways)")
    steps: dict[str, tuple[float, float, float]] = {}
    rejected_steps: dict[str, tuple[float, float, float]] = {}
    left = list(terms)
    while left:
        r0 = rss(free)
        trials = {k: _bic(r0, n_fit, len(keys(free))) - _bic(rss(free + [k]), n_fit, len(keys(free + [k])))
                  for k in left}
        k = max(trials, key=trials.get)
        before, after = heldout(free), heldout(free + [k])
        if trials[k] > BIC_GATE and after < before:
            free.append(k)
            steps[k] = (trials[k], before, after)
            left.remove(k)
        else:
            for k2 in left:
                rejected_steps[k2] = (trials[k2], heldout(free), heldout(free + [k2]))
            break

    # the identified combinations: every coefficient free (what the data say, with their uncertainties)
    all_free = ["offset"] + terms
    coef_all, cov_all, _ = fit(all_free, every)
    ia = {k: i for i, k in enumerate(keys(all_free))}

    def val(k):
        return nominal.get(k, 0.0) + float(coef_all[ia[k]])

    def sd(k, cov=cov_all, idx=ia):
        v = cov[idx[k], idx[k]]
        return float(math.sqrt(v)) if math.isfinite(v) and v >= 0 else float("nan")

    combos = {}
    for k in terms:
        if k not in COMBINATIONS:
            continue
        name, unit, what = COMBINATIONS[k]
        combos[name] = {"value": val(k), "sd": sd(k), "unit": unit, "nominal": nominal[k], "what": what,
                        "identifiable": "identified (given J nominal)"}
    kr, dmp = val("k_over_r"), val("damping")
    skr, sdm = sd("k_over_r"), sd("damping")
    cv = float(cov_all[ia["k_over_r"], ia["damping"]])
    # J-free ratios: (K²/R + b)/(K/R) and τ_c/(K/R), first-order propagation
    ke = dmp / kr
    ke_sd = abs(ke) * math.sqrt(max((sdm / dmp) ** 2 + (skr / kr) ** 2 - 2 * cv / (dmp * kr), 0.0))
    combos["effective_back_emf_constant"] = {
        "value": ke, "sd": ke_sd, "unit": "V*s/rad", "nominal": nominal["damping"] / nominal["k_over_r"],
        "what": "(K_t*K_e/R + b)/(K_t/R) = K_e + b*R/K_t", "identifiable": "identified (independent of J)"}
    b = dmp - K * kr
    b_sd = math.sqrt(max(sdm ** 2 + K * K * skr ** 2 - 2 * K * cv, 0.0))
    combos["viscous_damping"] = {"value": b, "sd": b_sd, "unit": "N*m*s/rad", "nominal": float(m.viscous_damping),
                                 "what": "b = (K_t*K_e/R + b) - K_t*(K_t/R)",
                                 "identifiable": "only given K_t nominal (a combination with K_t*K_e/R)"}
    if "coulomb" in ia:
        tc, stc = val("coulomb"), sd("coulomb")
        cvc = float(cov_all[ia["k_over_r"], ia["coulomb"]])
        bv = tc / kr
        combos["break_away_voltage"] = {
            "value": bv, "sd": abs(bv) * math.sqrt(max((stc / tc) ** 2 + (skr / kr) ** 2 - 2 * cvc / (tc * kr), 0.0))
            if tc else float("nan"), "unit": "V", "nominal": nominal["coulomb"] / nominal["k_over_r"],
            "what": "tau_c/(K_t/R): the voltage that starts the motor", "identifiable": "identified (independent of J)"}
    combos["torque_constant_and_resistance_apart"] = {
        "value": None, "sd": None, "unit": "", "nominal": None, "what": "K_t and R separately",
        "identifiable": "not identifiable without current (only K_t/R, and K_e + b R/K_t)"}

    if "load" in terms:
        g, gsd, ph, phsd = _gravity(val("load_sin"), val("load_cos"), cov_all, ia)
        combos["gravity_torque"] = {"value": g, "sd": gsd, "unit": "N*m", "nominal": float(ld.gravity_torque),
                                    "what": "tau_g: a gravity-like load at the output, tau_g sin(theta_out + phi)",
                                    "identifiable": "identified (given J nominal)"}
        combos["gravity_phase"] = {"value": ph, "sd": phsd, "unit": "rad", "nominal": float(ld.gravity_phase),
                                   "what": "phi_g", "identifiable": "identified (independent of J)"}

    # the final model and its uncertainties
    coef, cov, _ = fit(free, every)
    idx = {k: i for i, k in enumerate(keys(free))}
    final = dict(nominal)
    for k in keys(free):
        final[k] = nominal.get(k, 0.0) + float(coef[idx[k]])

    # judge: the held-out windows replayed under the recorded voltage, leave one out
    dt_med = float(np.median(np.diff(sig.time))) if len(sig.time) > 1 else 1.0
    length = max(8, int(round(WINDOW_S / dt_med)))
    test_all = _blocks(len(rows), holdout) if n_train is None else rows >= n_train
    wins = _windows(c, test_all, rows, length)
    base_coef = dict(nominal, offset=final["offset"])
    err_final = _replay(c, wins, J, final, rest, N, K)
    err_nom = _replay(c, wins, J, base_coef, rest, N, K)
    sim = {"channel": "the route's own mechanical ODE under the recorded voltage (frame.simulate has no "
                      "voltage-commanded DC drive)", "windows": len(wins), "window_s": length * dt_med,
           "metric": "speed error RMS", "unit": "rad/s",
           "nominal": float(np.sqrt(np.mean(err_nom ** 2))) if len(wins) else None,
           "updated": float(np.sqrt(np.mean(err_final ** 2))) if len(wins) else None}

    fields = {"k_over_r": "motor.phase_resistance", "damping": "motor.viscous_damping",
              "coulomb": COULOMB_FIELD, "load": "load.gravity_torque", "gear": GEAR_FIELD}
    findings, rejected = [], []
    for k in terms:
        effect = effect_for(fields[k])
        name, unit, what = COMBINATIONS.get(k, ("gravity_torque", "N*m", ""))
        if k not in free:
            dbic, before, after = rejected_steps.get(k, (float("nan"),) * 3)
            rejected.append(Term(effect, {}, {}, {}, {"metric": "torque_rms", "unit": "N*m", "before": before,
                                                       "after": after}, float(dbic), False,
                                 f"not supported (dBIC {dbic:.1f} <= {BIC_GATE:g} or held-out not better)"))
            continue
        dbic, before, after = steps[k]
        if k == "load":
            value, s, ph, phsd = _gravity(final["load_sin"], final["load_cos"], cov, idx)
            par, unc, un = ({"gravity_torque": value, "gravity_phase": ph}, {"gravity_torque": s, "gravity_phase": phsd},
                            {"gravity_torque": "N*m", "gravity_phase": "rad"})
        else:
            value, s = final[k], sd(k, cov, idx)
            par, unc, un = {name: value}, {name: s}, {name: unit}
        if k == "damping":
            bb = value - K * final["k_over_r"]
            par["viscous_damping_given_nominal_K"], unc["viscous_damping_given_nominal_K"] = bb, s
            un["viscous_damping_given_nominal_K"] = "N*m*s/rad"
        if k == "k_over_r":
            par["phase_resistance_given_nominal_K"] = K / value
            unc["phase_resistance_given_nominal_K"] = K * s / value ** 2
            un["phase_resistance_given_nominal_K"] = "ohm"
        ho = {"metric": "torque_rms", "unit": "N*m", "before": before, "after": after}
        without = dict(final, **{kk: nominal[kk] for kk in TERM_COLUMNS.get(k, (k,))})
        err_wo = _replay(c, wins, J, without, rest, N, K)
        d = err_wo ** 2 - err_final ** 2
        se = float(np.std(d, ddof=1) / math.sqrt(len(d))) if len(d) >= 3 else float("nan")
        simrec = {"metric": "speed error RMS", "unit": "rad/s", "windows": len(d),
                  "without": float(np.sqrt(np.mean(err_wo ** 2))) if len(d) else None,
                  "with": sim["updated"], "paired_gain": float(np.mean(d)) if len(d) else None, "paired_se": se}
        # practical significance on the parameter written: b for the damping (given K_t nominal)
        moved, ref = ((par["viscous_damping_given_nominal_K"], float(m.viscous_damping)) if k == "damping"
                      else (value, float(ld.gravity_torque)) if k == "load" else (value, nominal[k]))
        rel = abs(moved - ref) / abs(ref) if ref else math.inf
        what = "it"
        if k == "gear":
            # an additive friction term: its practical size is its share of the friction it joins, mu |tau_m|
            # against tau_c + mu |tau_m| over the fitted intervals (the nominal mu's share for a change of mu)
            tm = float(np.mean(np.abs(final["k_over_r"] * v_emf[every])))
            total = max(final["coulomb"], 0.0) + max(value, 0.0) * tm
            rel = abs(value - nominal["gear"]) * tm / total if total > 0 else math.inf
            what = "the friction"
        reason = ""
        if not (len(d) >= 3 and np.mean(d) > 2 * se):
            reason = (f"not confirmed by the held-out replay ({len(d)} windows: speed error RMS without it "
                      f"{simrec['without']:.4g}, with it {simrec['with']:.4g} rad/s)" if len(d) else
                      "no held-out window to replay")
        elif rel <= tolerance:
            reason = f"consistent with nominal (changes {what} by {100 * rel:.1f} % <= {100 * tolerance:g} %)"
        elif not (abs(s) <= max_relative_uncertainty * abs(value)):
            reason = f"suspected, not identifiable (sd {s:.3g} > {max_relative_uncertainty:g} x |{value:.3g}|)"
        term = Term(effect, par, unc, un, ho, float(dbic), not reason, reason, simrec)
        (rejected if reason else findings).append(term)
    if combos["viscous_damping"]["value"] < -3 * combos["viscous_damping"]["sd"]:
        notes.append("the damping fitted is below K_t^2/R of the nominal K_t: K_t or R nominal is off (without "
                     "current they are not separated)")
    return VoltageModeResult(findings, rejected, combos, notes,
                             {"metric": "torque_rms", "unit": "N*m", "nominal": heldout(["offset"]),
                              "after": heldout(free)}, sim, lagged, n,
                             {k: final[k] for k in ("k_over_r", "damping", "coulomb", "gear", "offset", "load_sin",
                                                       "load_cos")})


def updated_params(params, result: VoltageModeResult):
    """The parameters with the accepted combinations written in: Coulomb friction; the gear friction; the
    viscous damping given K_t nominal; R given K_t nominal."""
    upd = {}
    for f in result.findings:
        p = f.parameters
        name = COULOMB_FIELD.rsplit(".", 1)[-1]
        if name in p:
            upd[COULOMB_FIELD] = max(0.0, p[name])
        if "viscous_damping_given_nominal_K" in p:
            upd["motor.viscous_damping"] = max(0.0, p["viscous_damping_given_nominal_K"])
        if "phase_resistance_given_nominal_K" in p and p["phase_resistance_given_nominal_K"] > 0:
            upd["motor.phase_resistance"] = p["phase_resistance_given_nominal_K"]
        gear = GEAR_FIELD.rsplit(".", 1)[-1]
        if gear in p:
            upd[GEAR_FIELD] = max(0.0, p[gear])
        if "gravity_torque" in p:
            upd["load.gravity_torque"] = p["gravity_torque"]
            upd["load.gravity_phase"] = p["gravity_phase"]
    return params.replace(**upd) if upd else params


def report(signals, params, res: VoltageModeResult, options, say, t_start: float):
    """The route's :class:`~.report.document.DiagnosisReport` (the schema of the other routes)."""
    import time

    from .report.document import DiagnosisReport
    from .results import Undecidable, decide

    findings = []
    for x in res.findings:
        ev = [f"voltage mode: ΔBIC {x.delta_bic:.1f}; held-out torque RMS {x.held_out['before']:.4g} -> "
              f"{x.held_out['after']:.4g} N*m",
              f"held-out replay under the recorded voltage ({x.simulation['windows']} windows): speed error RMS "
              f"{x.simulation['without']:.4g} -> {x.simulation['with']:.4g} rad/s"]
        findings.append({"effect": x.effect, "description": f"{x.effect.replace('_', ' ')} (voltage mode)",
                         "form": "voltage mode", "parameters": x.parameters, "uncertainty": x.uncertainty,
                         "units": x.units, "fields": {}, "simulated": True, "evidence": ev,
                         "held_out": dict(x.held_out, metric="torque error RMS"),
                         "metrics": [dict(x.held_out, metric="torque error RMS"),
                                     {"metric": "speed error RMS (replay)", "unit": "rad/s",
                                      "before": x.simulation["without"], "after": x.simulation["with"]}],
                         "delta_bic": x.delta_bic, "correlations": []})
    rejected = [{"effect": x.effect, "form": "voltage mode", "reason": x.reason, "delta_bic": x.delta_bic,
                 "heldout_gain": (x.held_out.get("before") or 0) - (x.held_out.get("after") or 0)}
                for x in res.rejected]
    reasons = [] if res.held_out else [Undecidable("too_few_samples", "; ".join(res.notes[-1:]), "record longer")]
    rec = decide([f["effect"] for f in findings], reasons)
    notes = [f"data: {n}" for n in ((getattr(signals, "meta", None) or {}).get("notes") or [])] + list(res.notes)
    for name, cmb in res.combinations.items():
        if cmb.get("value") is None:
            notes.append(f"{cmb['what']}: {cmb['identifiable']}")
        else:
            notes.append(f"{cmb['what']} = {cmb['value']:.4g} ± {cmb['sd']:.2g} {cmb['unit']} (nominal "
                         f"{cmb['nominal']:.4g}): {cmb['identifiable']}")
    timing = {"total": time.perf_counter() - t_start}
    say(f"6/6 show: {rec.text()} (total {timing['total']:.2f} s)")
    compare = {"equation_error": {"voltage_mode": {
                   "nominal": {"holdout_rms": res.held_out.get("nominal"), "train_rms": None, "unit": "N*m"},
                   "updated": {"holdout_rms": res.held_out.get("after"), "train_rms": None, "unit": "N*m"}}},
               "replay": res.simulation or None, "thermal": None, "output_error_refit": None,
               "alias_simulation": None, "voltage_mode": {"combinations": res.combinations}}
    issues = [i.to_dict() if hasattr(i, "to_dict") else dict(i) for i in getattr(signals, "issues", [])]
    return DiagnosisReport(
        channels=sorted(c for c, v in signals.channels.items() if np.isfinite(v).any()), findings=findings,
        rejected=rejected, windows=[], data_issues=issues, not_checkable=[], aliases=[],
        verdict_record=rec, notes=notes, compare=compare,
        updated_params=updated_params(params, res), nominal_params=params, timing=timing,
        method="voltage mode (no current sensor)",
        setup={"rate_hz": (getattr(signals, "meta", {}) or {}).get("rate_hz"), "samples": int(len(signals.time)),
               "holdout": ("separate recording" if getattr(options, "holdout_signals", None) is not None else
                           f"{options.holdout:g} of the samples (interleaved blocks)"),
               "effects_tested": [effect_for(f) for f in ("motor.phase_resistance", "motor.viscous_damping",
                                                           COULOMB_FIELD, GEAR_FIELD, "load.gravity_torque")],
               "source": getattr(signals, "source", "")})
