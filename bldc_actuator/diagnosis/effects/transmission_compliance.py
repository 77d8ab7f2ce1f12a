"""A compliant transmission: the load a second mass behind a spring.

The catalogue record and its regressor forms (``FORMS``): from the rotor alone a searched anti-resonance
(:func:`v_compliance`, the column :func:`col_compliance`), with a load encoder the measured deflection and its
backlash (:func:`col_deflection`); :mod:`.backlash` offers the rotor-alone forms as its own."""

from __future__ import annotations

import math

import numpy as np

from .forms import Forms, Variant, col_harmonic, sd as sd_of
from .record import Bounds, Effect, Param

EFFECT = Effect(
    name="transmission_compliance", rank=100,
    description="a compliant transmission (shaft, belt, harmonic drive, series-elastic spring): the load is a second "
                "mass on a spring, a two-mass resonance in the rotor's motion",
    equations=("mechanical",), needs=("current", "velocity|position"), simulated=True,
    confusable={"inertia_error": "excite near the resonance (a chirp or steps): a rigid inertia error scales the "
                "acceleration at every frequency, a compliance only above the anti-resonance",
                "current_loop_delay": "a load encoder (joint side) measures the deflection directly"},
    params=(Param("load_inertia_reflected", "kg*m^2", bounds=(
                Bounds(lo=0.0, lo_sd=-3.0, label="reflected load inertia"),     # a load, clear of zero by 3 sd
                Bounds(hi=0.95, nominal="motor.rotor_inertia", label="reflected load inertia"))),   # a rotor left
            Param("load_inertia", "kg*m^2", "gear.load_inertia"),
            Param("transmission_stiffness", "N*m/rad", "gear.transmission_stiffness"),
            Param("transmission_damping", "N*m*s/rad", "gear.transmission_damping"),
            Param("backlash", "rad", "gear.backlash"),
            Param("rotor_inertia_motor_side", "kg*m^2"), Param("antiresonance_frequency", "Hz"),
            Param("resonance_frequency", "Hz"), Param("damping_ratio", "")),
    takes_from_rotor_inertia="load_inertia_reflected",
)


def col_deflection(kind, half: float = 0.0, zero: float = 0.0):
    """Columns of the transmission torque on the rotor measured by two encoders (rotor ``theta`` and load
    ``theta_load``, the load's at the output): ``tau_s/N = (k delta + c d(delta)/dt + offset)/N``,
    ``delta = theta/N - theta_load``; ``kind`` = ``k`` (delta/N), ``c`` (d(delta)/dt / N), ``offset`` (1/N: the
    two encoders' zeros differ by an unknown angle, k times it a constant torque), ``inertia`` (-omega': the load
    the rigid model held in the rotor inertia). With a backlash (``half`` its half width [rad, output side], ``zero``
    the encoders' offset, the dead zone's centre) the spring columns are ``dz(delta - zero)/N`` and the damping's
    only in contact, as the kernel's (:func:`bldc_actuator.kernel.backlash_deflection`)."""
    def build(ctx):
        S = ctx.sig
        N = ctx.params.gear.gear_ratio
        if kind == "inertia":
            return {"mechanical": -S["omega_dot"]}
        if kind == "offset":
            return {"mechanical": np.full(len(ctx.t), 1.0 / N)}
        d = S["theta"] / N - S["theta_load"] - zero
        contact = np.abs(d) > half
        if kind == "k":
            return {"mechanical": (np.sign(d) * np.maximum(np.abs(d) - half, 0.0) if half > 0 else d) / N}
        rate = S["omega"] / N - S["omega_load"]
        return {"mechanical": (rate * contact if half > 0 else rate) / N}
    return build


