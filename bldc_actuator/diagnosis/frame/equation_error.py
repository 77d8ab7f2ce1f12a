"""Equation error: the model's equations evaluated on measured signals, with parallel filtering.

Two equations of the q-axis model (see :mod:`bldc_actuator.model`), written as residuals that are zero when
the nominal parameters are right (motor side, SI):

mechanical [A]     ``r_m = i_q - P / K(T_h)``,  ``P = J dω/dt + b ω + τ_f(ω) + τ_cog(θ) + τ_ext/N``
                   (the torque the motion needs; ``τ_ext`` = torque-sensor reading when there is one, else
                   the nominal load ``load.*`` plus the ``load_torque`` channel; all at the output). Written
                   in current units with the measured current alone on the left, so its sensor noise is
                   not scaled by a fitted torque constant; torque columns are divided by K.
electrical [V]     ``r_e = v_q - R(T_w) i_q - L di_q/dt - K(T_h) ω - p ω L i_d``  (needs ``voltage_q``)

A missing effect shows up as ``r = Σ columns · Δparameters``; :mod:`.candidates` builds those columns.

Parallel filtering: every column and every target is built at the raw rate, then the SAME zero-phase
Butterworth low-pass (``scipy.signal.sosfiltfilt``) and the same decimation are applied to all of them,
per gap-free segment. Filtering only the target would make the filter's own lag look like physics.
Masked (NaN) samples are filled for the filter and the mask is filtered too: a decimated sample is used
only when its whole filter support was valid. Statistics (fits, BIC, held-out gates) use decimated data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy import signal as sps

from ... import effects, frames
from ... import drive_tuning
from ... import voltage_timing as vt
from ...params import ActuatorParams
from ... import zero_phase

EQUATIONS = ("mechanical", "electrical")
UNITS = {"mechanical": "A (q current; torque / K)", "electrical": "V (q-axis)"}


# -- filtering and decimation ---------------------------------------------------------------------

@dataclass
class Decimator:
    """Zero-phase low-pass at ``fc`` [Hz] then keep every ``q``-th sample, per segment.

    ``segments`` are ``[start, stop)`` raw index ranges; segments too short for the filter are dropped.
    """

    fs: float
    fc: float
    q: int
    segments: list[tuple[int, int]]
    order: int = 4
    steady: bool = False            #: table of steady-state points: no filter, no decimation
    sos: Any = None
    idx: np.ndarray = field(default=None)      #: raw index of every decimated sample
    seg_of: np.ndarray = field(default=None)   #: segment number of every decimated sample
    edge: np.ndarray = field(default=None)     #: True where the sample sits in a segment's edge zone

    def __post_init__(self):
        if not self.steady:
            self.sos = sps.butter(self.order, self.fc / (0.5 * self.fs), output="sos")
        idx, seg, edge = [], [], []
        margin = 0 if self.steady else int(math.ceil(1.5 * self.fs / self.fc))
        for k, (a, b) in enumerate(self.segments):
            if not self.usable(a, b):
                continue
            i = np.arange(a, b, 1 if self.steady else self.q)
            idx.append(i)
            seg.append(np.full(len(i), k))
            edge.append((i < a + margin) | (i >= b - margin))
        self.idx = np.concatenate(idx) if idx else np.zeros(0, int)
        self.seg_of = np.concatenate(seg) if seg else np.zeros(0, int)
        self.edge = np.concatenate(edge) if edge else np.zeros(0, bool)

    def usable(self, a: int, b: int) -> bool:
        if self.steady:
            return b > a
        return (b - a) > max(40, 6 * (2 * self.order + 1), int(4 * self.fs / self.fc))

    def __len__(self) -> int:
        return len(self.idx)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Filter + decimate a raw column (n,) or matrix (n, k); NaN-free input expected."""
        x = np.asarray(x, dtype=float)
        if self.steady:
            return x[self.idx]
        out = []
        for a, b in self.segments:
            if not self.usable(a, b):
                continue
            y = zero_phase.sosfiltfilt(self.sos, x[a:b], axis=0)
            out.append(y[:: self.q])
        if not out:
            return np.zeros((0,) + x.shape[1:])
        return np.concatenate(out, axis=0)

    def lowpass(self, x: np.ndarray, fc: float | None = None) -> np.ndarray:
        """Zero-phase low-pass at the raw rate (no decimation), per segment."""
        x = np.asarray(x, dtype=float)
        if self.steady:
            return x.copy()
        sos = self.sos if fc is None else sps.butter(self.order, min(fc, 0.45 * self.fs) / (0.5 * self.fs),
                                                     output="sos")
        out = x.copy()
        for a, b in self.segments:
            if b - a > 6 * (2 * self.order + 1):
                out[a:b] = zero_phase.sosfiltfilt(sos, x[a:b], axis=0)
        return out

    def mask(self, valid_raw: np.ndarray) -> np.ndarray:
        """Decimated samples whose filter support was all valid (and not in an edge zone)."""
        valid_raw = np.asarray(valid_raw, dtype=bool)
        if self.steady:
            return valid_raw[self.idx]
        m = self.apply(valid_raw.astype(float))
        return (np.abs(m - 1.0) < 0.01) & valid_raw[self.idx] & ~self.edge


#: the band [Hz] a joint's commanded motion occupies (gait, swings): the default low-pass never cuts below it
MOTION_BAND_HZ = 5.0

#: below this many samples per period of :data:`MOTION_BAND_HZ` the speed comes from an aligned velocity channel,
#: not from central differences of the angle (20: 0.4 % attenuation)
CENTRAL_DIFFERENCE_MIN_RATIO = 20.0


def choose_filter(fs: float, fc: float | None = None) -> tuple[float, int]:
    """Cut-off [Hz] and decimation factor: default cut-off ``min(0.1 fs, 100 Hz)`` (well above the
    mechanical dynamics, well below the current loop), but not below ``min(0.4 fs, MOTION_BAND_HZ)``: a coarse
    log (10 Hz) holds motion up to a few hertz, which a cut-off at 0.1 fs would remove from both sides of every
    equation (and from the states the replay starts from); decimated rate about 4 x cut-off."""
    if fc is None:
        fc = max(min(0.1 * fs, 100.0), min(0.4 * fs, MOTION_BAND_HZ))
    fc = float(min(fc, 0.4 * fs))
    q = max(1, int(fs / (4.0 * fc)))
    return fc, q


# -- the prepared recording -------------------------------------------------------------------------

def _fill(x: np.ndarray, ok: np.ndarray, segments) -> np.ndarray:
    """Linear interpolation over masked samples within each segment (edges held)."""
    x = np.array(x, dtype=float)
    for a, b in segments:
        o = ok[a:b]
        if o.all():
            continue
        if not o.any():
            x[a:b] = 0.0
            continue
        idx = np.arange(a, b)
        x[a:b] = np.interp(idx, idx[o], x[a:b][o])
    return x


def _gradient(x: np.ndarray, t: np.ndarray, segments) -> np.ndarray:
    out = np.zeros_like(x)
    for a, b in segments:
        if b - a >= 3:
            out[a:b] = np.gradient(x[a:b], t[a:b])
    return out


def _lag(ctx, late: np.ndarray, ref: np.ndarray) -> float:
    """Delay δ [s] of ``late`` behind ``ref`` (least squares on ``late ≈ ref - δ ref'``, low-passed)."""
    a = ctx.dec.apply(late)
    b = ctx.dec.apply(ref)
    db = ctx.dec.apply(_gradient(ref, ctx.t, ctx.segments))
    X = np.column_stack([b, -db])
    try:
        coef, *_ = np.linalg.lstsq(X, a, rcond=None)
    except np.linalg.LinAlgError:
        return 0.0
    return float(coef[1] / coef[0]) if coef[0] else 0.0


def _current_instrument(ctx: Context) -> np.ndarray | None:
    """Instrument for every column built from the q current (targets and regressors keep the measured one).

    A column made from the measured current carries the same sensor noise as the target (which contains
    ``K i_meas`` or ``R i_meas``): least squares then fits that noise and biases every current-proportional
    term (errors in variables; with 0.1 A of noise a torque-constant or resistance "error" appears in data that
    has none). The recorded command, aligned by the current loop's lag and clipped to the current limit, is
    free of that noise and follows the current: fits use it as an instrumental variable
    (``β = (ZᵀX)⁻¹ Zᵀy``), which stays consistent where the loop lags or saturates."""
    S, raw, have = ctx.sig, ctx.raw, ctx.have
    i_meas = S["i_q"]
    p = ctx.params
    if "current_command" in have:
        cmd, ok_c = raw["current_command"], ctx.valid["current_command"]
    elif "torque_command" in have:
        cmd = raw["torque_command"] / (p.motor.torque_constant_q * p.gear.gear_ratio)
        ok_c = ctx.valid["torque_command"]
    else:
        ctx.notes.append("no current command recorded: current-proportional terms are fitted against the "
                         "measured current (errors in variables bias them towards zero by the noise share)")
        return None
    lim = p.drive.current_limit
    cmd = np.clip(cmd, -lim, lim)
    if ctx.steady:
        return np.where(ok_c, cmd, i_meas)
    lp_i = ctx.dec.lowpass(i_meas)
    best = None
    for lag in range(0, 6):
        c = np.concatenate([np.full(lag, cmd[0]), cmd[: len(cmd) - lag]]) if lag else cmd
        e = lp_i - ctx.dec.lowpass(c)
        rms = float(np.sqrt(np.mean(e[ok_c] ** 2))) if ok_c.any() else np.inf
        if best is None or rms < best[0]:
            best = (rms, lag, c)
    rms, lag, c = best
    spread = float(np.std(lp_i))
    if not (spread > 0 and np.corrcoef(lp_i[ok_c], ctx.dec.lowpass(c)[ok_c])[0, 1] > 0.5):
        ctx.notes.append(f"the measured current hardly follows the command (tracking error {rms:.3g} A vs "
                         f"{spread:.3g} A): no current instrument, current-proportional terms may be biased")
        return None
    ctx.notes.append(f"current-proportional terms are fitted with the current command ({lag} sample(s) later) as "
                     f"instrument (tracking error {rms:.3g} A RMS vs {spread:.3g} A of signal)")
    return np.where(ok_c, c, i_meas)


