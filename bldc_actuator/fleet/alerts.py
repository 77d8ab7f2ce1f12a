"""Alerts a maintenance engineer can act on, from the first recordings of each tracked series.

A *series* is one actuator (id, joint) and one tracked parameter: its recordings ordered by start time, each
with a value and its stated 1-sigma uncertainty ``u_i`` (rows of status ``ok`` or ``warning``). Three kinds
of alert, each with its evidence; one alert record per series that raises any of them:

``off_nominal``  the LATEST recording's value differs from the reference -- the nominal parameter file, or with
                 ``reference="fleet"`` the fleet's own baseline for that actuator type (median over actuators
                 with the same parameter file of their first recordings; its unit-to-unit spread joins the
                 uncertainty) -- by more than the tolerance (relative, default 10 %, per parameter
                 overridable) AND by more than ``k_sigma`` (default 5) combined uncertainties
                 ``sqrt(F^2 u_i^2 + u_ref^2)``, AND that recording's change is supported the way a ``diagnose``
                 finding must be (row field ``supported``: diagnose's own verdict where it ran, else the same
                 selection gate and significance judge on the tracked fit, :func:`.health.support`; a value the
                 held-out data does not support is never an alert, however many sd it is off). From the first
                 recording.
``drifting``     weighted least squares of value vs time (weights ``1/u_i^2``); slope ``b`` with
                 ``se(b) = F / sqrt(sum w_i (t_i - t_w)^2)``; alert when ``|b| / se(b) > t_{1-alpha/2}(D)``.
                 From three recordings. ``F^2 = max(1, B^2)`` is the over-dispersion of the stated
                 uncertainties (Birge ratio): ``B^2 = sum chi^2 / sum dof`` of the weighted straight-line fits
                 of every series of that parameter in the fleet (``D = sum dof``; a series whose own fit is
                 not a straight line at p < 1e-4 against the fleet's median scatter -- a step -- is left
                 out of the pool). When the stated
                 uncertainties are honest (B^2 <= 1) the test is a z-test with them; when recordings scatter
                 more than stated, the scatter is measured on the fleet and the t quantile pays for its
                 estimation. From 5 recordings on, a series whose OWN chi^2/dof exceeds the fleet's uses its
                 own (t quantile with its own n - 2 dof): the fleet's log formats differ (a log with voltage
                 fixes K_t far better than one without), and a pooled B^2 below 1 let the worst-stated series
                 of a 30-day fleet alarm at 5x alpha. FALSE-ALARM RATE: ``alpha`` per series and run (default 0.001) for stable
                 actuators whose recording-to-recording scatter is Gaussian, independent and shares one
                 over-dispersion factor per parameter across the fleet (checked by Monte Carlo in
                 ``test_fleet_alerts.py`` and measured on a generated stable fleet: docs/fleet.md).
``shifted``      series of >= 8 recordings only: the robust baseline-vs-recent median test of :mod:`.trends`
                 (a step such as a K_t loss after an over-temperature event, which a straight line describes
                 poorly); false-alarm rate ``alpha`` per series, calibrated by Monte Carlo.

Every series gets, when the user gives a limit for its parameter (``limits={"coulomb_friction": 0.05}``),
the projected date the fitted line reaches it (with the dates for slope +- 1 se), or the first recording
that already passed it.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from . import trends

DEFAULT_ALPHA = 1e-3
DEFAULT_K_SIGMA = 5.0
DEFAULT_TOLERANCE = 0.10
MIN_DRIFT = 3
#: from this many residual dof (recordings - 2) on, a series' own over-dispersion is used when it exceeds the
#: fleet's (fewer: its chi^2 says too little)
MIN_OWN_DOF = 3
#: a series whose own straight-line chi^2 has a p-value below this is not pooled (a step, not scatter)
POOL_EXCLUDE_P = 1e-4
USABLE_STATUS = ("ok", "warning")


@dataclass
class Point:
    """One recording of a series."""

    start_time: str
    t_days: float
    value: float
    sd: float
    recording: str
    status: str = "ok"
    issues: str = ""
    supported: bool = True      #: the change passes diagnose's finding rule (rows without the field: True)
    support: str = ""

    def brief(self) -> dict[str, Any]:
        return {"start_time": self.start_time, "value": self.value, "sd": self.sd, "recording": self.recording}


@dataclass
class Options:
    alpha: float = DEFAULT_ALPHA
    k_sigma: float = DEFAULT_K_SIGMA
    tolerance: dict[str, float] = field(default_factory=dict)   #: parameter -> relative tolerance
    default_tolerance: float = DEFAULT_TOLERANCE
    limits: dict[str, float] = field(default_factory=dict)      #: parameter -> limit value (SI)
    reference: str = "nominal"                                  #: "nominal" | "fleet"
    min_change: float = 0.0                                     #: shift test: also this relative change

    def tol(self, parameter: str) -> float:
        return float(self.tolerance.get(parameter, self.default_tolerance))


def parse_assignments(items: list[str] | None, what: str) -> dict[str, float]:
    """``["coulomb_friction=0.05", ...]`` -> dict; a clear error naming the option otherwise."""
    out: dict[str, float] = {}
    for it in items or []:
        name, sep, val = str(it).partition("=")
        try:
            if not sep or not name.strip():
                raise ValueError
            out[name.strip()] = float(val)
        except ValueError:
            raise ValueError(f"{what}: expected PARAMETER=VALUE (SI, e.g. coulomb_friction=0.05), got {it!r}") from None
    return out


# ------------------------------------------------------------------------------------------ statistics

def line_fit(t: np.ndarray, v: np.ndarray, u: np.ndarray) -> dict[str, float]:
    """Weighted straight line (weights 1/u^2): intercept at the weighted mean time, slope, stated se of the
    slope, chi^2 and dof."""
    w = 1.0 / u ** 2
    tw = float(np.sum(w * t) / np.sum(w))
    sxx = float(np.sum(w * (t - tw) ** 2))
    a = float(np.sum(w * v) / np.sum(w))
    b = float(np.sum(w * (t - tw) * (v - a)) / sxx) if sxx > 0 else 0.0
    chi2 = float(np.sum(w * (v - a - b * (t - tw)) ** 2))
    return {"t_w": tw, "a": a, "b": b, "se_b": 1.0 / math.sqrt(sxx) if sxx > 0 else math.inf, "chi2": chi2,
            "dof": len(v) - 2, "se_a": 1.0 / math.sqrt(float(np.sum(w)))}


def overdispersion(series: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> tuple[float, int, int]:
    """(B^2, pooled dof, series pooled) over series (t, v, u) of one parameter (see the module docstring).

    Two steps, so that one step-like series cannot set the scatter of the whole fleet: a robust first
    estimate (median over series of chi^2 / median of chi^2(dof)), then the pooled sum over the series whose
    chi^2 / B0^2 is not beyond the p = 1e-4 tail of chi^2(dof)."""
    from scipy.stats import chi2 as chi2d

    fits = [line_fit(t, v, u) for t, v, u in series if len(v) >= 3]
    fits = [f for f in fits if f["dof"] > 0]
    if not fits:
        return 1.0, 0, 0
    b0 = float(np.median([f["chi2"] / chi2d.median(f["dof"]) for f in fits]))
    tot, dof, used = 0.0, 0, 0
    for f in fits:
        if b0 > 0 and chi2d.sf(f["chi2"] / b0, f["dof"]) < POOL_EXCLUDE_P:
            continue
        tot += f["chi2"]
        dof += f["dof"]
        used += 1
    return (tot / dof if dof else 1.0), dof, used


def drift_test(t: np.ndarray, v: np.ndarray, u: np.ndarray, *, b2: float = 1.0, dof_pool: int = 0,
               alpha: float = DEFAULT_ALPHA) -> dict[str, Any]:
    """The ``drifting`` test of the module docstring for one series (t in days)."""
    from scipy.stats import norm
    from scipy.stats import t as tdist

    n = len(v)
    if n < MIN_DRIFT or np.ptp(t) <= 0:
        return {"tested": False, "alert": False, "reason": f"{n} recording(s); the drift test needs >= {MIN_DRIFT} "
                "at different times"}
    f = line_fit(t, v, u)
    own = f["chi2"] / f["dof"] if f["dof"] >= MIN_OWN_DOF else 0.0
    if own > max(1.0, b2):          # this series scatters more than the fleet's: its own estimate, its own dof
        F, dof, source = math.sqrt(own), f["dof"], "own"
    elif b2 > 1.0 and dof_pool > 0:
        F, dof, source = math.sqrt(b2), dof_pool, "fleet"
    else:
        F, dof, source = 1.0, 0, "stated"
    se = F * f["se_b"]
    stat = f["b"] / se if se > 0 else (math.copysign(math.inf, f["b"]) if f["b"] else 0.0)
    crit = float(tdist.ppf(1 - alpha / 2, dof)) if dof > 0 else float(norm.ppf(1 - alpha / 2))
    return {"tested": True, "alert": bool(abs(stat) > crit), "slope_per_day": f["b"], "slope_se_per_day": se,
            "statistic": stat, "critical": crit, "overdispersion_F": F, "overdispersion_from": source,
            "pooled_dof": dof_pool,
            "chi2": f["chi2"], "dof": f["dof"], "t_w": f["t_w"], "value_at_t_w": f["a"], "n": n}


def project_limit(points: list[Point], drift: dict[str, Any], limit: float, t0: dt.datetime) -> dict[str, Any]:
    """When the fitted line reaches ``limit`` (or the first recording that already passed it)."""
    first_over = None
    direction = 1.0 if limit >= points[0].value else -1.0
    for p in points:
        if direction * (p.value - limit) >= 0:
            first_over = p
            break
    out: dict[str, Any] = {"limit": limit}
    if first_over is not None:
        out.update(reached=True, reached_at=first_over.start_time, recording=first_over.recording)
        return out
    out["reached"] = False
    b, se = drift.get("slope_per_day"), drift.get("slope_se_per_day")
    if not drift.get("tested") or b is None or b * direction <= 0:
        out["projected_date"] = None
        out["note"] = "not approaching the limit" if drift.get("tested") else "needs >= 3 recordings"
        return out

    def when(slope):
        if slope * direction <= 0:
            return None
        days = drift["t_w"] + (limit - drift["value_at_t_w"]) / slope
        return (t0 + dt.timedelta(days=days)).isoformat()

    out["projected_date"] = when(b)
    out["projected_date_early"] = when(b + direction * se)     # faster drift: earlier
    out["projected_date_late"] = when(b - direction * se)      # slower: later (None: may never)
    return out


# ------------------------------------------------------------------------------------------ the fleet

def _series(rows: list[dict]) -> dict[tuple[str, str, str], list[dict]]:
    out: dict[tuple[str, str, str], list[dict]] = {}
    for r in rows:
        if r.get("source") != "tracked" or r.get("status") not in USABLE_STATUS:
            continue
        try:
            v, u = float(r["value"]), float(r["uncertainty"])
        except (TypeError, ValueError, KeyError):
            continue
        if not (math.isfinite(v) and math.isfinite(u) and u > 0):
            continue
        out.setdefault((r["actuator_id"], str(r.get("joint") or ""), r["parameter"]), []).append(r)
    return out


def _fleet_reference(rows_by_key) -> dict[tuple[str, str], tuple[float, float, int]]:
    """(params file, parameter) -> (median of each actuator's first value, unit-to-unit sd, actuators)."""
    firsts: dict[tuple[str, str], list[float]] = {}
    for key, rs in rows_by_key.items():
        r0 = min(rs, key=lambda r: r["start_time"])
        firsts.setdefault((str(r0.get("params_file") or ""), key[2]), []).append(float(r0["value"]))
    out = {}
    for k, vals in firsts.items():
        x = np.array(vals)
        sd = 1.4826 * float(np.median(np.abs(x - np.median(x)))) if len(x) >= 3 else float("nan")
        out[k] = (float(np.median(x)), sd, len(x))
    return out


def evaluate(rows: list[dict], options: Options | None = None) -> dict[str, Any]:
    """Every tracked series of the fleet table tested; ``{"alerts": [...], "series": [...], "pool": {...}}``."""
    opt = options or Options()
    by_key = _series(rows)
    t0 = min((dt.datetime.fromisoformat(r["start_time"]) for rs in by_key.values() for r in rs), default=None)
    pts: dict[tuple, list[Point]] = {}
    for key, rs in by_key.items():
        ps = [Point(r["start_time"], (dt.datetime.fromisoformat(r["start_time"]) - t0).total_seconds() / 86400.0,
                    float(r["value"]), float(r["uncertainty"]), r["recording"], r.get("status", "ok"),
                    str(r.get("data_issues") or ""), _bool(r.get("supported", True)), str(r.get("support") or ""))
              for r in rs]
        pts[key] = sorted(ps, key=lambda p: (p.t_days, p.recording))
    arr = {k: (np.array([p.t_days for p in ps]), np.array([p.value for p in ps]), np.array([p.sd for p in ps]))
           for k, ps in pts.items()}
    pool = {}
    for par in sorted({k[2] for k in pts}):
        b2, dof, used = overdispersion([arr[k] for k in arr if k[2] == par])
        pool[par] = {"B2": b2, "F": math.sqrt(max(1.0, b2)), "dof": dof, "series": used}
    fleet_ref = _fleet_reference(by_key) if opt.reference == "fleet" else {}
    series_out, alerts = [], []
    for key in sorted(pts):
        aid, joint, par = key
        ps = pts[key]
        t, v, u = arr[key]
        rs = by_key[key]
        unit = rs[0].get("unit", "")
        P = pool[par]
        drift = drift_test(t, v, u, b2=P["B2"], dof_pool=P["dof"], alpha=opt.alpha)
        if drift.get("tested"):
            drift["line"] = [[p.start_time, drift["value_at_t_w"] + drift["slope_per_day"] * (p.t_days - drift["t_w"])]
                             for p in (ps[0], ps[-1])]
        # reference and off-nominal, per recording; the verdict on the latest
        if opt.reference == "fleet":
            ref, u_ref, n_ref = fleet_ref.get((str(rs[0].get("params_file") or ""), par), (float("nan"), float("nan"), 0))
            ref_name = f"fleet baseline ({n_ref} actuators)"
            if n_ref < 3:
                ref, ref_name = float("nan"), f"fleet baseline needs >= 3 actuators (has {n_ref})"
        else:
            ref = _float(rs[0].get("nominal"))
            u_ref, ref_name = 0.0, "nominal"
        tol = opt.tol(par)
        off = []
        for p in ps:
            if not math.isfinite(ref):
                off.append(None)
                continue
            comb = math.sqrt((P["F"] * p.sd) ** 2 + (u_ref if math.isfinite(u_ref) else 0.0) ** 2)
            dev = p.value - ref
            z = dev / comb if comb > 0 else math.inf
            beyond = bool(abs(z) > opt.k_sigma and abs(dev) > tol * abs(ref))
            off.append({"z": z, "relative": dev / abs(ref) if ref else math.inf,
                        "off": beyond and p.supported, "beyond_tolerance_and_sigma": beyond,
                        "supported": p.supported, "support": p.support})
        last_off = off[-1] if off and off[-1] else None
        shift = trends.shift_test(t, v, u, alpha=opt.alpha, min_change=opt.min_change) if len(v) >= 8 else \
            {"tested": False, "alert": False, "reason": f"{len(v)} recordings; the shift test needs >= 8"}
        kinds = []
        if last_off and last_off["off"]:
            kinds.append("off_nominal")
        if drift.get("alert"):
            kinds.append("drifting")
        if shift.get("alert"):
            kinds.append("shifted")
        rec: dict[str, Any] = {
            "actuator_id": aid, "joint": joint, "parameter": par, "unit": unit, "effect": rs[0].get("effect", ""),
            "n": len(ps), "first": ps[0].brief(), "last": ps[-1].brief(),
            "recordings": [p.recording for p in ps], "start_times": [p.start_time for p in ps],
            "reference": ref, "reference_sd": u_ref, "reference_kind": ref_name, "tolerance": tol,
            "k_sigma": opt.k_sigma, "alpha": opt.alpha,
            "off_nominal": {"latest": last_off, "recordings_off": [ps[i].start_time for i, o in enumerate(off)
                                                                  if o and o["off"]],
                            "z": [o["z"] if o else None for o in off]},
            "drift": drift, "shift": {k: v_ for k, v_ in shift.items() if k != "alert"} | {"alert": shift.get("alert", False)},
            "rate_per_day": drift.get("slope_per_day"), "rate_se_per_day": drift.get("slope_se_per_day"),
            "data_issues": sorted({p.issues for p in ps if p.issues}),
            "kinds": kinds, "alert": bool(kinds),
        }
        if par in opt.limits and t0 is not None:
            rec["limit"] = project_limit(ps, drift, opt.limits[par], t0)
        rec["message"] = message(rec) if kinds else ""
        series_out.append(rec)
        if kinds:
            alerts.append(rec)
    return {"alerts": alerts, "series": series_out, "pool": pool, "options": asdict(opt)}


def _bool(x) -> bool:
    """A ``supported`` cell: a bool, or its text from a CSV table (empty: no evidence either way -> True)."""
    if isinstance(x, str):
        return x.strip().lower() not in ("false", "0", "no")
    return True if x is None else bool(x)


def _float(x) -> float:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return float("nan")
    return x


def _g(x, d=4) -> str:
    return f"{x:.{d}g}" if isinstance(x, (int, float)) and math.isfinite(x) else "-"


def message(rec: dict[str, Any]) -> str:
    """One plain line a maintenance engineer can act on."""
    f, l_, u = rec["first"], rec["last"], rec["unit"]
    who = rec["actuator_id"] + (f" [{rec['joint']}]" if rec["joint"] and not rec["actuator_id"].endswith(rec["joint"]) else "")
    parts = [f"{who}: {rec['parameter']} {_g(f['value'])} ± {_g(f['sd'], 2)} ({f['start_time'][:10]}) -> "
             f"{_g(l_['value'])} ± {_g(l_['sd'], 2)} {u} ({l_['start_time'][:10]}, {rec['n']} recordings)"]
    if "off_nominal" in rec["kinds"]:
        o = rec["off_nominal"]["latest"]
        parts.append(f"OFF NOMINAL: {100 * o['relative']:+.0f} % of the {rec['reference_kind']} {_g(rec['reference'])} "
                     f"({abs(o['z']):.0f} combined sd; tolerance {100 * rec['tolerance']:.0f} %)")
    d = rec["drift"]
    if "drifting" in rec["kinds"]:
        parts.append(f"DRIFTING: {_g(d['slope_per_day'], 3)} ± {_g(d['slope_se_per_day'], 2)} {u}/day "
                     f"(|t| = {abs(d['statistic']):.1f} > {d['critical']:.2f}, false-alarm rate {rec['alpha']:g})")
    if "shifted" in rec["kinds"]:
        s = rec["shift"]
        parts.append(f"SHIFTED: median {_g(s['baseline_median'])} -> {_g(s['recent_median'])} "
                     f"(z = {s['z']:.1f} > {s['z_critical']:.2f})")
    lim = rec.get("limit")
    if lim:
        if lim.get("reached"):
            parts.append(f"limit {_g(lim['limit'])} {u} reached on {lim['reached_at'][:10]}")
        elif lim.get("projected_date"):
            parts.append(f"limit {_g(lim['limit'])} {u} projected for {lim['projected_date'][:10]}")
    return "; ".join(parts)