def compliance_filter(f_a: float, zeta: float, fs: float):
    """Discrete ``(b, a)`` of ``H(s) = -s^2 / (s^2 + 2 zeta w_a s + w_a^2)``, ``w_a = 2 pi f_a`` (bilinear,
    pre-warped at ``w_a`` so the anti-resonance stays where it is): the rotor acceleration's share that the load
    behind a compliant transmission does NOT follow (see :func:`col_compliance`)."""
    w = 2.0 * fs * math.tan(math.pi * f_a / fs)       # pre-warped anti-resonance [rad/s]
    k = 2.0 * fs                                      # s = k (1 - 1/z) / (1 + 1/z)
    kk, dz, ww = k * k, 2.0 * zeta * w * k, w * w
    a0 = kk + dz + ww
    return (np.array([-kk, 2.0 * kk, -kk]) / a0, np.array([1.0, (2.0 * ww - 2.0 * kk) / a0, (kk - dz + ww) / a0]))


def col_compliance(f_a: float, zeta: float):
    """Transmission compliance seen from the rotor alone (motor-side angle, no load encoder). The load J_l behind
    a spring k and damper c (output side) follows the rotor through
    ``theta_l = G theta/N``, ``G = (w_a^2 + 2 zeta w_a s)/(s^2 + 2 zeta w_a s + w_a^2)``, ``w_a = sqrt(k/J_l)``
    (the anti-resonance), ``c = 2 zeta w_a J_l``; the spring torque on the rotor is ``J_l theta_l''/N``. Against a
    rigid model holding the load in the rotor inertia (J_nominal = J + J_l/N^2) the mechanical residual is
    ``(J_l/N^2) (G - 1) omega'`` = column x (reflected load inertia): for a given ``f_a`` and ``zeta`` the
    column is the rotor acceleration through ``G - 1 = -s^2/(s^2 + 2 zeta w_a s + w_a^2)``, its coefficient the
    load inertia reflected to the rotor, ``J_l/N^2`` [kg m^2]. Filtered per segment at the raw rate, started in
    its steady state."""
    def build(ctx):
        from scipy.signal import lfilter, lfilter_zi

        b, a = compliance_filter(f_a, zeta, ctx.fs)
        x = ctx.sig["omega_dot"]
        y = np.zeros_like(x)
        zi = lfilter_zi(b, a)
        for lo, hi in ctx.segments:
            if hi > lo:
                y[lo:hi], _ = lfilter(b, a, x[lo:hi], zi=zi * x[lo])
        return {"mechanical": y}

    def cross(ctx):
        """the loop-fed current-sensor noise this column shares with the residual (fitted out: :mod:`..frame.loop_noise`);
        it depends on the load the coefficient describes (the joint loop answers the noise through it), so it is
        taken at the coefficient of the column's own compensated fit beside the always-fitted nuisance columns"""
        compensated_solve, filter_cross_of_load = ctx.tools.compensated_solve, ctx.tools.filter_cross_of_load

        if "mechanical" not in ctx.blocks:
            return {"mechanical": 0.0}
        cross_of = filter_cross_of_load(ctx, *compliance_filter(f_a, zeta, ctx.fs), ctx.fs)
        rows = ctx.train_rows("mechanical")
        col = ctx.dec.apply(np.nan_to_num(build(ctx)["mechanical"] / ctx.sig["K"]))[rows]
        nuis = [ctx.column(k, b).get("mechanical") for k, b in ctx.nuisance.items()]
        X = np.column_stack([col] + [c[rows] for c in nuis if c is not None])
        y = ctx.blocks["mechanical"].target[rows]
        try:
            _, bias = compensated_solve(X.T @ X, X.T @ y, 0, cross_of)
        except np.linalg.LinAlgError:
            bias = cross_of(0.0)
        return {"mechanical": bias}
    build.cross = cross
    return build


def excite_compliance(ctx):
    """A two-mass shows where the rotor's motion has content near the anti-resonance: acceleration with a part
    above a few hertz, inside the equation error's band."""
    if ctx.params.gear.transmission_stiffness > 0.0:
        return "the nominal parameters already hold a compliant transmission (gear.transmission_stiffness > 0)"
    if ctx.steady:
        return "needs transient motion (a steady-state recording)"
    a = ctx.dsig("omega_dot")
    if not np.std(a) > 0:
        return "needs acceleration"
    if compliance_band(ctx) is None:
        return f"needs a log fast enough to show a resonance (equation-error band up to {ctx.dec.fc:.3g} Hz)"
    fast = a - ctx.dec.lowpass(ctx.sig["omega_dot"], COMPLIANCE_MIN_HZ)[ctx.dec.idx]
    share = float(np.var(fast) / np.var(a))
    return None if share > 0.01 else (f"needs motion with content above {COMPLIANCE_MIN_HZ:g} Hz (the acceleration "
                                      f"holds {100 * share:.2g} % of its variance there)")