#: lag of the acceleration instrument [periods of the equation error's cut-off]: the zero-phase low-pass spreads the
#: residual's noise over a few periods of its cut-off each side, and the joint controller reacts to that noise (in
#: the current command) from one tick on; an instrument older than the spread cannot hold the noise the residual
#: holds (10 kHz drive log, 0.25 A sensor noise, true J = 1.4 x nominal: the command's acceleration unlagged 0.418,
#: 5 ms 0.405, 20 ms 0.402, 30 ms 0.403)
ACCELERATION_INSTRUMENT_LAG_PERIODS = 3.0
#: the acceleration instrument replaces the measured acceleration where the loop-fed current-sensor noise would move
#: the plain inertia coefficient by more than this share of the nominal inertia (elsewhere least squares is the more
#: efficient estimator and the lag would only cost precision)
ACCELERATION_INSTRUMENT_MIN_SHARE = 0.002


def _acceleration_instrument(ctx: Context) -> np.ndarray | None:
    """Instrument [rad/s^2] for every mechanical column built from the measured acceleration (the inertia, the
    torque-constant and magnet columns through ``P``, the load encoder's inertia column), or None.

    Closed-loop data: the drive regulates the current its sensor measures, so the sensor noise ``n`` is a real torque
    noise ``-K T n`` (:mod:`.loop_noise`): the mechanical residual is ``n`` and the measured acceleration holds
    ``-(K/J) T S_o n`` (``S_o`` the joint controller's sensitivity). Least squares reads that shared noise as an
    inertia too small by ``E[omega' n]/E[omega'^2]`` (10 kHz drive log, 0.25 A per phase: -14 % on a rigid joint
    of nominal inertia, a false inertia_error). Its size depends on the true inertia and on the joint controller
    (the nominal-model prediction of :mod:`.loop_noise` over-corrects a heavier joint: +4 % at J = 1.4 x nominal),
    so it is not subtracted: the column is instrumented instead by the acceleration the recorded current command
    asks for (nominal model: ``(K i_cmd - (P - J omega'))/J``; the measured acceleration without a command),
    :data:`ACCELERATION_INSTRUMENT_LAG_PERIODS` cut-off periods EARLIER. The command itself reacts to the noise
    through the joint controller within the filter's spread (unlagged it is biased the other way: +2.4 % on the
    same rigid joint); lagged past it, it is independent of the residual's noise whatever path the noise takes,
    and still follows the motion. Used where :mod:`.loop_noise` predicts a bias above
    :data:`ACCELERATION_INSTRUMENT_MIN_SHARE` of the inertia."""
    from .loop_noise import acceleration_cross

    S, p = ctx.sig, ctx.params
    if ctx.steady or "mechanical" not in ctx.blocks or "omega_dot" not in S:
        return None
    J = p.motor.rotor_inertia
    rows = ctx.train_rows("mechanical")
    x = ctx.dec.apply(S["omega_dot"] / S["K"])[rows]
    xx = float(x @ x)
    if not xx > 0.0:
        return None
    share = acceleration_cross(ctx, ctx.fs, joint=False)(np.ones_like) / xx / J
    if not abs(share) > ACCELERATION_INSTRUMENT_MIN_SHARE:
        return None
    lag = int(round(ACCELERATION_INSTRUMENT_LAG_PERIODS * ctx.fs / ctx.dec.fc))
    if "i_inst" in S:
        a = (S["K"] * S["i_inst"] - (S["P"] - J * S["omega_dot"])) / J
        what = "the acceleration the current command asks for"
    else:
        a = S["omega_dot"]
        what = "the measured acceleration"
    out = np.empty_like(a)
    for lo, hi in ctx.segments:
        k = min(lag, hi - lo)
        out[lo:lo + k] = a[lo]
        out[lo + k:hi] = a[lo:hi - k]
    ctx.notes.append(f"the current sensor's noise fed back by the drive's loop would bias the inertia by "
                     f"{100 * share:+.1f} % in least squares: acceleration columns are fitted with {what} "
                     f"{1e3 * lag / ctx.fs:.3g} ms earlier as instrument")
    return out


def _noise_std(x: np.ndarray) -> float:
    """Sample-to-sample noise level (robust): MAD of first differences / sqrt(2)."""
    d = np.diff(x)
    if len(d) < 3:
        return 0.0
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


@dataclass(frozen=True)
class CommandReplay:
    """How the window replay applies the logged commands between samples — a property of the drive that made the
    recording, which its user rarely knows (issue #14, the gym-electric-motor benchmark): ``hold`` each logged
    command until the next sample (a joint controller running at the log rate), or interpolate it linearly over
    ``substeps`` steps per sample (a command updated faster than the log: a speed loop at the current loop's rate,
    a log that keeps every 10th sample). Decided before any finding is judged (:func:`.simulate.command_replay`):
    by the nominal model's replay of the TRAINING windows both ways (the smaller error), or by the log rate when
    there is nothing to replay."""

    hold: bool                    #: True: each logged command held over its sample interval
    substeps: int                 #: replay steps per sample interval (1 when holding)
    decided_by: str               #: "training replay" | "log rate"
    #: the nominal model's replay error on the training windows, mean over windows, per way ("hold",
    #: "interpolate") and channel ("current" [A], "velocity" [rad/s])
    errors: dict = field(default_factory=dict)
    score: float = float("nan")   #: mean per-window relative error change, interpolated - held (< 0: interpolation better)
    noise_floor: float = float("nan")   #: z standard errors of that mean over the windows
    windows: int = 0

    @property
    def mode(self) -> str:
        return "hold" if self.hold else "interpolate"

    def to_dict(self) -> dict:
        return {"mode": self.mode, "substeps": self.substeps, "decided_by": self.decided_by,
                "errors": self.errors, "score": self.score, "noise_floor": self.noise_floor, "windows": self.windows}


@dataclass(frozen=True)
class FrameTools:
    """The frame's fitting functions an effect's forms call through ``ctx.tools``: the effects package
    (:mod:`..effects.forms`) imports nothing of the frame (``test/test_import_graph.py``)."""

    fit_columns: Callable            #: :func:`fit_columns`
    delta_bic: Callable              #: :func:`delta_bic`
    heldout_comparison: Callable     #: :func:`heldout_comparison`
    robust_std: Callable             #: :func:`robust_std`
    compensated_solve: Callable      #: :func:`.loop_noise.compensated_solve`
    filter_cross_of_load: Callable   #: :func:`.loop_noise.filter_cross_of_load`
    voltage_rate_cross: Callable     #: :func:`.loop_noise.voltage_rate_cross`
    decimated_cross: Callable        #: :func:`.clock_noise.decimated_cross`
    quantization_cross: Callable     #: :func:`.quantization_noise.decimated_cross`


