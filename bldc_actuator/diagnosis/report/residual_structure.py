"""Physics outside the catalogue: is the residual left after the accepted effects large and structured, and
where does it sit?

For each model equation, the final equation-error residual is explained by bin means (bins learnt on the training
rows, judged on the held-out rows, so noise cannot pass) of one signal at a time: time, speed, current
(command) and the mechanical angle; and its power spectrum says which frequency band holds most of it. A
residual is *structured* when one signal's bins explain at least :data:`MIN_EXPLAINED` of its held-out variance,
or when a frequency band holds that much more of its held-out power than a flat spectrum would, and *large*
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
            s += f", {100 * self.band_fraction:.0f} % of its power in {self.band_hz[0]:.3g}-{self.band_hz[1]:.3g} Hz"
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
    total = float(np.sum(p[1:]))
    if total <= 0:
        return None, 0.0
    if band is not None:
        m = (f >= band[0]) & (f < band[1])
        return band, float(np.sum(p[m])) / total
    best, frac = None, 0.0
    lo = max(f[1], fs / len(r))
    while lo < fs / 2:
        hi = lo * 2 ** (1 / 3)
        m = (f >= lo) & (f < hi)
        share = float(np.sum(p[m])) / total
        if share > frac:
            best, frac = (float(lo), float(hi)), share
        lo = hi
    return best, frac


def find(ctx, fit) -> list[Structure]:
    """The structure of ``fit``'s residual in every equation (large or not; see :attr:`Structure.large`)."""
    out = []
    ho = ctx.holdout_dec
    t = ctx.t_dec
    fs_dec = 1.0 / float(np.median(np.diff(t))) if len(t) > 2 else 0.0
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
        # a frequency band: chosen on the training rows, its excess share of power (over a flat spectrum up to the
        # low-pass cut-off) judged on the held-out rows
        band, _ = _band(r[train], fs_dec)
        frac = 0.0
        if band is not None:
            _, frac = _band(r[test], fs_dec, band)
            flat = (band[1] - band[0]) / max(min(ctx.dec.fc, fs_dec / 2), 1e-9)
            excess = (frac - flat) / max(1.0 - flat, 1e-9)
            if excess > (best[0] if best else 0.0):
                c = 0.5 * (band[0] + band[1])
                best = (excess, math.sqrt(max(excess, 0.0)) * res_rms, c, float("nan"), "a frequency band", "Hz")
        if best is None:
            continue
        out.append(Structure(eq, B.unit, res_rms, sig_rms, _SIGNAL[eq][1], best[4], best[0], best[1], best[2],
                             best[3], best[5], band, frac))
    return out