#: lowest anti-resonance [Hz] the compliance candidate looks for (below it a load follows its rotor like a rigid one
#: over any useful motion); the highest is a fraction of the equation error's band. Not higher: far below its
#: anti-resonance the column is ``(omega/w_a)^2 omega'``, the shape of the acceleration's own high-frequency deficit
#: (central differences of the angle, twice: ``sinc^2(omega T) ~ 1 - (omega T)^2/3``), which a rigid recording's
#: residual holds (a rigid 1 kHz recording was "explained" by a 77 Hz anti-resonance with 4 % of the inertia when
#: the band reached 70 Hz); a minimum at the top of the band is that deficit, not a resonance, and is not offered
COMPLIANCE_MIN_HZ = 3.0


COMPLIANCE_TOP_OF_BAND = 0.4


#: the compliance search (its grid of anti-resonances) fits the residual and the column low-passed at this fraction of
#: the equation error's cut-off: above it the residual keeps, by design, the angle-locked torques whose columns are
#: switched off there (:func:`resolvable`), and a torque the model leaves out moves the rotor, so the residual
#: follows the acceleration with the opposite sign -- the shape of a load that decouples (builtin
#: cogging_drive_log_10khz: an "anti-resonance" at 8.9 Hz fitted on the cogging left in 60-100 Hz, where the
#: residual followed -0.6 x the inertia's torque with coherence 0.9). Only the search: the final fit keeps the whole
#: band (low-passing the column alone biases its coefficient by the filter's transition).
COMPLIANCE_EVIDENCE_OF_BAND = 0.5


def compliance_evidence_hz(ctx) -> float:
    """[Hz] the compliance search's band (:data:`COMPLIANCE_EVIDENCE_OF_BAND` of the cut-off)."""
    return COMPLIANCE_EVIDENCE_OF_BAND * ctx.dec.fc


#: the backlash form (two encoders) is offered when it lowers the linear form's training residual by at least this
#: fraction, with a dead zone wider than this many load-encoder steps
BACKLASH_MIN_GAIN = 0.1


BACKLASH_MIN_STEPS = 2.0