@dataclass
class Context:
    """A recording brought into the model's frame at the raw rate, plus its decimation.

    Arrays are NaN-free (masked samples filled); ``valid[name]`` says which samples were real.
    Derived signals: ``omega`` (measured, or differentiated position), ``omega_s`` (smoothed, for
    nonlinear regressors), ``omega_dot``, ``theta`` (NaN-free rotor angle; ``theta_known``),
    ``i_q``, ``i_d``, ``di_dt``, ``v_q``, ``dv_dt``, ``T_w``, ``T_h`` (measured, proxy or model),
    ``v_max`` and ``headroom`` = |v|/v_max.
    """

    params: ActuatorParams
    t: np.ndarray
    segments: list[tuple[int, int]]
    fs: float
    dec: Decimator
    have: set                                  #: canonical channels present
    raw: dict[str, np.ndarray]                 #: canonical channels, filled
    valid: dict[str, np.ndarray]               #: canonical channel -> raw validity
    sig: dict[str, np.ndarray] = field(default_factory=dict)     #: derived signals (raw rate)
    notes: list[str] = field(default_factory=list)
    holdout_raw: np.ndarray | None = None      #: raw samples in the held-out part
    part_starts: tuple = ()                     #: first raw sample of each concatenated recording
    omega_eps: float = 0.0                     #: velocity noise scale [rad/s] (friction smoothing)
    steady: bool = False
    blocks: dict[str, "Block"] = field(default_factory=dict)
    nuisance: dict[str, Callable] = field(default_factory=dict)   #: always-fitted, never-reported columns
    nuisance_reason: str = ""
    #: how the window replay applies the logged commands between samples; None: by the log rate alone
    #: (:func:`.simulate.replay_substeps`)
    command_replay: CommandReplay | None = None
    #: drive settings identified from the recording before anything is judged (``drive.decoupling_enabled``,
    #: :func:`.drive_feedforward.identify`): every updated parameter set carries them
    drive_updates: dict = field(default_factory=dict)
    #: that identification's result (findings, rejected, not_checkable, simulation), reported by the judge stage
    drive_identified: dict | None = None
    #: the converter form of a found dead time (``drive.dead_time_sign``), chosen from the training windows by
    #: :func:`..judge.simulated.dead_time_form`; None: the file's
    dead_time_sign: str | None = None
    #: how the logged voltage is timed against its samples (:data:`VOLTAGE_TIMINGS`)
    voltage_timing: str = "auto"
    #: the timing the recording declares in its metadata (:func:`declared_timing`), None: it declares none
    declared_timing: vt.VoltageTiming | None = None
    #: the convention the voltage equation reads the logged voltage with (:func:`voltage_shift`): "command" (computed
    #: from the current sample logged with it), "applied" (held at the sample), None (at its sample, or a frame delay)
    voltage_convention: str | None = None
    #: [s] per raw sample: how far the instants the samples were taken at scatter around the time axis (white part;
    #: the cleaning's clock check, ``meta["sampling"]["clock"]``), 0 where none was resolved; noise in the
    #: derivatives (:mod:`.clock_noise`)
    instant_scatter: np.ndarray | None = None
    _col_cache: dict = field(default_factory=dict)
    _inst_cache: dict = field(default_factory=dict)
    _cross_cache: dict = field(default_factory=dict)
    _timing_cache: dict = field(default_factory=dict)
    _inertia_keys: set = field(default_factory=set)
    _memo_cache: dict = field(default_factory=dict)
    _rows_cache: dict = field(default_factory=dict)

    @property
    def tools(self) -> FrameTools:
        """The frame's fitting functions, for the effect modules' forms (:class:`FrameTools`)."""
        from .clock_noise import decimated_cross
        from .loop_noise import compensated_solve, filter_cross_of_load, voltage_rate_cross
        from .quantization_noise import decimated_cross as quantization_cross

        return FrameTools(fit_columns, delta_bic, heldout_comparison, robust_std, compensated_solve,
                          filter_cross_of_load, voltage_rate_cross, decimated_cross, quantization_cross)

    # decimated helpers
    @property
    def t_dec(self) -> np.ndarray:
        return self.t[self.dec.idx]

    @property
    def holdout_dec(self) -> np.ndarray:
        return self.holdout_raw[self.dec.idx]

    def dsig(self, name: str) -> np.ndarray:
        """A derived signal at the decimated instants (filtered like everything else)."""
        key = ("sig", name)
        if key not in self._col_cache:
            self._col_cache[key] = self.dec.apply(self.sig[name])
        return self._col_cache[key]

    def column(self, key, builder: Callable[["Context"], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        """Decimated column ``key`` (equation -> array), built at the raw rate by ``builder`` and cached.

        Built twice when an instrument exists: with the measured current and acceleration (the regressor) and
        with the aligned current command and the lagged acceleration instrument (its instrument,
        :meth:`instrument`; :func:`_current_instrument`, :func:`_acceleration_instrument`). A builder with a ``cross`` attribute
        (``cross(ctx) -> {eq: float}``) states the expected cross product of its column with the equation's
        residual noise (:meth:`cross`)."""
        if key not in self._col_cache:
            S = self.sig
            S["i_col"] = S.get("i_q")
            out = self._build(builder)
            self._col_cache[key] = out
            cross = getattr(builder, "cross", None)
            if cross is not None:
                self._cross_cache[key] = cross(self)
            swap = {"i_col": S["i_inst"]} if "i_inst" in S else {}
            if "a_inst" in S and cross is None:     # a column stating its own cross term keeps the measured motion
                swap.update(omega_dot=S["a_inst"], P=S["P_inst"])
            if swap:
                kept = {k: S[k] for k in swap if k != "i_col"}
                S.update(swap)
                try:
                    z = self._build(builder)
                finally:
                    S.update(kept)
                    S["i_col"] = S.get("i_q")
                if any(not np.array_equal(z[eq], out[eq]) for eq in out):
                    self._inst_cache[key] = z
            if getattr(builder, "inertia", False):
                self._inertia_keys.add(key)
            # the scattered instants' noise the column shares with the residual (:mod:`.clock_noise`); a column
            # instrumented by the lagged acceleration does not share it
            if not ("omega_dot" in swap and key in self._inst_cache):
                from .clock_noise import column_cross

                timing = column_cross(self, lambda: self._build(builder), out)
                if timing:
                    self._timing_cache[key] = timing
        return self._col_cache[key]

    def timing_cross(self, key) -> dict[str, float]:
        """Expected ``sum over an equation's training rows of column x u`` for the noise ``u`` of samples taken at
        scattered instants in the inertia column (:mod:`.clock_noise`): the residual holds ``-(J + beta_J) u``,
        ``beta_J`` the inertia column's coefficient (:meth:`is_inertia`); empty without a resolved scatter."""
        return self._timing_cache.get(key, {})

    def is_inertia(self, key) -> bool:
        """Whether the column ``key`` is the rotor inertia's (its builder says ``inertia = True``)."""
        return key in self._inertia_keys

    def train_rows(self, eq: str) -> np.ndarray:
        hit = self._rows_cache.get(("rows", eq))
        if hit is None:
            hit = self.blocks[eq].rows(self.holdout_dec, "train")
            self._rows_cache[("rows", eq)] = hit
        return hit

    def on_train(self, arr: np.ndarray, eq: str) -> np.ndarray:
        """``arr`` restricted to the training rows of ``eq`` (cached per array: fits reuse columns)."""
        key = (id(arr), eq)
        hit = self._rows_cache.get(key)
        if hit is None or hit[0] is not arr:
            hit = (arr, arr[self.train_rows(eq)])
            self._rows_cache[key] = hit
        return hit[1]

    def instrument(self, key) -> dict[str, np.ndarray] | None:
        """Instrument of a column built from the measured current (see :func:`_regressor_current`)."""
        return self._inst_cache.get(key)

    def memo(self, key, make: Callable[[], Any]) -> Any:
        """``make()`` once per context and ``key`` (derived quantities a search reuses across its grid)."""
        if key not in self._memo_cache:
            self._memo_cache[key] = make()
        return self._memo_cache[key]

    def cross(self, key) -> dict[str, float] | None:
        """Expected ``sum over an equation's training rows of column x residual`` for a column correlated with the
        residual's noise by construction (the loop-fed current-sensor noise in the acceleration: :mod:`.loop_noise`),
        taken out of the normal equations by :func:`fit_columns` (bias-compensated least squares)."""
        return self._cross_cache.get(key)

    def _build(self, builder) -> dict[str, np.ndarray]:
        raw = builder(self)
        out = {}
        for eq, x in raw.items():
            if eq in self.blocks:
                x = np.asarray(x, dtype=float)
                if x.ndim == 0:
                    x = np.full(len(self.t), float(x))
                if eq == "mechanical":     # torque columns -> current units, like the equation
                    x = x / self.sig["K"]
                out[eq] = self.dec.apply(np.nan_to_num(x))
        return out


@dataclass
class Block:
    """One equation on decimated samples: ``target`` (nominal residual), ``valid`` rows."""

    name: str
    target: np.ndarray
    valid: np.ndarray
    unit: str
    raw_target: np.ndarray      #: nominal residual at the raw rate, low-passed (for plots/locate)
    needs: list[str]
    excluded_rest: int = 0

    def rows(self, holdout: np.ndarray, which: str) -> np.ndarray:
        if which == "train":
            return self.valid & ~holdout
        if which == "holdout":
            return self.valid & holdout
        return self.valid


def holdout_mask(t: np.ndarray, segments, fraction: float) -> np.ndarray:
    """Held-out raw samples: the recording cut into 10 equal-time blocks (>= 1 s each when possible),
    every k-th block held out (k = round(1/fraction)), starting with the second; so the held-out part
    spans the recording (different excitation and temperature than its neighbours)."""
    if not (0.0 < fraction < 1.0):
        raise ValueError(f"holdout fraction: expected 0 < f < 1, got {fraction!r}")
    t0, t1 = float(t[0]), float(t[-1])
    dur = max(t1 - t0, 1e-9)
    n_blocks = max(3, min(30, int(round(3.0 / fraction)), int(dur / 1.0) or 3))
    edges = t0 + dur * np.arange(n_blocks + 1) / n_blocks
    k = max(2, int(round(1.0 / fraction)))
    blk = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, n_blocks - 1)
    return (blk % k) == 1


def prepare(parts: list[tuple[Any, bool]], params: ActuatorParams, *, fc: float | None = None,
            holdout: float = 0.3, voltage_timing: str = "auto") -> Context:
    """Concatenate recordings (``(signals, is_holdout_recording)``), fill masks, derive signals, choose
    the filter. With a single recording, the held-out part is chosen by :func:`holdout_mask`."""
    times, chans, segs, hold, starts, scatter = [], {}, [], [], [], []
    offset, n0 = 0.0, 0
    names: set = set()
    notes: list[str] = []
    steady = False
    for sig, _ in parts:
        names |= {k for k, v in sig.channels.items() if np.isfinite(np.asarray(v, float)).any()}
        steady = steady or bool(getattr(sig, "meta", {}).get("steady_state_points", False))
    for sig, is_ho in parts:
        t = np.asarray(sig.time, dtype=float)
        n = len(t)
        if n == 0:
            continue
        tt = t - t[0] + offset
        times.append(tt)
        starts.append(n0)
        for name in names:
            a = np.asarray(sig.channels.get(name, np.full(n, np.nan)), dtype=float)
            chans.setdefault(name, []).append(a)
        seglist = list(getattr(sig, "segments", None) or [(0, n)])
        for a, b in seglist:
            segs.append((int(a) + n0, int(b) + n0))
        hold.append(np.full(n, bool(is_ho)))
        clock = ((getattr(sig, "meta", {}) or {}).get("sampling") or {}).get("clock") or {}
        scatter.append(np.full(n, float(clock.get("instant_scatter_s") or 0.0)))
        dt = np.median(np.diff(t)) if n > 1 else 1.0
        offset = tt[-1] + 10 * dt
        n0 += n
    if not times:
        raise ValueError("diagnose: the recording holds no samples")
    t = np.concatenate(times)
    raw_in = {k: np.concatenate(v) for k, v in chans.items()}
    # split segments further at big time gaps (the data layer does this; be safe)
    segments = []
    for a, b in segs:
        if b - a < 2:
            continue
        dt = np.diff(t[a:b])
        med = np.median(dt)
        cuts = np.flatnonzero(~(dt <= 5 * med) | (dt <= 0)) + 1 + a
        edges = [a] + list(cuts) + [b]
        segments += [(int(x), int(y)) for x, y in zip(edges[:-1], edges[1:]) if y - x >= 2]
    dts = np.concatenate([np.diff(t[a:b]) for a, b in segments]) if segments else np.array([1.0])
    fs = 1.0 / float(np.median(dts))
    jitter = float(np.percentile(np.abs(dts * fs - 1.0), 99)) if len(dts) else 0.0
    if jitter > 0.1 and not steady:
        notes.append(f"sampling is irregular (99th percentile of |dt/dt_median - 1| = {jitter:.2f}); "
                     "filters assume a uniform rate")
    fc_used, q = choose_filter(fs, fc)
    dec = Decimator(fs, fc_used, q, segments, steady=steady)
    if len(dec) == 0:
        raise ValueError(f"diagnose: no segment is long enough for the filter (need > "
                         f"{4 * fs / fc_used:.0f} samples at {fs:.4g} Hz)")
    valid = {k: np.isfinite(v) for k, v in raw_in.items()}
    raw = {k: _fill(v, valid[k], segments) for k, v in raw_in.items()}
    # a current held at the drive's limit (cleaning's "clipped" levels): current-proportional terms are not
    # identifiable there; those samples stay in the signals but leave the equations
    clipped = np.zeros(len(t), bool)
    for (sig, _), a in zip([p for p in parts if len(np.asarray(p[0].time))], starts):
        levels = ((getattr(sig, "meta", {}) or {}).get("clipped") or {}).get("current", {}).get("levels", [])
        if levels and "current" in raw_in:
            seg = raw_in["current"][a:a + len(sig.time)]
            clipped[a:a + len(sig.time)] = np.isin(seg, np.asarray(levels, float))
    if clipped.any() and "current" in valid:
        valid["current"] = valid["current"] & ~clipped
        notes.append(f"current at the drive's limit in {100 * clipped.mean():.1f} % of the samples: left out of "
                     "the model equations (current-proportional terms are not identifiable there)")
    if voltage_timing not in VOLTAGE_TIMINGS:
        raise ValueError(f"voltage_timing: expected one of {', '.join(VOLTAGE_TIMINGS)}, got {voltage_timing!r}")
    # the drive the recording was made with: its current loop's model of the motor where the recording declares it
    params, tuned = drive_tuning.apply(params, drive_tuning.declared([sig for sig, _ in parts]))
    if tuned:
        notes.append(tuned)
    ctx = Context(params=params, t=t, segments=segments, fs=fs, dec=dec, have=set(raw), raw=raw, valid=valid,
                  notes=notes, steady=steady, part_starts=tuple(starts), voltage_timing=voltage_timing,
                  declared_timing=declared_timing([sig for sig, _ in parts]),
                  instant_scatter=np.concatenate(scatter))
    if len(parts) > 1 and any(h for _, h in parts):
        ctx.holdout_raw = np.concatenate(hold)
    else:
        ctx.holdout_raw = holdout_mask(t, segments, holdout)
    _derive(ctx)
    _build_blocks(ctx)
    _nuisance(ctx)
    return ctx


#: same-sample correlation of the logged current's and voltage's fast parts (above 0.3 x the log's Nyquist frequency)
#: at or below which the voltage was computed from the current sample it is logged with (:func:`voltage_alignment`)
SAME_SAMPLE_CORRELATION = -0.5


def voltage_alignment(ctx: Context) -> float | None:
    """[s] how long after its sampling instant the logged q voltage acts on the sampled current, where the log shows
    its convention; else None (the voltage taken at its sample, as before).

    A drive computes the voltage of a period from the current sampled at its start and holds it, after its
    computation delay ``d``, for one loop period ``T``: logged WITH that sample it acts centred ``d + T/2`` after
    it, while the equation's central differences take the current's derivative AT the sample. A voltage-rate
    column then reads the hold as a delay (builtin 10 kHz drive logs, ideal sensors: 50.9 us for d = 0, T/2 = 50
    us; accepted by the equation error as current_loop_delay on all four 10 kHz cases, refused only by the
    simulation). The log shows the pairing where the current sensor's noise is inside the drive's loop: the sample's
    noise reappears in the same sample's voltage as ``-K_p n`` (fast parts correlated below
    :data:`SAME_SAMPLE_CORRELATION`, more than with either neighbour; builtin logs at 100 Hz - 10 kHz: -0.72 to
    -0.99). A log without that signature (noise-free, or a voltage held from an earlier sample) keeps the
    voltage at its sample; the delay column then holds the convention too."""
    S = ctx.sig
    if ctx.steady or "v_q" not in S or "i_q" not in S:
        return None
    cached = ctx.memo(("voltage_alignment",), lambda: _same_sample_correlation(ctx))
    if cached is None:
        return None
    c_prev, c0, c_next = cached
    if not (c0 <= SAME_SAMPLE_CORRELATION and -c0 > max(abs(c_prev), abs(c_next))):
        return None
    return command_voltage_shift(ctx, f"their fast parts correlate {c0:.2f} at the same sample")


#: how a recording's voltage is timed against its samples where the log shows no frame delay on its d axis (a frame
#: delay it shows always places the voltage: :func:`voltage_at_sample`) (``DiagnoseOptions.voltage_timing``,
#: ``--voltage-timing``; the conventions: :mod:`bldc_actuator.voltage_timing`): ``applied`` = the voltage held at the
#: sample (this project's kernel, node and CSV writer: held over the loop period the sample ends, it acted half a
#: period BEFORE the sample); ``command`` = the voltage the drive computed from the sample it is logged with (acting
#: the nominal computation delay + half a loop period later); ``sample`` = the voltage acting at its sample; ``auto``
#: = the convention the recording declares in its metadata (:func:`declared_timing`), else ``command`` where the log
#: shows that pairing's noise signature (:func:`voltage_alignment`), else ``sample``
VOLTAGE_TIMINGS = ("auto", *vt.CONVENTIONS)


def declared_timing(recordings) -> vt.VoltageTiming | None:
    """The voltage timing the recordings declare (``meta["voltage_timing"]``, set by the loaders from an MCAP's
    metadata record or a CSV's comment lines); None when none declares one. Recordings that declare different
    conventions are an error (diagnose them apart, or say which with ``--voltage-timing``)."""
    found = [m for m in (getattr(sig, "meta", {}).get("voltage_timing") for sig in recordings) if m is not None]
    if not found:
        return None
    if len({(m.convention, m.acts_after_sample_s) for m in found}) > 1:
        raise ValueError("voltage_timing: the recordings declare different timings of their voltage ("
                         + "; ".join(f"{m.convention} in {m.source}" for m in found) + "): diagnose them apart")
    return found[0]


def voltage_shift(ctx: Context) -> float | None:
    """[s] how long after its sample the logged q voltage acts (negative: before it), by ``ctx.voltage_timing`` and
    the recording's declaration, where the log shows no frame delay; None: read at its sample. Sets
    ``ctx.voltage_convention``. ``auto`` takes a declared convention first (the writer knows what it logged),
    else the log's pairing signature (:func:`voltage_alignment`); a given convention overrides a declared one (said
    in the notes). A declared offset (the writer's, for its own sample instants) is used as declared."""
    timing, dec = ctx.voltage_timing, ctx.declared_timing
    if timing == "auto" and dec is None:
        shift = voltage_alignment(ctx)
        ctx.voltage_convention = "command" if shift is not None else None
        return shift
    if timing == "auto":
        timing, why = dec.convention, f"declared by the recording: {dec.source}"
    else:
        why = f"the user says so (--voltage-timing {timing})"
        if dec is not None and dec.convention != timing:
            ctx.notes.append(f"voltage equation: the recording declares its voltage timing {dec.convention!r} "
                             f"({dec.source}); --voltage-timing {timing} overrides it")
    offset = dec.acts_after_sample_s if dec is not None and dec.convention == timing else None
    if timing == "sample":
        ctx.notes.append(f"voltage equation: the logged voltage acts at its sample ({why})")
        return None
    ctx.voltage_convention = timing
    if timing == "command":
        return command_voltage_shift(ctx, why, offset)
    return applied_voltage_shift(ctx, why, offset)


def command_voltage_shift(ctx: Context, why: str, offset: float | None = None) -> float:
    """[s] how long after its sample a voltage the drive computed from that sample acts: the nominal computation
    delay (``drive.current_loop_delay``) + half a loop period (the hold), or a declared ``offset``; noted with
    ``why``. A free rotor read at the sample instead carries K² shift / J of apparent resistance (gym-electric-motor's
    drive, 150 µs, J 9e-5 kg·m²: +0.0092 Ω)."""
    d = ctx.params.drive
    shift = vt.command_offset(1.0 / d.current_loop_rate, d.current_loop_delay) if offset is None else offset
    how = "the nominal computation delay + half a loop period" if offset is None else "as declared"
    ctx.notes.append(f"voltage equation: the logged voltage was computed from the current sample logged with it "
                     f"({why}): it acts {1e6 * shift:.3g} µs after the sample ({how})")
    return shift


def applied_voltage_shift(ctx: Context, why: str, offset: float | None = None) -> float:
    """[s] when the voltage held at each sample (``applied``: the kernel's log) acts after it: a declared ``offset``,
    else the kernel's hold for samples at the log rate from a tick with the nominal loop rate and computation delay
    (:func:`bldc_actuator.voltage_timing.applied_offset`; -T/2 for a delay of 0 or T); noted with ``why``. Read at
    the sample instead, a free rotor's resistance comes out K² (T/2) / J LOW (this project's closed-loop recording,
    K 0.091 N·m/A, J 6e-5 kg·m², T 100 µs: -0.0069 Ω predicted, R 0.1624-0.1645 found for 0.17)."""
    if offset is None:
        offset = vt.kernel_applied_offset(ctx.params, 1.0 / ctx.fs)
        how = "the voltage held over the loop period at the sample, nominal loop rate and computation delay"
    else:
        how = "as declared"
    ctx.notes.append(f"voltage equation: the logged voltage is the one applied at its sample ({why}): it acts "
                     f"{1e6 * offset:+.3g} µs after the sample ({how}); the equation reads it "
                     f"{1e6 * abs(offset):.3g} µs {'later' if offset < 0 else 'earlier'}")
    return offset


def _same_sample_correlation(ctx: Context):
    """(lag -1, 0, +1) correlations of the logged current's and q voltage's parts above 0.3 x the Nyquist frequency
    (voltage later at +1), over the gap-free segments; None when too short."""
    S = ctx.sig
    sos = sps.butter(4, 0.3, "high", output="sos")
    a, b = [], []
    for lo, hi in ctx.segments:
        if hi - lo > 100:
            a.append(sps.sosfiltfilt(sos, S["i_q"][lo:hi])[10:-10])
            b.append(sps.sosfiltfilt(sos, S["v_q"][lo:hi])[10:-10])
    if not a:
        return None
    out = []
    for lag in (-1, 0, 1):
        x = np.concatenate([s[max(0, -lag):len(s) - max(0, lag)] for s in a])
        y = np.concatenate([s[max(0, lag):len(s) - max(0, -lag)] for s in b])
        den = math.sqrt(float(x @ x) * float(y @ y))
        out.append(float(x @ y) / den if den > 0 else 0.0)
    return tuple(out)


#: largest delay [loop periods] between a logged voltage's sampling instant and the middle of its application
#: (:func:`frame_delay`; a computation delay of one period plus half the held period is 1.5)
FRAME_DELAY_MAX_PERIODS = 2.5


def acting_v_q(S: dict, pole_pairs: int) -> np.ndarray:
    """The q voltage that acts on the winding: the logged d/q vector turned back by p ω d when the recording's
    voltage frame delay d is known (``S["frame_delay"]``, :func:`frame_delay`), else the logged ``v_q``."""
    if "frame_delay" not in S or "v_d" not in S:
        return S["v_q"]
    phi = pole_pairs * S["omega"] * float(S["frame_delay"])
    return S["v_q"] * np.cos(phi) - S["v_d"] * np.sin(phi)


def voltage_at_sample(ctx: Context, earlier: float = 0.0) -> np.ndarray:
    """The q voltage acting on the winding at each sample's instant (``earlier`` [s] before it), where the recording's
    voltage frame delay d is known (:func:`frame_delay`): the d/q vector logged d (+ ``earlier``) EARLIER
    (:func:`logged_earlier`), turned back by p ω d. A voltage that acts d after its sampling instant acts in the
    states (current, speed) of that later instant too, not only in the rotor's frame: read against the states of its
    own sample, the back-EMF term misses ``K d dω/dt``, and in free motion ``dω/dt ≈ K i_q / J``, so a resistance
    ``K² d / J`` too high appears (motulator's drive, d = 1.5 periods = 150 µs, K 0.0743 N·m/A, J 6e-5 kg·m²:
    +0.0138 Ω on every case, R 0.182 found as 0.193). Without a known delay: the logged ``v_q``."""
    S = ctx.sig
    if "frame_delay" not in S or "v_d" not in S:
        return S["v_q"]
    d = float(S["frame_delay"]) + earlier
    shifted = {"v_q": logged_earlier(ctx, "v_q", d), "v_d": logged_earlier(ctx, "v_d", d),
               "omega": S["omega"], "frame_delay": S["frame_delay"]}
    return acting_v_q(shifted, ctx.params.motor.pole_pairs)


def logged_earlier(ctx: Context, name: str, d: float) -> np.ndarray:
    """The derived signal ``ctx.sig[name]`` as logged ``d`` [s] EARLIER (``d < 0``: later), to first order:
    ``x(t - d) = x - d dx/dt`` with the rate from central differences within each segment (the one reading of "the
    voltage logged d earlier": the frame delay's and the voltage timing's). First order, so a fitted voltage-rate
    column (``v - δ dv/dt``, :func:`.candidates.col_delay`) adds to it exactly (the delay d + δ); for the delays it
    serves (up to 1.5 loop periods, a fraction of a log sample) its in-band error is below linear interpolation's,
    which it replaces (at 100 Hz, 0.15 sample of a 1 kHz log: interpolation -2.5 % in amplitude, this +0.4 %;
    motulator seed 0: R on tp_resistance 0.17891 -> 0.17904 for 0.182, every verdict the same)."""
    S = ctx.sig
    rate = S["dv_dt"] if name == "v_q" else ctx.memo(("rate", name), lambda: _gradient(S[name], ctx.t, ctx.segments))
    return S[name] - d * rate


def frame_delay(ctx: Context) -> tuple[float, float] | None:
    """(d [s], its sd) or None: how long after its sampling instant the logged d/q voltage acts, in a frame the
    rotor has turned by ``p ω d`` since (a PWM holds the voltage in stator coordinates; a drive that advances its
    angle by the delay, or a simulator holding the voltage in rotor coordinates, has none). From the d-axis
    equation on the training rows: ``v_d - (R i_d - p ω L i_q) = L di_d/dt - d p ω v_q`` (first order in
    ``p ω d``; v_q ≈ K ω makes the rotation the d-axis' largest term, and the q-side effects the search looks for
    hardly enter it). None unless d is resolved (> 3 sd, > 0.1 loop period) and below
    :data:`FRAME_DELAY_MAX_PERIODS` periods. motulator's drive: 152 ± 0.3 µs on every case (1.5 periods of 100 µs),
    where the q equation without it kept -0.26 mV/(rad/s) of apparent back-EMF and a correlation time of 0.1 s in
    its residual (n_eff 35 of 1985 rows), which hid a 40 % resistance error."""
    S = ctx.sig
    if ctx.steady or not all(k in S for k in ("v_d", "v_q", "i_d", "i_q", "omega")):
        return None
    m = ctx.params.motor
    pw = m.pole_pairs * S["omega"]
    r_d = S["v_d"] - S["R"] * S["i_d"] + pw * m.q_inductance * S["i_q"]
    did = _gradient(S["i_d"], ctx.t, ctx.segments)
    ok = ctx.valid["voltage_q"] & ctx.valid.get("voltage_d", ctx.valid["voltage_q"]) & ctx.valid["current"] \
        & ctx.valid["omega"] & ctx.valid["i_d"]
    rows = ctx.dec.mask(ok) & ~ctx.holdout_dec
    if rows.sum() < 50:
        return None
    X = np.column_stack([ctx.dec.apply(pw * S["v_q"]), ctx.dec.apply(did)])[rows]
    y = ctx.dec.apply(r_d)[rows]
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(y))) or not np.any(X[:, 0]):
        return None
    c, *_ = np.linalg.lstsq(X, y, rcond=None)
    e = y - X @ c
    cov = np.linalg.pinv(X.T @ X) * float(np.var(e)) * integrated_autocorrelation_time(e)
    d, sd = -float(c[0]), float(np.sqrt(max(cov[0, 0], 0.0)))
    period = 1.0 / ctx.params.drive.current_loop_rate
    if d > 3.0 * sd and 0.1 * period < d <= FRAME_DELAY_MAX_PERIODS * period:
        return d, sd
    return None


