"""Diagnosis of a log with shaft torque and angle/speed but no motor current: cogging and friction from the
torque balance.

A dynamometer cogging run, a motor unpowered (or position-held by its drive with the current not logged)
and turned by something else: the torque sensor then reads what the motor itself resists. With the
motor-side speed ω, angle θ and acceleration α = dω/dt, and the gear ratio N (torque at the output)::

    τ_sensor = -N [ τ_c sign(ω) + b ω + J α + τ_cog(θ) ] + τ_0

(τ_c Coulomb friction, b viscous damping, J rotor inertia, τ_cog the cogging torque
:func:`bldc_actuator.effects.cogging_torque` with N_c periods per revolution, τ_0 a sensor offset). The
sign is the canonical one (positive = the actuator drives in +): a motor that only resists gives a
sensor torque opposite to its motion. When no encoder column exists the angle is integrated from the
speed per segment (said so in the result: its phase is relative and it drifts with the speed sensor's
offset). A term is accepted when it lowers the BIC by more than 10 and improves the held-out torque
(interleaved blocks). The cogging order is the peak of the angle-order spectrum of the friction-only
residual; its harmonics k = 1.. are added while each is accepted.

What this cannot do, and says: without current it cannot separate the motor's own electromagnetic torque
— when the balance explains little of the torque (R² < 0.5) the motor was probably powered and the
findings are marked not identifiable; with motion in one direction only, Coulomb friction and a sensor
offset are one column (reported as a drag, with the experiment that separates them).

What it can decide all the same (issue #24): a ripple locked to the angle in the MEASURED torque
(:func:`angle_locked_ripple`: the order standing out of its neighbouring orders, its amplitude and their
uncertainties, the same in both directions or halves), reported as the finding ``angle_locked_ripple`` unless
the balance attributes it as the motor's cogging; :func:`ripple_contrast` compares two or more recordings (a
compensation off and on) at one order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..effects import cogging_torque
from .effects import Route, WriteBack, registry
from .frame.least_squares import ols
from .signals import Signals, fill_gaps

#: the finding of an angle-locked ripple in the measured torque (this route's own effect)
RIPPLE_EFFECT = registry.one(lambda e: e.route is Route.TORQUE_BALANCE).name
#: the cogging finding (an angle series written onto the nominal one), which the ripple does not repeat
COGGING_EFFECT = registry.one(lambda e: e.writeback is WriteBack.COGGING_SERIES).name

BIC_GATE = 10.0


def applicable(sig: Signals) -> bool:
    """Torque and motion are logged, current is not (nor a current command)."""
    ch = sig.channels

    def has(n):
        return n in ch and np.isfinite(ch[n]).sum() >= 20

    return has("torque") and (has("velocity") or has("position")) and not has("current")


@dataclass
class Term:
    effect: str
    parameters: dict
    uncertainty: dict
    units: dict
    held_out: dict
    delta_bic: float
    accepted: bool
    reason: str = ""
    simulation: dict | None = None    #: a route's held-out replay of the term, where it has one (voltage mode)


@dataclass
class TorqueBalanceResult:
    findings: list[Term]
    rejected: list[Term]
    notes: list[str]
    angle_source: str
    r2: float
    held_out: dict
    not_checkable: list[dict] = field(default_factory=list)
    spectrum: dict | None = None      #: the angle-order peak: order ± sd, amplitude, x median, revolutions
    ripple: dict | None = None        #: the angle-locked ripple in the measured torque (:func:`angle_locked_ripple`)
    #: (angle, friction-only residual, the ripple's neighbour power) the ripple was measured on (for contrasts)
    ripple_input: tuple | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        def t(x: Term) -> dict:
            return {"effect": x.effect, "parameters": x.parameters, "uncertainty": x.uncertainty, "units": x.units,
                    "held_out": x.held_out, "delta_bic": x.delta_bic, "reason": x.reason, "simulated": True}

        return {"method": "torque balance (no motor current)", "angle_source": self.angle_source,
                "r2": self.r2, "held_out": self.held_out, "findings": [t(x) for x in self.findings],
                "rejected": [t(x) for x in self.rejected], "not_checkable": self.not_checkable,
                "order_spectrum": self.spectrum, RIPPLE_EFFECT: self.ripple, "notes": self.notes}


# ----------------------------------------------------------------------------------------- signals

def _per_segment(sig: Signals, f) -> np.ndarray:
    out = np.full(len(sig.time), np.nan)
    for a, b in sig.segments:
        if b - a >= 5:
            out[a:b] = f(sig.time[a:b], a, b)
    return out


def motion(sig: Signals) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """(θ, ω, α, how the angle was obtained) on the motor side."""
    from scipy.signal import savgol_filter

    ch = sig.channels
    w = ch.get("velocity")
    th = ch.get("position")
    how = "position channel (encoder)"
    if w is None or not np.isfinite(w).any():
        w = _per_segment(sig, lambda t, a, b: np.gradient(fill_gaps(th[a:b]), t))
        how += "; speed differentiated from it"
    if th is None or not np.isfinite(th).any():
        def integ(t, a, b):
            v = fill_gaps(w[a:b])
            return np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
        th = _per_segment(sig, integ)
        how = ("integrated from the speed (no encoder column): phase relative to the start of each segment, "
               "drifts with the speed sensor's offset")

    def acc(t, a, b):
        v = fill_gaps(w[a:b])
        n = b - a
        win = min(n - (1 - n % 2), max(5, int(round(0.02 / max(np.median(np.diff(t)), 1e-9))) | 1))
        if win < 5:
            return np.gradient(v, t)
        return savgol_filter(v, win, 2, deriv=1, delta=float(np.median(np.diff(t))))
    return th, w, _per_segment(sig, acc), how


def _blocks(n: int, frac: float, nblocks: int = 10) -> np.ndarray:
    """Held-out mask: interleaved blocks, a fraction ``frac`` of the samples."""
    edges = np.linspace(0, n, 2 * nblocks + 1).astype(int)
    mask = np.zeros(n, bool)
    period = 1.0 / frac
    k = 0
    for i in range(len(edges) - 1):
        if (i + 0.5) % period < 1.0:
            mask[edges[i]:edges[i + 1]] = True
            k += 1
    return mask


def _bic(rss: float, n: int, k: int) -> float:
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


PEAK_OVER_MEDIAN = 5.0
MIN_PERIODS = 3.0        #: an angle order must complete this many periods over the angle covered


def _consistent(th, r, order, om, both_ways) -> tuple[bool, str]:
    """The harmonic fitted separately on two halves (the two directions, else the first and second half of
    the angle travelled) agrees in amplitude (within 3 sigma + 30 %) and phase (within 60 deg): cogging is
    locked to the angle, a disturbance locked to time is not."""
    if both_ways:
        halves = [om > 0, om < 0]
        label = "directions"
    else:
        travel = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(th)))])
        halves = [travel < travel[-1] / 2, travel >= travel[-1] / 2]
        label = "halves of the travel"
    fits = []
    for m in halves:
        if m.sum() < 20:
            return False, f"too few samples in one of the {label}"
        X = np.column_stack([np.cos(order * th[m]), np.sin(order * th[m])])
        coef, cov, _ = ols(X, r[m])
        fits.append((complex(coef[0], coef[1]), float(np.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)))))
    (z1, s1), (z2, s2) = fits
    a1, a2 = abs(z1), abs(z2)
    amp_ok = abs(a1 - a2) <= 3 * math.hypot(s1, s2) + 0.3 * max(a1, a2)
    dphi = abs(math.degrees(np.angle(z1 / z2))) if a1 > 0 and a2 > 0 else 180.0
    ok = amp_ok and dphi <= 60.0        # an angle integrated from speed drifts: a looser phase test
    return ok, f"{label}: amplitudes {a1:.3g} and {a2:.3g} N*m, phases {dphi:.0f} deg apart"


def order_spectrum(theta: np.ndarray, r: np.ndarray, max_order: int) -> np.ndarray:
    """Amplitude of the least-squares harmonic fit of ``r`` at each order 1..max_order of ``theta``."""
    amps = np.zeros(max_order + 1)
    for k in range(1, max_order + 1):
        c, s = np.cos(k * theta), np.sin(k * theta)
        X = np.column_stack([c, s])
        coef = np.linalg.lstsq(X, r, rcond=None)[0]
        amps[k] = float(np.hypot(*coef))
    return amps


def order_scan(theta: np.ndarray, r: np.ndarray, kmin: float, kmax: int, revs: float):
    """(orders, amplitudes) of the least-squares harmonic fit of ``r`` at orders kmin..kmax of ``theta``: integer
    orders when the span resolves them (>= 4 revolutions), else a grid of 1/(4 R) (R revolutions covered)."""
    if revs >= 4.0:
        ks = np.arange(max(1, int(math.ceil(kmin))), kmax + 1, dtype=float)
    else:
        step = 0.25 / max(revs, 1e-9)
        ks = np.arange(kmin, kmax + step / 2, step)
        if len(ks) > 2000:
            ks = np.linspace(kmin, kmax, 2000)
    amps = np.zeros(len(ks))
    for i, k in enumerate(ks):
        X = np.column_stack([np.cos(k * theta), np.sin(k * theta)])
        coef = np.linalg.lstsq(X, r, rcond=None)[0]
        amps[i] = float(np.hypot(*coef))
    return ks, amps


def _half_width(ks: np.ndarray, amps: np.ndarray, i: int) -> float:
    """Half width of the peak at ``ks[i]`` where the amplitude falls to 1/sqrt(2) of it (interpolated); at least
    half the grid step."""
    level = amps[i] / math.sqrt(2)

    def edge(direction):
        j = i
        while 0 <= j + direction < len(ks) and amps[j + direction] > level:
            j += direction
        if not 0 <= j + direction < len(ks):
            return abs(ks[j] - ks[i])
        a0, a1 = amps[j], amps[j + direction]
        x = ks[j] + (ks[j + direction] - ks[j]) * (a0 - level) / max(a0 - a1, 1e-300)
        return abs(x - ks[i])

    step = float(ks[1] - ks[0]) if len(ks) > 1 else 1.0
    return max(0.5 * (edge(-1) + edge(1)), 0.5 * step)


# ----------------------------------------------------------------------------------------- angle-locked ripple

#: a ripple is reported when its order's power stands out of the neighbouring orders' at this false-alarm
#: probability over all the orders searched (Bonferroni), and it is the same in both halves of the data
RIPPLE_FALSE_ALARM = 1e-3
#: the neighbouring orders a peak is compared with: within this many orders of it (at least 6 each side), the
#: peak's own lobe (+-1.5 / revolutions covered, at least +-1 order) left out
RIPPLE_NEIGHBOURS = 0.3


def fit_order(theta: np.ndarray, r: np.ndarray, order: float) -> tuple[complex, float]:
    """Least-squares ``a cos(k theta) + b sin(k theta)`` of ``r`` at ``order`` k: (a + i b, white-noise SD of a
    and b from the fit's residual)."""
    X = np.column_stack([np.cos(order * theta), np.sin(order * theta)])
    coef, cov, _ = ols(X, r)
    return complex(coef[0], coef[1]), float(math.sqrt(max(0.5 * (cov[0, 0] + cov[1, 1]), 0.0)))


def _neighbour_floor(ks: np.ndarray, amps: np.ndarray, i: int, lobe: float) -> tuple[float, int]:
    """(mean squared amplitude, count) of the orders near ``ks[i]`` outside its lobe: the local noise level
    there (the measured torque's unexplained part is rarely white: a powered motor's own torque wanders)."""
    k = ks[i]
    reach = max(6.0, RIPPLE_NEIGHBOURS * k)
    d = np.abs(ks - k)
    sel = (d > max(lobe, 1.0)) & (d <= reach + lobe)
    if sel.sum() < 4:
        return float("nan"), 0
    return float(np.mean(np.square(amps[sel]))), int(sel.sum())


def angle_locked_ripple(theta: np.ndarray, r: np.ndarray, omega: np.ndarray, revs: float, kmin: float,
                        kmax: int, both_ways: bool) -> dict | None:
    """The angle-locked ripple of ``r`` (the measured torque less what the balance explains, N*m at the output)
    against the motor angle ``theta``: the order whose amplitude stands out most of its neighbouring orders
    (power ratio F; p-value from F(2, 2m) with m neighbours, times the number of orders searched), its order
    refined on a fine grid with the Cramer-Rao SD from the neighbours' noise level, its amplitude (least squares
    at that order) with the SD max(neighbours' level, white-noise fit), and whether it is the same in both halves
    of the data (angle-locked, not time-locked). None when no order can be searched."""
    from scipy.stats import f as f_dist

    if kmax <= kmin or len(r) < 50:
        return None
    ks, amps = order_scan(theta, r, kmin, kmax, revs)
    lobe = 1.5 / max(revs, 1e-9)
    ratios = np.full(len(ks), np.nan)
    counts = np.zeros(len(ks), int)
    for i in range(len(ks)):
        fl, m = _neighbour_floor(ks, amps, i, lobe)
        if m and fl > 0:
            ratios[i], counts[i] = amps[i] ** 2 / fl, m
    if not np.isfinite(ratios).any():
        return None
    i = int(np.nanargmax(ratios))
    k0 = float(ks[i])
    floor, m = _neighbour_floor(ks, amps, i, lobe)
    F = float(ratios[i])
    # on a grid finer than the resolution (< 4 revolutions: steps of 1/(4 R)) neighbouring amplitudes are not
    # independent: the degrees of freedom and the number of orders searched count independent orders only
    step = float(ks[1] - ks[0]) if len(ks) > 1 else 1.0
    per_order = min(1.0, step * revs)
    m_eff = max(2, int(round(m * per_order)))
    n_search = max(1, int(round(len(ks) * per_order)))
    p = float(min(1.0, f_dist.sf(F, 2, 2 * m_eff) * n_search))
    # refine the order within the lobe on a fine grid
    res = 0.443 / max(revs, 1e-9)
    fine = np.linspace(k0 - res, k0 + res, 41)
    fa = np.array([abs(fit_order(theta, r, k)[0]) for k in fine])
    k_hat = float(fine[int(np.argmax(fa))])
    z, sd_white = fit_order(theta, r, k_hat)
    amp = abs(z)
    sd_local = math.sqrt(floor / 2.0) if math.isfinite(floor) else float("nan")
    amp_sd = max(sd_white, sd_local) if math.isfinite(sd_local) else sd_white
    span = float(np.nanmax(theta) - np.nanmin(theta)) if both_ways else float(np.sum(np.abs(np.diff(theta))))
    order_sd = min(res, math.sqrt(6.0) * amp_sd / max(amp * max(span, 1e-9), 1e-300))
    consistent, why = _consistent(theta, r, int(round(k_hat)) if revs >= 4.0 else k_hat, omega, both_ways)
    locked = bool(p < RIPPLE_FALSE_ALARM and consistent)
    return {"order": k_hat, "order_sd": order_sd, "order_resolution": res, "amplitude": amp,
            "amplitude_sd": amp_sd, "cos": z.real, "sin": z.imag, "phase": float(np.angle(z)),
            "power_over_neighbours": F, "neighbours": m_eff, "neighbour_rms": math.sqrt(floor) if floor == floor else None,
            "p_value": p, "orders_searched": n_search, "revolutions": revs, "consistency": why,
            "consistent": bool(consistent), "angle_locked": locked}


@dataclass
class RippleContrast:
    """The angle-locked ripple of several recordings (e.g. a compensation off and on) at one order."""

    order: float                      #: the order compared [per motor revolution] (the strongest file's)
    order_sd: float
    amplitude: dict[str, float]       #: label -> amplitude at that order [N*m at the output]
    amplitude_sd: dict[str, float]
    significant: dict[str, bool]      #: label -> the ripple stands out of its neighbours in that file
    difference: float                 #: first label's amplitude - the last's [N*m]
    difference_sd: float
    ratio: float                      #: last / first
    message: str

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def ripple_contrast(recordings: dict, params, *, holdout: float = 0.3,
                    order: float | None = None) -> RippleContrast:
    """``recordings``: label -> cleaned Signals (torque and motion, e.g. {"off": ..., "on": ...}). Each is
    diagnosed (:func:`diagnose`); the order is ``order`` [per motor revolution] when given, else the most
    significant file's ripple order, and every file's
    amplitude is fitted AT that order (even where it does not stand out, so the contrast has a number and an
    SD on both sides). The message states the order, the amplitudes with SDs and the change."""
    if len(recordings) < 2:
        raise ValueError(f"ripple_contrast: recordings: expected two or more labelled recordings, got "
                         f"{len(recordings)}")
    runs = {lab: diagnose(sig, params, holdout=holdout) for lab, sig in recordings.items()}
    with_r = {lab: r.ripple for lab, r in runs.items() if r.ripple is not None}
    if not with_r:
        raise ValueError("ripple_contrast: no recording covers enough angle to search an order")
    if order is not None:
        if not (math.isfinite(order) and order > 0):
            raise ValueError(f"ripple_contrast: order: expected a positive number of periods per motor revolution, "
                             f"got {order!r}")
        order_sd = 0.0
    else:
        best = min(with_r, key=lambda lab: (with_r[lab]["p_value"], -with_r[lab]["power_over_neighbours"]))
        order, order_sd = with_r[best]["order"], with_r[best]["order_sd"]
    amp, sd, sig_ = {}, {}, {}
    for lab, r in runs.items():
        th, resid, floor = r.ripple_input
        z, sd_white = fit_order(th, resid, order)
        amp[lab] = abs(z)
        sd[lab] = max(sd_white, math.sqrt(floor / 2.0)) if floor == floor else sd_white
        sig_[lab] = bool(r.ripple and r.ripple["angle_locked"] and abs(r.ripple["order"] - order)
                         <= 3 * math.hypot(r.ripple["order_sd"], order_sd) + 0.5)
    labs = list(recordings)
    a, b = labs[0], labs[-1]
    diff, dsd = amp[a] - amp[b], math.hypot(sd[a], sd[b])
    ratio = amp[b] / amp[a] if amp[a] > 0 else float("nan")
    parts = ", ".join(f"{lab} {amp[lab]:.3g} ± {sd[lab]:.2g} N*m" + ("" if sig_[lab] else " (not above its "
                                                                      "neighbouring orders)") for lab in labs)
    msg = (f"angle-locked torque ripple at order {order:.3g} ± {order_sd:.2g} per motor revolution: {parts}; "
           f"{a} - {b} = {diff:.3g} ± {dsd:.2g} N*m ({abs(diff) / max(dsd, 1e-300):.1f} sigma), {b}/{a} = {ratio:.2f}")
    return RippleContrast(order, order_sd, amp, sd, sig_, diff, dsd, ratio, msg)


# ----------------------------------------------------------------------------------------- diagnosis

def diagnose(sig: Signals, params, *, holdout: float = 0.3, max_harmonics: int = 3) -> TorqueBalanceResult:
    N = float(sig.meta.get("gear_ratio") or params.gear.gear_ratio)
    theta, w, alpha, how = motion(sig)
    tau = sig.channels["torque"]
    ok = np.isfinite(tau) & np.isfinite(theta) & np.isfinite(w) & np.isfinite(alpha)
    notes = [f"no motor current: cogging and friction from the torque balance (sensor torque at the output, gear "
             f"ratio {N:g}); angle {how}"]
    n = int(ok.sum())
    if n < 50:
        return TorqueBalanceResult([], [], notes + [f"only {n} usable samples"], how, float("nan"), {})
    th, om, al, y = theta[ok], w[ok], alpha[ok], tau[ok]
    test = _blocks(n, holdout)
    train = ~test
    w_eps = max(1e-3, 0.02 * float(np.percentile(np.abs(om), 95)))
    sgn = np.where(np.abs(om) > w_eps, np.sign(om), om / w_eps)
    both_ways = min(np.mean(om > w_eps), np.mean(om < -w_eps)) > 0.05
    revs = float(np.nansum(np.abs(np.diff(th)))) / (2 * math.pi)

    # nominal model prediction (the parameters as given): one implementation of the cogging equation
    e, m = params.effects, params.motor
    nominal = -N * (e.coulomb_friction * sgn + m.viscous_damping * om + m.rotor_inertia * al
                    + np.asarray(cogging_torque(th, e.cogging_order, np.asarray(e.cogging_cos, float),
                                                np.asarray(e.cogging_sin, float)) if e.cogging_order else 0.0))

    cols: dict[str, np.ndarray] = {"offset": np.ones(n)}
    terms: list[tuple[str, list[str]]] = []
    if both_ways:
        cols["coulomb"] = -N * sgn
        terms.append(("coulomb_friction", ["coulomb"]))
    else:
        notes.append("motion in one direction only: Coulomb friction and a sensor offset are one column; the drag "
                     "is reported as the offset (experiment: turn it both ways)")
    if np.std(om) > 0:
        cols["viscous"] = -N * om
        terms.append(("viscous_friction", ["viscous"]))
    if np.std(al) * m.rotor_inertia * N > 1e-3 * max(np.std(y), 1e-12):
        cols["inertia"] = -N * al
        terms.append(("inertia_error", ["inertia"]))

    def fit(keys, rows):
        X = np.column_stack([cols[k][rows] for k in keys])
        return ols(X, y[rows])

    def heldout(keys):
        coef, _, _ = fit(keys, train)
        pred = np.column_stack([cols[k][test] for k in keys]) @ coef
        return float(np.sqrt(np.mean((y[test] - pred) ** 2)))

    accepted_keys = ["offset"]
    findings, rejected = [], []
    base_rss = float(np.sum(fit(accepted_keys, np.ones(n, bool))[2] ** 2))
    for effect, keys in terms:
        trial = accepted_keys + keys
        rss = float(np.sum(fit(trial, np.ones(n, bool))[2] ** 2))
        dbic = _bic(base_rss, n, len(accepted_keys)) - _bic(rss, n, len(trial))
        before, after = heldout(accepted_keys), heldout(trial)
        ok_ = dbic > BIC_GATE and after < before
        rec = (effect, keys, dbic, before, after)
        if ok_:
            accepted_keys, base_rss = trial, rss
            findings.append(rec)
        else:
            rejected.append(rec)

    # cogging: the order of the peak of the friction-only residual's angle-order spectrum. Over a span of R
    # revolutions orders are resolved to about 1/R: the peak is reported with that uncertainty (the -3 dB half
    # width of its lobe, ~0.443/R), not refused for a short span; an order needs >= MIN_PERIODS periods in the span
    cog_terms = []
    spectrum = None
    ripple = None
    ripple_input = None
    friction_keys = list(accepted_keys)
    kmin = max(1.0, MIN_PERIODS / max(revs, 1e-9))
    dth = float(np.median(np.abs(np.diff(th)))) or 1e-9 if n > 1 else 1e-9
    kmax = int(min(400, max(2, math.pi / dth / 2)))
    if kmax > kmin:
        _, _, r = fit(accepted_keys, np.ones(n, bool))
        # the ripple locked to the angle in the MEASURED torque: decidable without the motor's own torque
        ripple = angle_locked_ripple(th, r, om, revs, kmin, kmax, both_ways)
        if ripple is not None:
            nr = ripple["neighbour_rms"]
            ripple_input = (th, r, nr ** 2 if nr is not None else float("nan"))
        ks, amps_k = order_scan(th, r, kmin, kmax, revs)
        i = int(np.argmax(amps_k))
        k_peak = float(ks[i])
        order = int(round(k_peak))
        floor = float(np.median(amps_k))
        peak_amp = float(amps_k[i])
        # on the integer grid (>= 4 revolutions) the lobe is narrower than the grid: its -3 dB half width 0.443/R
        order_sd = 0.443 / revs if revs >= 4.0 else _half_width(ks, amps_k, i)
        stands_out = peak_amp >= PEAK_OVER_MEDIAN * floor
        consistent, why = _consistent(th, r, order, om, both_ways)
        spectrum = {"order": k_peak, "order_sd": order_sd, "amplitude": peak_amp,
                    "peak_over_median": peak_amp / max(floor, 1e-300), "revolutions": revs,
                    "integer_orders": [k for k in range(int(math.floor(k_peak - order_sd)),
                                                        int(math.ceil(k_peak + order_sd)) + 1)
                                       if abs(k - k_peak) <= order_sd + 1e-9 and k >= 1],
                    "angle_locked": bool(stands_out and consistent), "consistency": why}
        amps = {order: peak_amp}
        if not (stands_out and consistent):
            notes.append(f"cogging: the order-{k_peak:.3g} peak ({peak_amp:.3g} N*m) "
                         + (f"is only {peak_amp / max(floor, 1e-300):.1f} x the spectrum's median"
                            if not stands_out else f"is not the same in both halves of the data ({why})")
                         + ": not cogging (noise or a time-locked disturbance)")
        for h in range(1, max_harmonics + 1 if stands_out and consistent else 1):
            k = order * h
            if k > kmax:
                break
            cols[f"cog_c{h}"] = -N * np.cos(k * th)
            cols[f"cog_s{h}"] = -N * np.sin(k * th)
            trial = accepted_keys + [f"cog_c{h}", f"cog_s{h}"]
            rss = float(np.sum(fit(trial, np.ones(n, bool))[2] ** 2))
            dbic = _bic(base_rss, n, len(accepted_keys)) - _bic(rss, n, len(trial))
            before, after = heldout(accepted_keys), heldout(trial)
            if dbic > BIC_GATE and after < before:
                accepted_keys, base_rss = trial, rss
                cog_terms.append((h, dbic, before, after))
            else:
                break
        notes.append(f"angle-order spectrum of the friction-only residual: peak at order {k_peak:.3g} ± "
                     f"{order_sd:.2g} per motor revolution ({amps[order]:.3g} N*m at the output, "
                     f"{peak_amp / max(floor, 1e-300):.1f} x the median), {revs:.2f} revolution(s) covered")
        if cog_terms:
            findings.append(("cogging_torque", [c for h, *_ in cog_terms for c in (f"cog_c{h}", f"cog_s{h}")],
                             sum(t[1] for t in cog_terms), cog_terms[0][2], cog_terms[-1][3]))
    not_checkable = [] if spectrum is not None else [
        {"effect": "cogging_torque", "reason": f"the angle covers {revs:.3g} revolution(s): no order up to {kmax} "
                                               f"completes {MIN_PERIODS:g} periods"}]

    coef, cov, r = fit(accepted_keys, np.ones(n, bool))
    idx = {k: i for i, k in enumerate(accepted_keys)}
    r2 = 1.0 - float(np.sum(r ** 2)) / max(float(np.sum((y - y.mean()) ** 2)), 1e-300)
    identifiable = r2 >= 0.5
    if not identifiable:
        notes.append(f"the torque balance explains only {100 * r2:.0f} % of the torque variance: the motor was "
                     "probably powered (its own torque is not logged without current): findings are suspected, "
                     "not identifiable (experiment: log the motor current, or turn it unpowered)")

    def sd(k):
        v = cov[idx[k], idx[k]]
        return float(math.sqrt(v)) if v >= 0 and math.isfinite(v) else float("nan")

    out_f: list[Term] = []
    out_r: list[Term] = []
    for effect, keys, dbic, before, after in findings:
        ho = {"metric": "torque_rms", "unit": "N*m", "before": before, "after": after}
        if effect == "coulomb_friction":
            par, unc, un = {"coulomb_friction": float(coef[idx["coulomb"]])}, {"coulomb_friction": sd("coulomb")}, {"coulomb_friction": "N*m"}
        elif effect == "viscous_friction":
            par, unc, un = {"viscous_damping": float(coef[idx["viscous"]])}, {"viscous_damping": sd("viscous")}, {"viscous_damping": "N*m*s/rad"}
        elif effect == "inertia_error":
            par, unc, un = {"rotor_inertia": float(coef[idx["inertia"]])}, {"rotor_inertia": sd("inertia")}, {"rotor_inertia": "kg*m^2"}
        else:
            par = {"cogging_order": order}
            unc, un = {"cogging_order": spectrum["order_sd"]}, {"cogging_order": ""}
            for h, *_ in cog_terms:
                a, b = float(coef[idx[f"cog_c{h}"]]), float(coef[idx[f"cog_s{h}"]])
                par[f"cos_{h}"], par[f"sin_{h}"] = a, b
                unc[f"cos_{h}"], unc[f"sin_{h}"] = sd(f"cog_c{h}"), sd(f"cog_s{h}")
                un[f"cos_{h}"] = un[f"sin_{h}"] = "N*m"
            par["amplitude_1"] = float(math.hypot(par["cos_1"], par["sin_1"]))
            unc["amplitude_1"] = float(math.hypot(unc["cos_1"], unc["sin_1"]))
            un["amplitude_1"] = "N*m"
        term = Term(effect, par, unc, un, ho, float(dbic), identifiable,
                    "" if identifiable else "suspected, not identifiable (torque balance explains too little)")
        (out_f if identifiable else out_r).append(term)
    for effect, keys, dbic, before, after in rejected:
        out_r.append(Term(effect, {}, {}, {}, {"metric": "torque_rms", "unit": "N*m", "before": before, "after": after},
                          float(dbic), False, f"not supported (dBIC {dbic:.1f} <= {BIC_GATE:g} or held-out not better)"))
    if "coulomb" in idx and coef[idx["coulomb"]] < 0:
        notes.append("fitted Coulomb friction is negative: the torque sensor's sign is probably opposite to the "
                     "canonical one (positive = the actuator drives in +); fix the sign in the input profile")
    offset = float(coef[idx["offset"]])
    notes.append(f"constant torque (sensor offset{'' if both_ways else ' + one-direction drag'}): {offset:.4g} N*m")
    if ripple is not None:
        _ripple_finding(ripple, cols, friction_keys, fit, heldout, n, th, out_f, out_r, notes)
    nom_rms = float(np.sqrt(np.mean((y[test] - nominal[test] - np.mean(y[train] - nominal[train])) ** 2)))
    final = heldout(accepted_keys)
    return TorqueBalanceResult(out_f, out_r, notes, how, r2,
                               {"metric": "torque_rms", "unit": "N*m", "nominal": nom_rms, "after": final},
                               not_checkable, spectrum, ripple, ripple_input)


def _ripple_finding(rip, cols, keys, fit, heldout, n, th, out_f, out_r, notes) -> None:
    """The angle-locked ripple as a finding of its own (the measured torque's, whoever makes it) unless the
    balance already attributes it as the motor's cogging at that order; said in the notes either way."""
    k = rip["order"]
    txt = (f"angle-locked ripple in the measured torque: order {k:.4g} ± {rip['order_sd']:.2g} per motor revolution, "
           f"{rip['amplitude']:.3g} ± {rip['amplitude_sd']:.2g} N*m at the output ({rip['power_over_neighbours']:.1f} x "
           f"the power of its {rip['neighbours']} neighbouring orders, p = {rip['p_value']:.2g} over "
           f"{rip['orders_searched']} orders; {rip['consistency']}), {rip['revolutions']:.2f} revolution(s)")
    if not rip["angle_locked"]:
        notes.append(txt.replace("angle-locked ripple in the measured torque", "no angle-locked ripple in the "
                                 "measured torque: the strongest order") + ": not reported")
        return
    cog = [f for f in out_f if f.effect == COGGING_EFFECT
           and abs(f.parameters.get("cogging_order", -1) - k) <= 3 * rip["order_sd"] + 0.5]
    if cog:
        notes.append(txt + ": attributed to the motor's cogging by the torque balance")
        return
    cols["ripple_c"], cols["ripple_s"] = np.cos(k * th), np.sin(k * th)
    trial = keys + ["ripple_c", "ripple_s"]
    every = np.ones(n, bool)
    rss0, rss1 = (float(np.sum(fit(kk, every)[2] ** 2)) for kk in (keys, trial))
    dbic = _bic(rss0, n, len(keys)) - _bic(rss1, n, len(trial))
    ho = {"metric": "torque_rms", "unit": "N*m", "before": heldout(keys), "after": heldout(trial)}
    par = {"order": k, "amplitude": rip["amplitude"], "cos": rip["cos"], "sin": rip["sin"]}
    unc = {"order": rip["order_sd"], "amplitude": rip["amplitude_sd"], "cos": rip["amplitude_sd"],
           "sin": rip["amplitude_sd"]}
    un = {"order": "per motor revolution", "amplitude": "N*m", "cos": "N*m", "sin": "N*m"}
    notes.append(txt + ": reported as a finding of the measured torque (cogging or torque ripple; without the "
                       "motor current the motor's own share is not separated)")
    out_f.append(Term(RIPPLE_EFFECT, par, unc, un, ho, float(dbic), True,
                      "angle-locked in the measured torque (decidable without the motor current)"))


def updated_params(params, result: TorqueBalanceResult):
    """The parameters with the accepted terms written in (friction, inertia, cogging)."""
    upd = {}
    for f in result.findings:
        p = f.parameters
        if f.effect == "coulomb_friction":
            upd["effects.coulomb_friction"] = max(0.0, p["coulomb_friction"])
        elif f.effect == "viscous_friction":
            upd["motor.viscous_damping"] = max(0.0, p["viscous_damping"])
        elif f.effect == "inertia_error" and p["rotor_inertia"] > 0:
            upd["motor.rotor_inertia"] = p["rotor_inertia"]
        elif f.effect == "cogging_torque":
            h = sorted(int(k.split("_")[1]) for k in p if k.startswith("cos_"))
            upd["effects.cogging_order"] = int(p["cogging_order"])
            upd["effects.cogging_cos"] = tuple(p[f"cos_{k}"] for k in h)
            upd["effects.cogging_sin"] = tuple(p[f"sin_{k}"] for k in h)
    return params.replace(**upd) if upd else params