def _encoder_backlash(ctx) -> Variant | None:
    """Backlash seen by two encoders: the dead zone's half width (log grid from two load-encoder steps to 0.05 rad)
    and centre (the encoders' zero offset, from the linear fit, refined on a small grid) that fit the training
    residual best with the spring, damping, inertia and offset columns; offered when it beats the linear form by
    :data:`BACKLASH_MIN_GAIN`."""
    B = ctx.blocks["mechanical"]
    rows = ctx.train_rows("mechanical")
    y = B.target[rows]
    nuis = [ctx.column(k, b).get("mechanical") for k, b in ctx.nuisance.items()]
    X0 = [c[rows] for c in nuis if c is not None]
    cache = {}

    def dec(kind, half=0.0, zero=0.0):
        key = (kind, half, zero)
        if key not in cache:
            raw = col_deflection(kind, half, zero)(ctx)["mechanical"]
            # decimated in current units, as the equation-error columns are (a search: not cached in the context)
            cache[key] = ctx.dec.apply(np.nan_to_num(raw / ctx.sig["K"]))[rows]
        return cache[key]

    def fit(half, zero):
        X = np.column_stack([dec("k", half, zero), dec("c", half, zero), dec("inertia"), dec("offset")] + X0)
        beta, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ beta
        return float(r @ r), beta

    base, beta = fit(0.0, 0.0)
    if not beta[0] > 0:
        return None
    zero0 = -float(beta[3]) / float(beta[0])      # k (delta - zero) = k delta + offset
    th_l = ctx.sig["theta_load"]
    steps = np.abs(np.diff(th_l))
    steps = steps[steps > 0]
    lo = max(BACKLASH_MIN_STEPS * (float(np.min(steps)) if len(steps) else 0.0), 1e-5)
    best = (base, 0.0, zero0)
    for half in np.geomspace(lo, 0.05, 12):
        for dz in (-0.5, -0.25, 0.0, 0.25, 0.5):
            r, b = fit(float(half), zero0 + dz * float(half))
            if b[0] > 0 and r < best[0]:
                best = (r, float(half), zero0 + dz * float(half))
    if not best[1] > 0 or best[0] > (1.0 - BACKLASH_MIN_GAIN) * base:
        return None
    from scipy.optimize import minimize

    _, h0, z0 = best

    def cost(v):
        half, zero = h0 * math.exp(v[0]), z0 + h0 * v[1]
        if half < lo:
            return float("inf")
        r, b = fit(half, zero)
        return r if b[0] > 0 else float("inf")

    res = minimize(cost, np.zeros(2), method="Nelder-Mead",
                   options={"xatol": 1e-3, "maxiter": 80, "initial_simplex": np.array([[0, 0], [0.2, 0], [0, 0.2]])})
    half, zero = (h0 * math.exp(res.x[0]), z0 + h0 * res.x[1]) if res.fun < best[0] else (h0, z0)
    tag = f"@{half:.6g},{zero:.6g}"      # its own column keys (columns are cached by key)
    return Variant(EFFECT.name,
                   f"from the rotor and load encoders, backlash {1e3 * 2 * half:.3g} mrad",
                   {"tr_k" + tag: col_deflection("k", half, zero), "tr_c" + tag: col_deflection("c", half, zero),
                    "tr_j": col_deflection("inertia"), "tr_0": col_deflection("offset")},
                   hyper={"kind": "encoders", "backlash": 2.0 * half})


def compliance_band(ctx) -> tuple[float, float] | None:
    """(lowest, highest) anti-resonance [Hz] the recording can show, or None."""
    hi = COMPLIANCE_TOP_OF_BAND * min(ctx.dec.fc, 0.4 * ctx.fs)
    return (COMPLIANCE_MIN_HZ, hi) if hi > 2.0 * COMPLIANCE_MIN_HZ else None