def _nuisance(ctx: Context) -> None:
    """Columns fitted in every model but never reported as effects.

    A recording slower than the current loop samples settled currents and voltages: the inductive
    transient after each command step happens between samples, so the recorded v_q misses ``L di/dt`` and
    carries the controller's sampling phase. A free ``di_q/dt`` column absorbs that measurement artefact; the
    inductance is then not identifiable (listed as not checkable). (A ``dv_q/dt`` nuisance would absorb more,
    but in free motion dv/dt ∝ dω/dt ∝ i_q, which leaves a resistance column only the current noise.)"""
    if "electrical" not in ctx.blocks or ctx.steady:
        return
    bw = ctx.params.drive.current_loop_bandwidth
    if ctx.fs >= 4.0 * bw:
        return
    ctx.nuisance = {"nuis_di_dt": lambda c: {"electrical": c.sig["di_dt"]}}
    ctx.nuisance_reason = (f"the recording ({ctx.fs:.4g} Hz) is slower than 4 x the current-loop bandwidth "
                           f"({bw:.4g} Hz): inductive transients happen between samples")
    ctx.notes.append(f"voltage equation: the L di_q/dt term is fitted freely (sampling nuisance), because "
                     f"{ctx.nuisance_reason}")


#: [rad] the widest range a wrapping angle channel covers: one turn, and a little for a sensor's rounding
WRAP_SPAN = 2 * math.pi * (1 + 1e-3)


