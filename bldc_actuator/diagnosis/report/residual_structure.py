"""Physics outside the catalogue: is the residual left after the accepted effects large and structured, and
where does it sit?

For each model equation, the final equation-error residual is explained by bin means (bins learnt on the training
rows, judged on the held-out rows, so noise cannot pass) of one signal at a time: time, speed, current
(command) and the mechanical angle; and its power spectrum says which frequency band holds most of it. A
residual is *structured* when one signal's bins explain at least :data:`MIN_EXPLAINED` of its held-out variance,
or when a frequency band holds that much more of its held-out power than the recording's own noise would put
there (:func:`noise_reference`: sensor noise through the derivatives and the low-pass the equation error uses, its
levels fitted to the training rows' spectrum; a flat spectrum is wrong for an acceleration differentiated twice from
a noisy angle, whose noise power rises as f^4 up to the cut-off, and an encoder's error is a line wherever the speed
dwells: :func:`quantization_paths`), and *large*
when that structured part is at least :data:`MIN_SIZE` of the equation's own signal (the current for
the mechanical equation, v_q for the electrical one). Such a residual means the catalogue's effects do not
describe the data: the verdict is then not "nothing missing" (:mod:`.results`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

MIN_EXPLAINED = 0.25     #: held-out variance fraction one signal's bins must explain
MIN_SIZE = 0.05          #: structured RMS / the equation's signal RMS
N_BINS = 12

#: equation -> (derived signal the equation is measured against, its name)
_SIGNAL = {"mechanical": ("i_q", "the current"), "electrical": ("v_q", "v_q")}
#: explanatory signal -> (derived signal name, label, unit)
#: (the current coordinate is the aligned current command: binning by the measured current would bin its own noise,
#: which every equation's residual carries; acceleration is left out for the same reason: it is differentiated from
#: the angle, and its noise is in the mechanical residual through J dω/dt)
_WHERE = (("time", None, "time", "s"), ("speed", "omega", "speed", "rad/s"), ("current", "i_inst", "current", "A"),
          ("angle", "theta", "mechanical angle", "rad"))


@dataclass
class Structure:
    """A structured residual in one equation."""

    equation: str
    unit: str
    residual_rms: float          #: held-out residual RMS after the accepted effects
    signal_rms: float            #: held-out RMS of the equation's signal
    signal_name: str
    follows: str                 #: the signal whose bins explain it best
    explained: float             #: fraction of the held-out residual variance those bins explain
    structured_rms: float        #: RMS of that structured part (held-out)
    peak_at: float               #: bin centre with the largest |mean| (in the signal's unit)
    peak_mean: float             #: that bin's mean residual
    where_unit: str
    band_hz: tuple[float, float] | None   #: frequency band holding the most residual power
    band_fraction: float         #: its share of the power
    band_noise_share: float = 0.0   #: the share of the power the recording's noise puts in that band

    @property
    def large(self) -> bool:
        return self.explained >= MIN_EXPLAINED and self.structured_rms >= MIN_SIZE * self.signal_rms

    def describe(self) -> str:
        s = (f"{self.equation} residual RMS {self.residual_rms:.3g} {self.unit} "
             f"({100 * self.residual_rms / max(self.signal_rms, 1e-300):.0f} % of {self.signal_name}) left after the "
             f"accepted effects; {100 * self.explained:.0f} % of it follows {self.follows}")
        if self.peak_mean == self.peak_mean:
            s += f" (largest {self.peak_mean:+.3g} {self.unit} near {self.follows} {self.peak_at:.3g} {self.where_unit})"
        if self.band_hz:
            s += (f", {100 * self.band_fraction:.0f} % of its power in {self.band_hz[0]:.3g}-{self.band_hz[1]:.3g} Hz "
                  f"(its noise would put {100 * self.band_noise_share:.0f} % there)")
        return s

    def to_dict(self) -> dict:
        d = asdict(self)
        d["large"] = self.large
        d["message"] = self.describe()
        return d


def _explained(x: np.ndarray, r: np.ndarray, train: np.ndarray, test: np.ndarray, periodic: bool):
    """Bin means of r over x from the training rows, judged on the test rows: (explained fraction, structured RMS,
    peak bin centre, peak mean)."""
    xt = x[train]
    if periodic:
        edges = np.linspace(0.0, 2 * math.pi, N_BINS + 1)
    else:
        edges = np.unique(np.quantile(xt, np.linspace(0, 1, N_BINS + 1)))
    if len(edges) < 3:
        return 0.0, 0.0, float("nan"), 0.0
    nb = len(edges) - 1
    bt = np.clip(np.searchsorted(edges, xt, side="right") - 1, 0, nb - 1)
    cnt = np.bincount(bt, minlength=nb)
    means = np.bincount(bt, weights=r[train], minlength=nb) / np.maximum(cnt, 1)
    means[cnt < 5] = 0.0
    bh = np.clip(np.searchsorted(edges, x[test], side="right") - 1, 0, nb - 1)
    pred = means[bh]
    rh = r[test] - np.mean(r[train])
    var = float(np.mean(rh ** 2))
    if var <= 0:
        return 0.0, 0.0, float("nan"), 0.0
    expl = 1.0 - float(np.mean((rh - (pred - np.mean(r[train]))) ** 2)) / var
    k = int(np.argmax(np.abs(means - np.mean(r[train]))))
    centre = 0.5 * (edges[k] + edges[k + 1])
    return max(0.0, expl), math.sqrt(max(0.0, expl) * var), float(centre), float(means[k])


def _psd(r: np.ndarray, fs: float):
    from scipy.signal import welch

    return welch(r - np.mean(r), fs=fs, nperseg=min(len(r), 1024))


def _band(r: np.ndarray, fs: float, band=None) -> tuple[tuple[float, float] | None, float]:
    """The 1/3-octave band holding the most power of r (sampled at fs), or the share of power in ``band``."""
    if len(r) < 64 or not fs > 0:
        return None, 0.0
    f, p = _psd(r, fs)
    return _band_of(f, p, fs / len(r), band)


def _band_of(f: np.ndarray, p: np.ndarray, f_min: float, band=None) -> tuple[tuple[float, float] | None, float]:
    """:func:`_band` on a spectrum ``p`` over ``f`` (the DC bin left out of the total)."""
    total = float(np.sum(p[1:]))
    if total <= 0:
        return None, 0.0
    if band is not None:
        m = (f >= band[0]) & (f < band[1])
        return band, float(np.sum(p[m])) / total
    best, frac = None, 0.0
    lo = max(f[1], f_min)
    while lo < f[-1]:
        hi = lo * 2 ** (1 / 3)
        m = (f >= lo) & (f < hi)
        share = float(np.sum(p[m])) / total
        if share > frac:
            best, frac = (float(lo), float(hi)), share
        lo = hi
    return best, frac


#: the noise paths into an equation's residual, as powers of the central difference the derivatives use: a sensor's
#: white noise as recorded (current, voltage), through one derivative (a speed from the angle, di/dt, dv/dt) and
#: through two (the acceleration from the angle)
NOISE_DERIVATIVES = (0, 1, 2)


def noise_shapes(f: np.ndarray, dec) -> np.ndarray | None:
    """Power spectra [k, f] (each peak-normalized) at the decimated rate of white noise at the raw rate taken
    through ``k`` central differences (:data:`NOISE_DERIVATIVES`), the zero-phase low-pass (``sosfiltfilt``: the
    Butterworth's gain squared) and the decimation (``dec.q``: the bands above the decimated Nyquist fold back).
    None without a filter (a steady-state table)."""
    from scipy.signal import sosfreqz

    if getattr(dec, "steady", False) or getattr(dec, "sos", None) is None:
        return None
    fs, q = float(dec.fs), max(1, int(dec.q))
    fs_dec = fs / q
    out = np.zeros((len(NOISE_DERIVATIVES), len(f)))
    for k in range(q + 1):      # aliases k fs_dec +- f inside [0, fs/2]
        for fa in ((k * fs_dec + f), (k * fs_dec - f)) if k else (f,):
            m = (fa >= 0) & (fa <= fs / 2)
            if not m.any():
                continue
            _, h = sosfreqz(dec.sos, worN=fa[m], fs=fs)
            g = np.abs(h) ** 4
            d2 = (fs * np.sin(2 * math.pi * fa[m] / fs)) ** 2
            for j, n in enumerate(NOISE_DERIVATIVES):
                out[j, m] += g * d2 ** n
    peak = out.max(axis=1, keepdims=True)
    return out / np.where(peak > 0, peak, 1.0)


def quantization_paths(ctx) -> dict[str, np.ndarray]:
    """Per equation, the part of its residual the angle's quantization (:func:`..frame.quantization_noise.angle_error`) makes, at the decimated
    instants: the error through one and two central differences (the speed and the acceleration the equations take
    from the angle) and the low-pass, scaled as the equation takes them (mechanical, in current units: -(J dw/dt +
    b w) / K; electrical: -K w). An encoder's error is not white but a sawtooth at |omega| / step and its harmonics,
    folded about the log rate: a line wherever the speed dwells (a 0.8 rad/s triangle on a 14-bit encoder logged at 1
    kHz: 86 Hz). It is re-made by quantizing the smoothed angle on the recorded grid: its spectrum is the recorded
    error's, its phase need not be. Empty when the angle
    is not quantized or the speed is not taken from it."""
    from ..frame.quantization_noise import angle_error

    err = angle_error(ctx)
    if err is None:
        return {}
    d1, d2 = err
    dec, S = ctx.dec, ctx.sig
    m = ctx.params.motor
    K = np.asarray(S.get("K", m.torque_constant_q), float)
    return {"mechanical": dec.apply(-(m.rotor_inertia * d2 + m.viscous_damping * d1) / K),
            "electrical": dec.apply(-K * d1)}


def noise_reference(f: np.ndarray, p: np.ndarray, dec, fixed: np.ndarray | None = None) -> np.ndarray | None:
    """The spectrum the residual has when it is the recording's own noise: ``fixed`` (a noise path's own spectrum,
    e.g. of :func:`quantization_paths` on the same rows, on the same ``f``) plus :func:`noise_shapes` with
    non-negative levels fitted to ``p`` (the training rows' spectrum) up to the cut-off in log power with a robust
    loss (``soft_l1``), so that a band of structure (a few bins far above the rest) does not set the levels. None
    when it cannot be formed."""
    from scipy.optimize import least_squares

    B = noise_shapes(f, dec)
    if B is None:
        return None
    fixed = np.zeros(len(f)) if fixed is None or len(fixed) != len(f) else np.maximum(fixed, 0.0)
    ok = (f > 0) & (f <= dec.fc) & (p > 0)     # (above the cut-off the filter's skirt, leakage and the joins of
    if ok.sum() < 8:                            #  the training blocks set the spectrum, not the noise's level)
        return None
    lp = np.log(p[ok])

    def res(x):
        return np.log(np.exp(x) @ B[:, ok] + fixed[ok] + 1e-300) - lp

    x0 = np.full(len(B), float(np.median(lp)))
    x = least_squares(res, x0, loss="soft_l1", f_scale=0.5).x
    return np.exp(x) @ B + fixed


def find(ctx, fit) -> list[Structure]:
    """The structure of ``fit``'s residual in every equation (large or not; see :attr:`Structure.large`)."""
    out = []
    ho = ctx.holdout_dec
    t = ctx.t_dec
    fs_dec = 1.0 / float(np.median(np.diff(t))) if len(t) > 2 else 0.0
    qpaths = quantization_paths(ctx)
    for eq, B in ctx.blocks.items():
        r = fit.resid.get(eq)
        if r is None or eq not in _SIGNAL or _SIGNAL[eq][0] not in ctx.sig:
            continue
        train, test = B.rows(ho, "train"), B.rows(ho, "holdout")
        if train.sum() < 5 * N_BINS or test.sum() < 2 * N_BINS:
            continue
        sig_rms = float(np.sqrt(np.mean(ctx.dsig(_SIGNAL[eq][0])[test] ** 2)))
        res_rms = float(np.sqrt(np.mean(r[test] ** 2)))
        best = None
        for label, name, what, unit in _WHERE:
            if name is not None and name not in ctx.sig:
                continue
            x = t if name is None else ctx.dsig(name)
            periodic = label == "angle"
            if periodic:
                x = np.mod(x, 2 * math.pi)
            if not np.isfinite(x[train | test]).all() or np.ptp(x[train]) == 0:
                continue
            e, srms, centre, mean = _explained(np.nan_to_num(x), r, train, test, periodic)
            if best is None or e > best[0]:
                best = (e, srms, centre, mean, what, unit)
        # a frequency band: chosen on the training rows, its excess share of power over the share the recording's
        # noise puts there (:func:`noise_reference`, fitted to the training rows; flat up to the low-pass cut-off
        # when it cannot be formed) judged on the held-out rows
        band, frac, ref_share = None, 0.0, 0.0
        if train.sum() >= 64 and test.sum() >= 64 and fs_dec > 0:
            f, p = _psd(r[train], fs_dec)
            band, _ = _band_of(f, p, fs_dec / train.sum())
        if band is not None:
            _, frac = _band(r[test], fs_dec, band)
            qp = qpaths.get(eq)
            ref = noise_reference(f, p, ctx.dec, None if qp is None else _psd(np.nan_to_num(qp[train]), fs_dec)[1])
            if ref is not None:
                _, ref_share = _band_of(f, ref, 0.0, band)
            else:
                ref_share = (band[1] - band[0]) / max(min(ctx.dec.fc, fs_dec / 2), 1e-9)
            excess = (frac - ref_share) / max(1.0 - ref_share, 1e-9)
            if excess > (best[0] if best else 0.0):
                c = 0.5 * (band[0] + band[1])
                best = (excess, math.sqrt(max(excess, 0.0)) * res_rms, c, float("nan"), "a frequency band", "Hz")
        if best is None:
            continue
        out.append(Structure(eq, B.unit, res_rms, sig_rms, _SIGNAL[eq][1], best[4], best[0], best[1], best[2],
                             best[3], best[5], band, frac, ref_share))
    return out