def _compliance_rss(ctx, loc=None):
    """``rss(f_a, zeta) -> (rss, coefficient, noise_coefficient)``: the nominal mechanical residual (training rows)
    fitted by the compliance column (with the always-fitted nuisance columns and the angle harmonics of the orders
    the locate stage found in it: an angle-locked torque moves the rotor, so it is fitted beside the column, not
    through it), all low-passed again at
    :func:`compliance_evidence_hz`; the column filtered at the DECIMATED rate from the decimated acceleration (all
    linear: a quick stand-in for the raw-rate column, for the search only). Bias-compensated: the current sensor's
    noise that the drive's loop feeds into the motor makes the residual and the acceleration share a noise of
    opposite signs (:mod:`..frame.loop_noise`), whose expected cross product -- through the joint loop as the recording shows
    it, which answers the noise through the load the coefficient describes -- is taken out of the normal equations
    together with the coefficient (:func:`..frame.loop_noise.compensated_solve`), and so is the angle noise both
    hold (``-J u`` in the target, ``u`` through the column: the scattered instants' and the encoder's
    quantization, :mod:`..frame.clock_noise`, :mod:`..frame.quantization_noise`); ``noise_coefficient`` is the reflected
    inertia that noise alone would give the column (plain least squares = ``coefficient + noise_coefficient``),
    ``rss`` the residual left by the compensated fit."""
    from scipy.signal import butter, lfilter, lfilter_zi

    from ...zero_phase import sosfiltfilt

    compensated_solve, filter_cross_of_load = ctx.tools.compensated_solve, ctx.tools.filter_cross_of_load

    B = ctx.blocks["mechanical"]
    J = ctx.params.motor.rotor_inertia
    rows = ctx.train_rows("mechanical")
    K = np.broadcast_to(np.asarray(ctx.sig["K"], float), ctx.sig["omega_dot"].shape)
    x = ctx.dec.apply(ctx.sig["omega_dot"] / K)
    fs_dec = ctx.fs / max(ctx.dec.q, 1)
    runs = np.flatnonzero(np.diff(ctx.dec.seg_of)) + 1
    bounds = list(zip(np.r_[0, runs], np.r_[runs, len(x)]))
    band = compliance_evidence_hz(ctx)
    sos = butter(ctx.dec.order, min(band, 0.45 * fs_dec) / (0.5 * fs_dec), output="sos")

    def clean(v):
        out = np.nan_to_num(np.asarray(v, float))
        for lo, hi in bounds:
            if hi - lo > 6 * (2 * ctx.dec.order + 1):
                out[lo:hi] = sosfiltfilt(sos, out[lo:hi])
        return out

    y = clean(B.target)[rows]
    yy = float(y @ y)
    nuis = [ctx.column(k, b).get("mechanical") for k, b in ctx.nuisance.items()]
    peaks = ((loc or {}).get("mechanical") or {}).get("order_spectrum") or {}
    for o in sorted({int(pk["order"]) for pk in peaks.get("peaks", [])[:6]}):
        nuis += [ctx.column(f"cog{o}{w[0]}1", col_harmonic(o, 1, w)).get("mechanical") for w in ("cos", "sin")]
    X0 = [clean(c)[rows] for c in nuis if c is not None]
    # what every trial shares is computed once: the nuisance block of the normal equations, and the target-side
    # filtering of the noise sequences (the same arrays on every call: their identity keys the cache)
    X0 = np.column_stack(X0) if X0 else np.zeros((len(y), 0))
    G00, g0 = X0.T @ X0, X0.T @ y
    targets: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def clean_target(u):
        hit = targets.get(id(u))
        if hit is None or hit[0] is not u:
            hit = targets[id(u)] = (u, clean(u))
        return hit[1]

    def rss(f_a, zeta):
        if not 0.0 < f_a < 0.45 * fs_dec:
            return float("inf"), 0.0, 0.0
        b, a = compliance_filter(f_a, zeta, fs_dec)
        zi = lfilter_zi(b, a)

        def filt(v):
            col = np.zeros_like(v)
            for lo, hi in bounds:
                col[lo:hi], _ = lfilter(b, a, v[lo:hi], zi=zi * v[lo])
            return col
        c = clean(filt(x))[rows]
        cX = c @ X0
        G = np.block([[np.atleast_2d(c @ c), cX[None, :]], [cX[:, None], G00]])
        g = np.r_[c @ y, g0]
        bias = np.zeros(len(g))
        # the noise the column shares with the target (-J u): the scattered instants' (frame/clock_noise.py) and
        # the encoder's quantization through the twice-differenced angle (frame/quantization_noise.py)
        timing = J * (ctx.tools.decimated_cross(ctx, lambda u: clean(filt(u)), clean_target)
                      + ctx.tools.quantization_cross(ctx, lambda u: clean(filt(u)), clean_target))
        loop = filter_cross_of_load(ctx, b, a, fs_dec, (sos, fs_dec))
        try:
            beta, bias[0] = compensated_solve(G, g, 0, lambda load: loop(load) - timing)
            plain = np.linalg.solve(G, g)
        except np.linalg.LinAlgError:
            return float("inf"), 0.0, 0.0
        return yy - float((g - bias) @ beta), float(beta[0]), float(plain[0] - beta[0])
    return rss


#: anti-resonances tried before refining (log-spaced over the band) and damping ratios
COMPLIANCE_GRID = 48


COMPLIANCE_ZETA_GRID = (0.02, 0.05, 0.1, 0.2, 0.4)


#: local minima of the grid refined and offered as forms
COMPLIANCE_FORMS = 2