def _derive(ctx: Context) -> None:
    p = ctx.params
    m, raw, have, segs, t = p.motor, ctx.raw, ctx.have, ctx.segments, ctx.t
    n = len(t)
    S = ctx.sig
    ones = np.ones(n, bool)
    zero = np.zeros(n)
    # angle and speed
    if "position" in have:
        th = raw["position"].copy()
        wrapped_n, continuous_n, span_max = 0, 0, 0.0
        for a, b in segs:
            d = np.diff(th[a:b])
            jump = np.abs(d) > 0.9 * math.pi
            if not jump.any():
                continue
            # whether the channel wraps is read from the channel itself: a wrapping angle stays within one turn
            # ([0, 2 pi), [-pi, pi), ...); one that leaves it is continuous however far it moves per sample (a
            # motor-side angle of a geared servo moves ~20 rad per sample on fast moves), whatever a lagging or
            # filtered speed channel says (issue #24: 11-75 invented turns from the speed-consistency test)
            span = float(np.ptp(th[a:b]))
            if span > WRAP_SPAN:
                continuous_n += int(jump.sum())
                span_max = max(span_max, span)
                continue
            wrapped_n += int(jump.sum())
            if "velocity" in have:   # a coarse log of fast wrapping motion moves > pi per sample: the turns
                v = raw["velocity"][a:b]   # are removed where the velocity says the angle did not go (np.unwrap
                step = 0.5 * (v[1:] + v[:-1]) * np.diff(t[a:b])   # would take the shorter way round)
                turns = np.where(np.isfinite(step), np.round((d - step) / (2 * math.pi)), np.round(d / (2 * math.pi)))
                th[a:b] = th[a] + np.concatenate([[0.0], np.cumsum(d - 2 * math.pi * turns)])
            else:
                th[a:b] = np.unwrap(th[a:b])
        if wrapped_n:
            ctx.notes.append(f"position was wrapped (it stays within one turn and jumps by more than 0.9 pi "
                             f"{wrapped_n} time(s)): unwrapped per segment")
        if continuous_n:
            ctx.notes.append(f"position moves more than 0.9 pi in {continuous_n} sample(s) but spans up to "
                             f"{span_max:.4g} rad (more than one turn): a continuous angle, taken as recorded")
        S["theta"] = th
        ctx.valid["theta"] = ctx.valid["position"]
    use_pos = "position" in have and not ctx.steady
    if use_pos and "velocity" in have:
        # the two must agree in scale before the angle may stand in for the speed
        w_pos = _gradient(S["theta"], t, segs)
        ok = ctx.valid["position"] & ctx.valid["velocity"]
        a, b = ctx.dec.lowpass(w_pos)[ok], ctx.dec.lowpass(raw["velocity"])[ok]
        ratio = float(a @ b / (b @ b)) if len(b) and (b @ b) > 0 else 1.0
        if not 0.9 <= ratio <= 1.1:
            use_pos = False
            ctx.notes.append(f"d(position)/dt is {ratio:.3g} x the velocity channel: speed taken from the velocity "
                             f"channel; angle-dependent effects use the position as recorded")
    S["omega_from_position"] = np.array(0.0)
    if use_pos:
        S["omega_from_position"] = np.array(1.0)
        # central differences of the angle: no delay (a drive's velocity is often a backward difference,
        # half a sample late, which looks like a resistance error in the voltage equation)
        S["omega"] = _gradient(S["theta"], t, segs)
        ctx.valid["omega"] = ctx.valid["position"] & np.roll(ctx.valid["position"], 1) & np.roll(ctx.valid["position"], -1)
        if "velocity" in have:
            lag = _lag(ctx, raw["velocity"], S["omega"])
            S["velocity_channel_lag"] = np.array(lag)
            msg = "velocity taken from the position channel (central differences)"
            if abs(lag) > 0.25 / ctx.fs:
                msg += f"; the velocity channel lags it by {1e3 * lag:.2f} ms"
            elif ctx.fs < CENTRAL_DIFFERENCE_MIN_RATIO * MOTION_BAND_HZ:
                # a coarse log: the difference over +-1 sample attenuates the motion band (6 % for a 1 Hz gait
                # at 10 Hz, several times a resistance change's voltage); an aligned velocity channel does not
                S["omega"] = raw["velocity"]
                S["omega_from_position"] = np.array(0.0)
                ctx.valid["omega"] = ctx.valid["velocity"]
                f_m = min(MOTION_BAND_HZ, 0.1 * ctx.fs)
                x = 2 * math.pi * f_m / ctx.fs
                msg = (f"velocity taken from the velocity channel as recorded (aligned with the position's within a "
                       f"quarter sample): at {ctx.fs:.4g} Hz central differences of the angle attenuate "
                       f"{f_m:.3g} Hz motion by {100 * (1 - math.sin(x) / x):.0f} %")
            ctx.notes.append(msg)
    elif "velocity" in have:
        S["omega"] = raw["velocity"]
        ctx.valid["omega"] = ctx.valid["velocity"]
    elif "position" in have:
        S["omega"] = np.zeros(n)
        ctx.valid["omega"] = ctx.valid["position"]
    if "theta" not in S and "omega" in S:
        th = np.zeros(n)
        for a, b in segs:
            w = S["omega"][a:b]
            th[a:b] = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t[a:b]))])
        S["theta"] = th
        ctx.valid["theta"] = ctx.valid["omega"]
    S["theta_known"] = np.array(1.0 if "position" in have else 0.0)
    if "load_position" in have and not ctx.steady:   # a second encoder behind the transmission (output side)
        S["theta_load"] = raw["load_position"]
        ctx.valid["theta_load"] = ctx.valid["load_position"]
        S["omega_load"] = _gradient(S["theta_load"], t, segs)
    if "omega" in S:
        w = S["omega"]
        S["omega_dot"] = zero.copy() if ctx.steady else _gradient(w, t, segs)
        fc_s = ctx.dec.fc
        S["omega_s"] = ctx.dec.lowpass(w, fc_s)
        if ctx.steady:
            noise = 0.0
        else:   # white-noise level in the smoothed speed, from the part above the cut-off ...
            hi = w - S["omega_s"]
            x = 2.0 * fc_s / ctx.fs
            noise = float(np.std(hi)) * math.sqrt(x / max(1.0 - x, 1e-3))
            # ... or from the top fifth of the band alone, when that is quieter: on a coarse log (10 Hz, cut-off
            # 1 Hz) the motion itself reaches above the cut-off and is not noise (white noise gives both the same)
            top = w - ctx.dec.lowpass(w, 0.4 * ctx.fs)
            noise = min(noise, float(np.std(top)) * math.sqrt(x / 0.2))
        spread = float(np.percentile(np.abs(S["omega_s"]), 90)) if n else 1.0
        ctx.omega_eps = max(2.0 * noise, 1e-3 * spread, 1e-6)
    # currents
    if "current" in have:
        S["i_q"] = raw["current"]
        S["di_dt"] = zero.copy() if ctx.steady else _gradient(S["i_q"], t, segs)
        S["i_col"] = S["i_q"]
        inst = _current_instrument(ctx)
        if inst is not None:
            S["i_inst"] = inst
    S["i_d"] = raw["current_d"] if "current_d" in have else zero.copy()
    ctx.valid.setdefault("i_d", ctx.valid.get("current_d", ones))
    # temperatures: measured, proxy, or the nominal thermal network driven by the measured current
    T_w = raw.get("winding_temperature")
    T_h = raw.get("housing_temperature")
    if T_w is None and T_h is not None:
        T_w = T_h
        ctx.notes.append("winding temperature not recorded: housing temperature used in R(T)")
    if T_h is None and T_w is not None:
        T_h = T_w
        ctx.notes.append("housing temperature not recorded: winding temperature used for the magnet")
    if T_w is None:
        if "i_q" in S:
            T_w, T_h = thermal_response(ctx, p)
        else:
            T_w = T_h = np.full(n, p.thermal.initial_winding_temperature)
    S["T_w"], S["T_h"] = T_w, T_h
    # voltages
    bus = raw["bus_voltage"] if "bus_voltage" in have else np.full(n, p.drive.bus_voltage)
    S["v_max"] = frames.voltage_limit_q(bus, m.winding)
    if "voltage_q" in have:
        S["v_q"] = raw["voltage_q"]
        S["dv_dt"] = zero.copy() if ctx.steady else _gradient(S["v_q"], t, segs)
        v_d = raw["voltage_d"] if "voltage_d" in have else zero
        S["headroom"] = np.hypot(S["v_q"], v_d) / np.maximum(S["v_max"], 1e-9)
        if "voltage_d" in have:
            S["v_d"] = v_d
    # effective torque constant with the nominal magnet temperature dependence
    K = m.torque_constant_q * effects.flux_factor(T_h, m.reference_temperature, m.magnet_temperature_coefficient,
                                                  m.magnet_temperature_enabled)
    S["K"] = K
    S["R"] = effects.resistance_at(m.phase_resistance, T_w, m.reference_temperature,
                                   m.copper_temperature_coefficient, m.resistance_temperature_enabled)