def v_compliance(ctx, loc):
    """The anti-resonance (``f_a``) and its damping ratio searched on the nominal residual: a log grid over
    :func:`compliance_band` x :data:`COMPLIANCE_ZETA_GRID` (a lightly damped two-mass is a narrow valley in
    ``f_a``, so a coarse grid misses it by tens of percent), its best local minima (with a positive load inertia)
    refined jointly in (log f_a, log zeta) by Nelder-Mead; each is one form, its ``f_a`` refined again in the
    final fit (beside the other accepted effects)."""
    from scipy.optimize import minimize

    if "theta_load" in ctx.sig and "mechanical" in ctx.blocks:
        out = [Variant(EFFECT.name, "from the rotor and load encoders (deflection measured)",
                       {"tr_k": col_deflection("k"), "tr_c": col_deflection("c"), "tr_j": col_deflection("inertia"),
                        "tr_0": col_deflection("offset")}, hyper={"kind": "encoders"})]
        bl = _encoder_backlash(ctx)
        return out + ([bl] if bl is not None else [])
    band = compliance_band(ctx)
    if band is None or "mechanical" not in ctx.blocks:
        return []
    lo, hi = band
    rss = _compliance_rss(ctx, loc)
    fs = np.geomspace(lo, hi, COMPLIANCE_GRID)
    table = np.array([[rss(float(f), z) for z in COMPLIANCE_ZETA_GRID] for f in fs])   # (f, zeta, [rss, coef, noise])
    val = np.where(table[:, :, 1] > table[:, :, 2], table[:, :, 0], np.inf)
    best_z = np.argmin(val, axis=1)
    curve = val[np.arange(len(fs)), best_z]
    minima = [i for i in range(1, len(fs) - 1) if np.isfinite(curve[i])
              and curve[i] <= curve[i - 1] and curve[i] <= curve[i + 1]]    # interior: a resonance inside the band
    minima = sorted(minima, key=lambda i: curve[i])[:COMPLIANCE_FORMS]
    out = []
    for i in minima:
        x0 = np.array([math.log(fs[i]), math.log(COMPLIANCE_ZETA_GRID[best_z[i]])])

        def cost(v):
            f, z = math.exp(v[0]), math.exp(min(max(v[1], math.log(0.005)), math.log(1.0)))
            r, c, c_noise = rss(f, z)
            return r if c > c_noise else r + abs(r)

        res = minimize(cost, x0, method="Nelder-Mead", options={"xatol": 0.002, "fatol": 1e-9 * curve[i],
                                                                 "maxiter": 200, "initial_simplex":
                                                                 np.array([x0, x0 + [0.04, 0.0], x0 + [0.0, 0.3]])})
        f = float(math.exp(res.x[0]))
        zeta = float(min(max(math.exp(res.x[1]), 0.005), 1.0))
        if not lo < f < hi:     # refined onto or beyond the band's edge: not a resolved anti-resonance
            continue
        _, c, c_noise = rss(f, zeta)
        if not c > c_noise:     # at least half of the plain fit must be more than the loop-fed sensor noise
            continue
        key = f"compliance@{f:.6g},{zeta:.4g}"
        out.append(Variant(EFFECT.name, f"anti-resonance {f:.3g} Hz, damping ratio {zeta:.2g}",
                           {key: col_compliance(f, zeta)}, hyper={"f_a": f, "zeta": zeta},
                           nonlinear={"f_a": (f, max(lo, f / 1.15), min(hi, f * 1.15),
                                              lambda c, v, key=key, zeta=zeta: {key: col_compliance(v, zeta)})}))
    return out


def params_compliance(coef, cov, keys, variant, ctx):
    """The column's coefficient is the load inertia reflected to the rotor, ``J_l/N^2`` [kg m^2]; with the
    anti-resonance ``f_a`` (refined, in ``variant.hyper``) and damping ratio: ``J_l``, ``k = (2 pi f_a)^2 J_l``,
    ``c = 2 zeta (2 pi f_a) J_l`` (output side), and the rotor side's own inertia, the nominal one less ``J_l/N^2``
    (written by :func:`bldc_actuator.diagnosis.frame.simulate.updated_params`, so an inertia finding composes with it)."""
    N = ctx.params.gear.gear_ratio
    if variant.hyper.get("kind") == "encoders":     # two encoders: k, c and the load inertia fitted directly
        out = _params_compliance_encoders(coef, cov, keys, ctx)
        if "backlash" in variant.hyper:
            ok = out["transmission_stiffness"]["field"] is not None
            out["backlash"] = {"value": float(variant.hyper["backlash"]), "sd": float("nan"), "unit": "rad",
                               "field": "gear.backlash" if ok else None}
        return out
    j_ref = float(coef[0])
    sd = sd_of(cov, 0)
    f_a, zeta = float(variant.hyper["f_a"]), float(variant.hyper["zeta"])
    w_a = 2.0 * math.pi * f_a
    J_l = j_ref * N * N
    j_m = ctx.params.motor.rotor_inertia - j_ref
    f_r = f_a * math.sqrt(1.0 + j_ref / j_m) if j_m > 0 and j_ref > 0 else float("nan")
    rel = sd / abs(j_ref) if j_ref else float("nan")
    ok = j_ref > 0.0
    return {"load_inertia_reflected": {"value": j_ref, "sd": sd, "unit": "kg*m^2", "field": None},
            "load_inertia": {"value": J_l, "sd": sd * N * N, "unit": "kg*m^2", "field": "gear.load_inertia" if ok else None},
            "transmission_stiffness": {"value": w_a * w_a * J_l, "sd": w_a * w_a * J_l * rel, "unit": "N*m/rad",
                                       "field": "gear.transmission_stiffness" if ok else None},
            "transmission_damping": {"value": 2.0 * zeta * w_a * J_l, "sd": 2.0 * zeta * w_a * J_l * rel,
                                     "unit": "N*m*s/rad", "field": "gear.transmission_damping" if ok else None},
            "rotor_inertia_motor_side": {"value": j_m, "sd": sd, "unit": "kg*m^2", "field": None},
            "antiresonance_frequency": {"value": f_a, "sd": float("nan"), "unit": "Hz", "field": None},
            "resonance_frequency": {"value": f_r, "sd": float("nan"), "unit": "Hz", "field": None},
            "damping_ratio": {"value": zeta, "sd": float("nan"), "unit": "", "field": None}}


def _params_compliance_encoders(coef, cov, keys, ctx):
    N = ctx.params.gear.gear_ratio
    ik = next(i for i, key in enumerate(keys) if key.startswith("tr_k"))
    ic = next(i for i, key in enumerate(keys) if key.startswith("tr_c"))
    ij = keys.index("tr_j")
    k, damp, j_ref = float(coef[ik]), float(coef[ic]), float(coef[ij])
    J_l = j_ref * N * N
    ok = k > 0.0 and j_ref > 0.0
    j_m = ctx.params.motor.rotor_inertia - j_ref
    f_a = math.sqrt(k / J_l) / (2.0 * math.pi) if ok else float("nan")
    f_r = f_a * math.sqrt(1.0 + j_ref / j_m) if ok and j_m > 0 else float("nan")
    return {"load_inertia_reflected": {"value": j_ref, "sd": sd_of(cov, ij), "unit": "kg*m^2", "field": None},
            "load_inertia": {"value": J_l, "sd": sd_of(cov, ij) * N * N, "unit": "kg*m^2",
                             "field": "gear.load_inertia" if ok else None},
            "transmission_stiffness": {"value": k, "sd": sd_of(cov, ik), "unit": "N*m/rad",
                                       "field": "gear.transmission_stiffness" if ok else None},
            "transmission_damping": {"value": damp, "sd": sd_of(cov, ic), "unit": "N*m*s/rad",
                                     "field": "gear.transmission_damping" if ok and damp >= 0.0 else None},
            "rotor_inertia_motor_side": {"value": j_m, "sd": sd_of(cov, ij), "unit": "kg*m^2", "field": None},
            "antiresonance_frequency": {"value": f_a, "sd": float("nan"), "unit": "Hz", "field": None},
            "resonance_frequency": {"value": f_r, "sd": float("nan"), "unit": "Hz", "field": None}}


FORMS = Forms(v_compliance, excite_compliance, params_compliance)