def thermal_response(ctx: Context, p: ActuatorParams, extra_heat: np.ndarray | None = None,
                     T0: tuple[float, float] | None = None, every: int | None = None):
    """Winding and housing temperature of the two-node network driven by the measured Joule power
    ``R(T_w)(i_d² + i_q²)`` (+ ``extra_heat`` [W]), per segment (state carried across segments; a second
    recording, e.g. a held-out file, starts again from its own first measured temperatures),
    evaluated every ``every`` raw samples and held in between. Returns raw-rate (T_w, T_h)."""
    from ... import model

    th, m = p.thermal, p.motor
    S = ctx.sig
    n = len(ctx.t)
    i2 = S["i_q"] ** 2 + S.get("i_d", 0.0) ** 2
    if every is None:
        every = max(1, int(ctx.fs / 20.0))      # 20 Hz is plenty for thermal time constants
    T_w = np.empty(n)
    T_h = np.empty(n)
    y1 = (T0[0] if T0 else th.initial_winding_temperature) - th.ambient_temperature
    y2 = (T0[1] if T0 else th.initial_housing_temperature) - th.ambient_temperature
    cache: dict[float, tuple] = {}
    prev_end = None
    restart = set(ctx.part_starts[1:])
    for a, b in ctx.segments:
        if a in restart:           # another recording (a held-out file): its own measured temperatures
            y1 = _first_temperature(ctx, ("winding_temperature", "housing_temperature"), a, y1 + th.ambient_temperature) \
                - th.ambient_temperature
            y2 = _first_temperature(ctx, ("housing_temperature", "winding_temperature"), a, y2 + th.ambient_temperature) \
                - th.ambient_temperature
        elif prev_end is not None:   # gap: let the network relax without power over the gap
            gap = ctx.t[a] - ctx.t[prev_end - 1]
            if gap > 0:
                p11, p12, p21, p22, *_ = model._thermal_matrices(
                    th.winding_to_housing_resistance, th.housing_to_ambient_resistance,
                    th.winding_heat_capacity, th.housing_heat_capacity, gap, model._ScalarOps)
                y1, y2 = p11 * y1 + p12 * y2, p21 * y1 + p22 * y2
        for k0 in range(a, b, every):
            k1 = min(k0 + every, b)
            T_w[k0:k1] = y1 + th.ambient_temperature
            T_h[k0:k1] = y2 + th.ambient_temperature
            h = float(ctx.t[min(k1, b - 1)] - ctx.t[k0]) if k1 < b else float(ctx.t[b - 1] - ctx.t[k0]) + 1.0 / ctx.fs
            if h <= 0:
                continue
            hk = round(h, 9)
            mats = cache.get(hk)
            if mats is None:
                mats = model._thermal_matrices(th.winding_to_housing_resistance, th.housing_to_ambient_resistance,
                                               th.winding_heat_capacity, th.housing_heat_capacity, h,
                                               model._ScalarOps)
                cache[hk] = mats
            p11, p12, p21, p22, G1, G2, *_ = mats
            R = effects.resistance_at(m.phase_resistance, y1 + th.ambient_temperature, m.reference_temperature,
                                      m.copper_temperature_coefficient, m.resistance_temperature_enabled)
            P = R * float(np.mean(i2[k0:k1]))
            if extra_heat is not None:
                P += float(np.mean(extra_heat[k0:k1]))
            y1, y2 = p11 * y1 + p12 * y2 + G1 * P, p21 * y1 + p22 * y2 + G2 * P
        prev_end = b
    return T_w, T_h


def _first_temperature(ctx: Context, names, k: int, default: float) -> float:
    for n in names:
        if n in ctx.have and ctx.valid[n][k:].any():
            return float(ctx.raw[n][k + int(np.argmax(ctx.valid[n][k:]))])
    return default


def stuck_mask(ctx: Context, window: float | None = None) -> np.ndarray:
    """Raw samples where the rotor does not move: the angle stays within about one encoder count (or
    three noise levels) over ``window`` seconds (default max(20 ms, 5/fc)) centred on the sample."""
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    n = len(ctx.t)
    out = np.zeros(n, bool)
    if "theta" not in ctx.sig or ctx.steady:
        return out
    th = ctx.sig["theta"]
    d = np.abs(np.diff(th))
    nz = d[d > 1e-12]
    quantum = float(np.percentile(nz, 5)) if len(nz) > 10 else 0.0
    d2 = np.diff(th, 2)
    noise = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0) if len(d2) > 10 else 0.0
    tol = max(1.5 * quantum, 3.0 * noise, 1e-9)
    if window is None:
        window = max(0.02, 5.0 / ctx.dec.fc)
    size = max(3, int(round(window * ctx.fs)) | 1)
    for a, b in ctx.segments:
        x = th[a:b]
        rng = maximum_filter1d(x, size, mode="nearest") - minimum_filter1d(x, size, mode="nearest")
        out[a:b] = rng <= tol
    return out


def _build_blocks(ctx: Context) -> None:
    p, S, have = ctx.params, ctx.sig, ctx.have
    m, e, N = p.motor, p.effects, p.gear.gear_ratio
    n = len(ctx.t)
    ones = np.ones(n, bool)
    if "i_q" in S and "omega" in S:
        w, ws = S["omega"], S["omega_s"]
        basis = effects.friction_basis(ws, e.stribeck_velocity, ctx.omega_eps)
        tau_f = basis @ np.array([e.coulomb_friction, e.friction_asymmetry, e.stribeck_friction])
        if e.gear_load_friction:     # the gear's friction grows with the motor's torque K i_q
            tau_f = tau_f + basis[:, 0] * effects.gear_load_friction(S["K"] * S["i_q"], e.gear_load_friction)
        tau_cog = effects.cogging_torque(S["theta"], e.cogging_order, e.cogging_cos, e.cogging_sin) \
            if e.cogging_order and len(e.cogging_cos) else np.zeros(n)
        if "torque" in have:
            tau_ext = ctx.raw["torque"]
            ext_ok = ctx.valid["torque"]
        else:
            tau_ext = effects.position_load_torque_out(S["theta"] / N, p.load.load_torque, p.load.gravity_torque,
                                                       p.load.gravity_phase, p.load.spring_stiffness,
                                                       p.load.spring_zero)
            tau_ext = tau_ext + np.zeros(n)
            ext_ok = ones
            if "load_torque" in have:
                tau_ext = tau_ext + ctx.raw["load_torque"]
                ext_ok = ctx.valid["load_torque"]
        # torque the motion needs (nominal model), and the mechanical equation in CURRENT units with the
        # measured current on the left: its sensor noise stays additive instead of being scaled by a fitted
        # torque constant (which would make the right K look worse than a wrong inertia)
        P = m.rotor_inertia * S["omega_dot"] + m.viscous_damping * w + tau_f + tau_cog + tau_ext / N
        S["P"] = P
        y = S["i_q"] - P / S["K"]
        ok = ctx.valid["current"] & ctx.valid["omega"] & ext_ok
        # stuck (no motion at all for a while): the friction force is then anything up to breakaway, so those
        # samples say nothing. Slow but moving samples stay: dropping them by a speed threshold would select
        # angles (cogging wells) and bias every angle-dependent term.
        rest = stuck_mask(ctx)
        excluded = 0
        if not ctx.steady and 0 < rest.mean() < 0.8:
            grow = max(1, int(ctx.fs / ctx.dec.fc))
            rest = np.convolve(rest.astype(float), np.ones(2 * grow + 1), "same") > 0
            excluded = int((rest & ok).sum())
            ok = ok & ~rest
        elif rest.mean() >= 0.8:
            ctx.notes.append(f"rotor at rest in {100 * rest.mean():.0f}% of samples: friction is not identifiable")
        S["rest"] = rest.astype(float)
        ctx.blocks["mechanical"] = Block("mechanical", ctx.dec.apply(y), ctx.dec.mask(ok), UNITS["mechanical"],
                                         ctx.dec.lowpass(y), ["current", "velocity|position"], excluded)
        a_inst = _acceleration_instrument(ctx)
        if a_inst is not None:
            S["a_inst"] = a_inst
            S["P_inst"] = P + m.rotor_inertia * (a_inst - S["omega_dot"])
    if "i_q" in S and "omega" in S and "v_q" in S:
        v_q = S["v_q"]
        fd = frame_delay(ctx)
        if fd is not None:     # the q voltage that acts on the winding at the states' instant (see below)
            S["frame_delay"] = np.array(fd[0])
            v_q = voltage_at_sample(ctx)
            ctx.notes.append(f"voltage equation: the logged voltage acts {1e6 * fd[0]:.3g} ± {1e6 * fd[1]:.2g} µs "
                             f"after its sampling instant, in a frame the rotor has turned by p ω d since (from the "
                             f"d-axis equation; a PWM that holds it in stator coordinates): the q equation at each "
                             f"sample uses the voltage logged d earlier, turned back by p ω d")
        # without a frame delay, the recording's declared timing, the user's, or the log's own pairing of voltage and
        # current sample says when the voltage acts (a frame delay already places it: one shift, not two)
        shift = voltage_shift(ctx) if fd is None else None
        if shift is not None:   # the voltage that drives the sampled current: the one logged ``shift`` earlier
            S["voltage_alignment"] = np.array(shift)
            v_q = logged_earlier(ctx, "v_q", shift)
        y = v_q - S["R"] * S["i_q"] - m.q_inductance * S["di_dt"] - S["K"] * S["omega"] \
            - m.pole_pairs * S["omega"] * m.q_inductance * S["i_d"]
        ok = ctx.valid["voltage_q"] & ctx.valid["current"] & ctx.valid["omega"] & ctx.valid["i_d"]
        ctx.blocks["electrical"] = Block("electrical", ctx.dec.apply(y), ctx.dec.mask(ok), UNITS["electrical"],
                                         ctx.dec.lowpass(y), ["voltage_q", "current", "velocity|position"])


# -- statistics -----------------------------------------------------------------------------------

def integrated_autocorrelation_time(r: np.ndarray, max_lag: int = 200) -> float:
    """τ_int = 1 + 2 Σ ρ_k (Sokal window: stop at the first lag with ρ_k < 0.05): samples per
    independent sample of a coloured residual. ``n_eff = n / τ_int``."""
    import scipy.fft as sfft

    r = np.asarray(r, float)
    r = r - r.mean()
    n = len(r)
    if n < 8 or not np.any(r):
        return 1.0
    L = min(max_lag, n // 4)
    m = sfft.next_fast_len(2 * n, real=True)
    f = sfft.rfft(r, m)
    ac = sfft.irfft(f.real ** 2 + f.imag ** 2, m)[: L + 1]
    ac = ac / ac[0]
    tau = 1.0
    for k in range(1, L + 1):
        if ac[k] < 0.05:
            break
        tau += 2.0 * ac[k]
    return float(tau)


@dataclass
class Fit:
    """Weighted least-squares fit of a set of columns on the equation blocks."""

    keys: list[str]
    beta: np.ndarray
    cov: np.ndarray
    rss: dict[str, float]            #: per block, training, unweighted
    n: dict[str, int]
    n_eff: dict[str, float]
    resid: dict[str, np.ndarray]     #: per block, over ALL decimated samples (NaN where invalid)
    weights: dict[str, float]

    def coef(self) -> dict[str, float]:
        return dict(zip(self.keys, self.beta))


def fit_columns(ctx: Context, cols: dict[str, dict[str, np.ndarray]], keys: list[str],
                weights: dict[str, float], blocks: list[str] | None = None) -> Fit:
    """Stacked weighted least squares ``w_e y_e ≈ w_e X_e β`` over the blocks (training rows only).

    ``cols[key][eq]`` is a decimated column (absent for an equation it does not enter). Returns
    residuals on every decimated sample so held-out errors follow without refitting.
    """
    blocks = blocks or list(ctx.blocks)
    Xs, Zs, ys, parts = [], [], [], []
    use_iv = False
    bias = np.zeros(len(keys))      # expected Xᵀe of columns correlated with the noise by construction
    timing = np.zeros(len(keys))    # ... the scattered instants' share, per unit of the inertia (-(J + beta_J) timing)
    j_inertia = next((j for j, k in enumerate(keys) if ctx.is_inertia(k)), None)
    for eq in blocks:
        B = ctx.blocks[eq]
        rows = ctx.train_rows(eq)
        w = weights[eq]
        X = np.zeros((int(rows.sum()), len(keys)))
        Z = np.zeros_like(X)
        for j, k in enumerate(keys):
            c = cols[k].get(eq)
            if c is not None:
                bias[j] += w * w * float((ctx.cross(k) or {}).get(eq, 0.0))
                timing[j] += w * w * float(ctx.timing_cross(k).get(eq, 0.0))
                X[:, j] = ctx.on_train(c, eq)
                inst = ctx.instrument(k)
                if inst is not None and inst.get(eq) is not None:
                    Z[:, j] = ctx.on_train(inst[eq], eq)
                    use_iv = True
                else:
                    Z[:, j] = X[:, j]
        Xs.append(w * X)
        Zs.append(w * Z)
        ys.append(w * B.target[rows])
        parts.append((eq, rows))
    X = np.vstack(Xs) if Xs else np.zeros((0, len(keys)))
    Z = np.vstack(Zs) if Zs else np.zeros((0, len(keys)))
    y = np.concatenate(ys) if ys else np.zeros(0)
    if keys:
        scale = np.sqrt((X ** 2).sum(axis=0))
        scale[scale == 0] = 1.0
        Xn, Zn = X / scale, Z / scale
        A_n = Zn.T @ Xn
        if timing.any():   # Zᵀ(y - Xβ) = -(J + β_J) timing: the inertia coefficient's share moves to the left
            J = ctx.params.motor.rotor_inertia
            bias = bias - J * timing
            if j_inertia is not None:
                A_n[:, j_inertia] -= timing / (scale * scale[j_inertia])
        if bias.any():   # bias-compensated: Zᵀ(y - Xβ) = E[Zᵀe]
            use_iv = True
            beta_n, *_ = np.linalg.lstsq(A_n, Zn.T @ y - bias / scale, rcond=1e-12)
        elif use_iv:   # instrumental variables: Zᵀ(y - Xβ) = 0
            beta_n, *_ = np.linalg.lstsq(Zn.T @ Xn, Zn.T @ y, rcond=1e-12)
        else:
            beta_n, *_ = np.linalg.lstsq(Xn, y, rcond=1e-10)
        beta = beta_n / scale
    else:
        beta = np.zeros(0)
        Xn, Zn, scale = X, Z, np.ones(0)
    rss, nn, neff, resid = {}, {}, {}, {}
    taus = []
    for eq, rows in parts:
        B = ctx.blocks[eq]
        pred = np.zeros(len(B.target))
        for j, k in enumerate(keys):
            c = cols[k].get(eq)
            if c is not None:
                pred = pred + beta[j] * c
        r = B.target - pred
        r_all = np.where(B.valid, r, np.nan)
        resid[eq] = r_all
        rt = r[rows]
        rss[eq] = float(rt @ rt)
        nn[eq] = int(rows.sum())
        tau = integrated_autocorrelation_time(rt)
        taus.append(tau)
        neff[eq] = nn[eq] / tau
    # covariance of β: s² (XᵀX)⁻¹ inflated by the residual's correlation time
    if keys and len(y) > len(keys):
        rw = y - X @ beta
        s2 = float(rw @ rw) / (len(y) - len(keys))
        tau = float(np.mean(taus)) if taus else 1.0
        try:
            if use_iv:
                A = np.linalg.pinv(A_n)
                cov_n = A @ (Zn.T @ Zn) @ A.T * s2 * tau
            else:
                cov_n = np.linalg.pinv(Xn.T @ Xn) * s2 * tau
        except np.linalg.LinAlgError:
            cov_n = np.full((len(keys), len(keys)), np.inf)
        cov = cov_n / np.outer(scale, scale)
    else:
        cov = np.zeros((len(keys), len(keys)))
    return Fit(list(keys), beta, cov, rss, nn, neff, resid, dict(weights))


def touched(base: Fit, new: Fit, rtol: float = 1e-12) -> list[str]:
    """Equations whose training residual differs between two fits (where the new columns enter)."""
    return [eq for eq in new.rss if abs(new.rss[eq] - base.rss.get(eq, 0.0)) > rtol * max(base.rss.get(eq, 0.0), 1e-300)]


def delta_bic(base: Fit, new: Fit) -> float:
    """ΔBIC (positive = the new model is better) with the effective sample count of the new model's
    residual per block: ``Σ_e n_eff,e ln(RSS0_e/RSS1_e) - Δk ln(Σ n_eff)``, over the equations the
    difference touches."""
    gain = 0.0
    eqs = touched(base, new) or list(new.rss)
    for eq in eqs:
        if base.rss.get(eq, 0) > 0 and new.rss[eq] > 0:
            gain += new.n_eff[eq] * math.log(base.rss[eq] / new.rss[eq])
    dk = len(new.keys) - len(base.keys)
    n_tot = max(2.0, sum(new.n_eff[eq] for eq in eqs))
    return float(gain - dk * math.log(n_tot))


def robust_std(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    if len(x) < 3:
        return 1.0
    s = 1.4826 * float(np.median(np.abs(x - np.median(x))))
    return s if s > 0 else float(np.std(x)) or 1.0


def heldout_comparison(ctx: Context, base: Fit, new: Fit, weights: dict[str, float],
                       chunk_seconds: float | None = None) -> dict[str, Any]:
    """Held-out error before/after: relative RMS change of the weighted stacked residual and a t-statistic
    of the per-chunk change in squared error (chunks of contiguous held-out time)."""
    ho = ctx.holdout_dec
    tdec = ctx.t_dec
    d_all, t_all, r0_all, r1_all = [], [], [], []
    per_eq = {}
    for eq in (touched(base, new) or list(new.resid)):
        B = ctx.blocks[eq]
        rows = B.rows(ho, "holdout")
        if not rows.any():
            continue
        w = weights[eq]
        r0 = base.resid[eq][rows] * w
        r1 = new.resid[eq][rows] * w
        per_eq[eq] = (float(np.sqrt(np.mean((r0 / w) ** 2))), float(np.sqrt(np.mean((r1 / w) ** 2))))
        d_all.append(r0 ** 2 - r1 ** 2)
        t_all.append(tdec[rows])
        r0_all.append(r0)
        r1_all.append(r1)
    if not d_all:
        return {"available": False, "rel": 0.0, "t": 0.0, "per_eq": {}}
    d = np.concatenate(d_all)
    tt = np.concatenate(t_all)
    r0 = np.concatenate(r0_all)
    r1 = np.concatenate(r1_all)
    ss0, ss1 = float(r0 @ r0), float(r1 @ r1)
    rel = 1.0 - math.sqrt(ss1 / ss0) if ss0 > 0 else 0.0
    # chunks: contiguous time pieces of about chunk_seconds
    dur = float(tt.max() - tt.min()) if len(tt) else 0.0
    if chunk_seconds is None:
        chunk_seconds = max(0.25, dur / 60.0)
    order = np.argsort(tt, kind="stable")
    tt, d = tt[order], d[order]
    cid = np.floor((tt - tt[0]) / chunk_seconds).astype(int)
    _, inv = np.unique(cid, return_inverse=True)
    sums = np.bincount(inv, weights=d)
    if len(sums) >= 4 and np.std(sums) > 0:
        tstat = float(np.mean(sums) / (np.std(sums, ddof=1) / math.sqrt(len(sums))))
    else:
        tstat = 0.0
    return {"available": True, "rel": rel, "t": tstat, "per_eq": per_eq, "chunks": int(len(sums))}


def rms(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2))) if len(x) else float("nan")


def ee_metrics(ctx: Context, fit: Fit) -> dict[str, dict[str, float]]:
    """Equation-error residual RMS per equation on training and held-out rows."""
    ho = ctx.holdout_dec
    out = {}
    for eq, B in ctx.blocks.items():
        r = fit.resid[eq]
        out[eq] = {"train_rms": rms(r[B.rows(ho, "train")]), "holdout_rms": rms(r[B.rows(ho, "holdout")]),
                   "unit": B.unit}
    return out
