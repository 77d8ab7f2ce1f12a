"""Diagnose every recording x joint of a fleet on Dask and collect one table.

:func:`process_file` is the unit of work (one file, all its joints; never raises: a failure becomes a
record). :func:`run` maps it over the files on a ``distributed`` cluster -- a ``LocalCluster`` of worker
PROCESSES on this machine by default (one thread each, scheduler and dashboard bound to 127.0.0.1), or an
existing scheduler (``tcp://host:8786``) -- with a progress bar, and returns the rows and failures.

Row schema (one row per recording x joint x parameter; :data:`COLUMNS`):

``recording`` path, ``joint`` (empty for single-joint files), ``actuator_id``, ``start_time`` (ISO 8601,
UTC), ``start_time_source``, ``source`` (``tracked``: the health estimator of :mod:`.health`, every
recording; ``finding``: a parameter of an effect ``diagnose`` accepted), ``effect``, ``parameter``,
``value``, ``uncertainty`` (1 sigma), ``unit``, ``nominal``, ``heldout_before``, ``heldout_after``,
``heldout_metric``, ``accepted`` (``diagnose`` accepted this effect in this recording), ``diagnosis`` (what
``diagnose`` said about this parameter's effect in this recording: ``accepted: value +- sd``, ``not found: why``
(tested, no evidence), a verdict such as ``not_identifiable: why``; empty when it did not test it), ``diagnose_value``,
``diagnose_uncertainty`` (the value +- sd ``diagnose`` fitted for this parameter when it accepted it), ``supported``
(the change from nominal passes the rule a ``diagnose`` finding must pass: ``diagnose``'s own verdict on this effect
in this recording where it ran and tested it, else the same gate and significance judge on the tracked fit,
:func:`.health.support`; an off-nominal alert needs it), ``support`` (that rule's verdict in words), ``status`` (``ok``; ``warning``: the value
stands but the recording has a data issue of :data:`SERIOUS_ISSUES`; ``not_checkable``, ``not_identifiable``,
``failed``), ``reason``, ``data_issues`` (every data issue of the recording, ``kind channel: detail``, also
an unfinalized MCAP), ``profile`` (the input profile that read the file, given or auto-detected),
``params_file``. Exactly one row per recording x joint x parameter: a parameter that is both tracked and a
parameter of an accepted finding is ONE ``tracked`` row (the finding in ``diagnosis``). A log with torque and motion but no current is diagnosed by
the torque balance (:mod:`bldc_actuator.diagnosis.torque_balance`); its rows are ``finding`` rows.
"""

from __future__ import annotations

import math
import os
import sys
import time
import traceback
import uuid
from dataclasses import dataclass, field
from typing import Any

COLUMNS = ("recording", "joint", "actuator_id", "start_time", "start_time_source", "source", "effect",
           "parameter", "value", "uncertainty", "unit", "nominal", "heldout_before", "heldout_after",
           "heldout_metric", "accepted", "diagnosis", "diagnose_value", "diagnose_uncertainty", "supported", "support", "status", "reason", "data_issues", "profile",
           "params_file")

#: DataIssue kinds that make a recording's values less trustworthy: its rows get status ``warning``
#: (``constant``: a fixed bus voltage or a joint at rest is listed in ``data_issues`` but is no warning)
SERIOUS_ISSUES = ("outlier", "gap", "duplicate_time", "non_monotonic_time", "unit_suspect", "nan", "clipped",
                  "unfinalized")

#: environment for worker processes: single-threaded BLAS (the fits are small; threads only contend),
#: ROS discovery kept on this host
WORKER_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "MPLBACKEND": "Agg"}


@dataclass
class Job:
    """Everything a worker needs for one file (plain data: it travels to other machines)."""

    path: str
    root: str
    params_file: str | None = None
    params_map: list = field(default_factory=list)
    profile: str | None = None
    mapping_file: str | None = None
    diagnose: bool = True           #: also run the full diagnosis (findings rows); tracked rows always
    holdout: float = 0.3


def _f(x) -> float:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return float("nan")
    return x


def _base_row(job: Job, joint, aid: str, start: str, start_src: str, params_file: str | None) -> dict[str, Any]:
    return {"recording": job.path, "joint": "" if joint is None else str(joint), "actuator_id": aid,
            "start_time": start, "start_time_source": start_src, "profile": job.profile or "",
            "params_file": params_file or ""}


def _failure(job: Job, joint, stage: str, exc: BaseException) -> dict[str, Any]:
    msg = f"{type(exc).__name__}: {exc}"
    return {"recording": job.path, "joint": "" if joint is None else str(joint), "stage": stage, "error": msg,
            "traceback": "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))[-2000:]}


def process_file(job: Job) -> dict[str, Any]:
    """Diagnose every joint of one file. Returns ``{"rows": [...], "failures": [...], "seconds": s,
    "joints": n}``; never raises."""
    for k, v in WORKER_ENV.items():
        os.environ.setdefault(k, v)
    t0 = time.perf_counter()
    rows: list[dict] = []
    failures: list[dict] = []
    try:
        from ..diagnosis.io.loaders import Mapping
        from . import source

        mapping = Mapping.from_yaml(job.mapping_file) if job.mapping_file else None
        joint_list = source.joints(job.path, profile=job.profile)
    except Exception as exc:  # noqa: BLE001 - reported, the run goes on
        failures.append(_failure(job, None, "open", exc))
        return {"rows": rows, "failures": failures, "seconds": time.perf_counter() - t0, "joints": 0}
    for joint in joint_list:
        try:
            with _single_threaded_blas():
                r, f = _process_joint(job, joint, mapping)
            rows += r
            failures += f
        except Exception as exc:  # noqa: BLE001
            failures.append(_failure(job, joint, "load-clean-prepare", exc))
    return {"rows": rows, "failures": failures, "seconds": time.perf_counter() - t0, "joints": len(joint_list)}


def _single_threaded_blas():
    """OpenBLAS single-threaded around the fits, also on a remote worker whose BLAS was loaded before
    ``OPENBLAS_NUM_THREADS`` could be set (the diagnosis' own context manager; a no-op if it is gone)."""
    import contextlib

    try:
        from ..diagnosis.threads import SingleThreadedBLAS as _SingleThreadedBLAS
    except ImportError:
        return contextlib.nullcontext()
    return _SingleThreadedBLAS()


def _params_for(job: Job, path_id: str):
    from ..params import load_yaml
    from .discover import params_for

    pf = params_for(job.params_map, path_id, job.path) if job.params_map else None
    pf = pf or job.params_file
    return (load_yaml(pf), pf) if pf else (None, None)


def _process_joint(job: Job, joint, mapping) -> tuple[list[dict], list[dict]]:
    """Rows of one joint and the failures of its stages (a failing stage keeps the other's rows)."""
    from ..diagnosis.io.cleaning import clean
    from . import source
    from .health import track

    path_id = source.actuator_id(None, job.path, job.root, joint)
    params, pf = _params_for(job, path_id)
    raw = source.load(job.path, joint=joint, profile=job.profile, mapping=mapping, params=params)
    if params is None:
        params = raw.meta.get("params_from_recording")
        pf = "(parameters recorded in the file)" if params is not None else None
        if params is None:
            raise ValueError(f"{job.path}: no nominal parameters: give --params FILE or --params-map FILE "
                             "(this recording carries none)")
    aid = source.actuator_id(raw, job.path, job.root, joint)
    if job.params_map and aid != path_id:
        p2, pf2 = _params_for(job, aid)
        if p2 is not None and pf2 != pf:
            params, pf = p2, pf2
    when, when_src = source.start_time(raw, job.path)
    sig = clean(raw, params=params)
    base = _base_row(job, joint, aid, when.isoformat(), when_src, pf)
    base["profile"] = raw.meta.get("profile") or job.profile or ""      # the input profile that read it
    issues = data_issues(sig)
    base["data_issues"] = " | ".join(f"{k} {c}: {d}" for k, c, d in issues)
    serious = sorted({k for k, _, _ in issues if k in SERIOUS_ISSUES})
    from ..diagnosis import torque_balance
    from ..diagnosis.pipeline import TORQUE_BALANCE, route

    # the route is the diagnosis' own choice (pipeline.route); fleet keeps its row builder for the torque balance
    if route(sig) == TORQUE_BALANCE:
        res = torque_balance.diagnose(sig, params, holdout=job.holdout)
        return _with_issues(_torque_balance_rows(base, res), serious), []
    from .health import prepare

    ctx = prepare(sig, params, holdout=job.holdout)
    failures = []
    tracked, report = [], None
    try:
        tracked = track(sig, params, holdout=job.holdout, ctx=ctx)
    except Exception as exc:  # noqa: BLE001 - the diagnosis may still work
        failures.append(_failure(job, joint, "tracked", exc))
    if job.diagnose:
        try:
            report = _diagnose(sig, params, job.holdout)
        except Exception as exc:  # noqa: BLE001 - the tracked rows stay
            failures.append(_failure(job, joint, "diagnose", exc))
    return _with_issues(_rows(base, tracked, report, params), serious), failures


def _diagnose(sig, params, holdout: float) -> dict:
    """The ONE call into the full diagnosis pipeline (:func:`bldc_actuator.diagnosis.pipeline.diagnose`)."""
    from ..diagnosis.pipeline import DiagnoseOptions, diagnose

    return diagnose(sig, params, options=DiagnoseOptions(holdout=holdout)).to_dict()


def data_issues(sig) -> list[tuple[str, str, str]]:
    """(kind, channel, detail) of every data issue of a loaded, cleaned recording: the DataIssues, and an
    MCAP the writer never finalized (the loader's note; kind ``unfinalized``)."""
    out = [(i.kind, i.channel, f"{i.detail} -> {i.action}" if i.action else i.detail)
           for i in getattr(sig, "issues", [])]
    for note in (getattr(sig, "meta", {}) or {}).get("notes", []):
        if "not finalized" in str(note).lower():
            out.append(("unfinalized", "file", str(note).replace("recording: ", "", 1)))
    return out


def _with_issues(rows: list[dict], serious: list[str]) -> list[dict]:
    if not serious:
        return rows
    for r in rows:
        if r.get("status") == "ok":
            r["status"] = "warning"
            r["reason"] = "; ".join(x for x in (r.get("reason"), "data issue: " + ", ".join(serious)) if x)
    return rows


def _diagnosis_by_effect(report: dict | None) -> dict[str, str]:
    """effect -> what diagnose said about it (accepted / rejected / suspected, not identifiable)."""
    if not report:
        return {}
    out: dict[str, str] = {}
    for r in report.get("rejected", []) or []:
        e = r.get("effect")
        if e and e not in out:
            out[e] = f"{r.get('verdict') or 'not found'}: {r.get('reason') or r.get('form') or ''}".strip(": ")
    for f in report.get("findings", []) or []:
        unc = f.get("uncertainty") or {}
        vals = ", ".join(f"{k} = {_g(v)} ± {_g(unc.get(k))}" for k, v in (f.get("parameters") or {}).items()
                         if isinstance(v, (int, float)) and not isinstance(v, bool))
        out[f["effect"]] = f"accepted: {vals}"
    return out


def _g(x) -> str:
    try:
        return f"{float(x):.4g}"
    except (TypeError, ValueError):
        return "-"


def _rows(base: dict, tracked: list, report: dict | None, params) -> list[dict]:
    """One row per parameter: tracked rows first; a finding's parameter that is tracked folds into it."""
    said = _diagnosis_by_effect(report)
    findings = (report or {}).get("findings", []) or []
    accepted = {f["effect"] for f in findings}
    fitted = {}                     # parameter -> (value, sd) that diagnose accepted
    for f in findings:
        unc = f.get("uncertainty") or {}
        for name, value in (f.get("parameters") or {}).items():
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                fitted.setdefault(name, (_f(value), _f(unc.get(name))))
    rows, names = [], set()
    for t in tracked:
        dv, du = fitted.get(t.parameter, (float("nan"), float("nan")))
        ok, why = supported(t, t.effect in accepted, said.get(t.effect, ""))
        rows.append(dict(base, source="tracked", effect=t.effect, parameter=t.parameter, value=t.value,
                         uncertainty=t.uncertainty, unit=t.unit, nominal=t.nominal, heldout_before=t.heldout_before,
                         heldout_after=t.heldout_after, heldout_metric=t.heldout_metric,
                         accepted=t.effect in accepted, diagnosis=said.get(t.effect, ""), diagnose_value=dv,
                         diagnose_uncertainty=du, supported=ok, support=why, status=t.status, reason=t.reason))
        names.add(t.parameter)
    flat = params.to_flat() if params is not None else {}
    for f in findings:
        ho = f.get("held_out") or {}
        units = f.get("units") or {}
        unc = f.get("uncertainty") or {}
        fields = f.get("fields") or {}
        for name, value in (f.get("parameters") or {}).items():
            if name in names or not isinstance(value, (int, float)) or isinstance(value, bool):
                continue
            names.add(name)
            nominal = _f(flat.get(fields.get(name))) if fields.get(name) in flat else float("nan")
            rows.append(dict(base, source="finding", effect=f["effect"], parameter=name, value=_f(value),
                             uncertainty=_f(unc.get(name)), unit=str(units.get(name, "")), nominal=nominal,
                             heldout_before=_f(ho.get("before")), heldout_after=_f(ho.get("after")),
                             heldout_metric=str(ho.get("metric", "")) + (f" [{ho['unit']}]" if ho.get("unit") else ""),
                             accepted=True, diagnosis=said.get(f["effect"], ""), diagnose_value=_f(value),
                             diagnose_uncertainty=_f(unc.get(name)), supported=True, support="accepted by diagnose",
                             status="ok",
                             reason="" if fields.get(name) in flat else "no nominal field for this parameter"))
    return rows


def supported(t, accepted: bool, said: str) -> tuple[bool, str]:
    """ONE finding rule for a tracked change: where ``diagnose`` ran on this recording and tested this effect
    (``said`` non-empty), its verdict (accepted: supported; anything else -- not found, not identifiable, not
    confirmed in simulation -- not); otherwise the tracked fit's own verdict from the same gate and judges
    (:func:`.health.support`)."""
    if accepted:
        return True, "accepted by diagnose: " + said.removeprefix("accepted: ")
    if said:
        return False, "diagnose: " + said
    return bool(t.supported), t.support


def _torque_balance_rows(base: dict, res) -> list[dict]:
    rows, seen = [], set()
    for f, accepted in [(f, True) for f in res.findings] + [(f, False) for f in res.rejected if f.parameters]:
        ho = f.held_out
        for name, value in f.parameters.items():
            if name in seen:          # one row per parameter: an accepted value wins over a rejected form
                continue
            seen.add(name)
            rows.append(dict(base, source="finding", effect=f.effect, parameter=name, value=_f(value),
                             uncertainty=_f(f.uncertainty.get(name)), unit=str(f.units.get(name, "")),
                             nominal=float("nan"), heldout_before=_f(ho.get("before")),
                             heldout_after=_f(ho.get("after")), heldout_metric="torque_rms [N*m]",
                             accepted=accepted, supported=accepted,
                             support="accepted by the torque balance" if accepted else "not accepted by the torque balance",
                             status="ok" if accepted else "not_identifiable",
                             reason=f.reason or "torque balance (no motor current)"))
    if not rows:
        rows.append(dict(base, source="finding", effect="", parameter="", value=float("nan"),
                         uncertainty=float("nan"), unit="", nominal=float("nan"), heldout_before=float("nan"),
                         heldout_after=float("nan"), heldout_metric="torque_rms [N*m]", accepted=False,
                         status="not_checkable", reason="torque balance: " + "; ".join(res.notes[-2:])))
    return rows


# ------------------------------------------------------------------------------------------ Dask

def local_cluster(workers: int, threads: int = 1):
    """A cluster of worker processes on this machine: scheduler and its HTTP server (dashboard when bokeh is
    installed) on 127.0.0.1 only, at a free port (no clash with another cluster's 8787)."""
    from distributed import LocalCluster

    for k, v in WORKER_ENV.items():      # inherited by the worker processes
        os.environ.setdefault(k, v)
    return LocalCluster(n_workers=workers, threads_per_worker=threads, processes=True, host="127.0.0.1",
                        dashboard_address="127.0.0.1:0", silence_logs=40)


@dataclass
class RunResult:
    rows: list[dict]
    failures: list[dict]
    files: int
    joints: int
    seconds: float
    workers: int
    scheduler: str


def run(jobs: list[Job], *, scheduler: str | None = None, workers: int | None = None, progress: bool = True,
        client=None) -> RunResult:
    """Process ``jobs`` on Dask (see the module docstring). ``client``: an existing ``distributed.Client``."""
    from distributed import Client, as_completed

    t0 = time.perf_counter()
    cluster = None
    own_client = client is None
    if client is None:
        if scheduler:
            client = Client(scheduler, timeout="30s")
        else:
            n = workers or max(1, min(os.cpu_count() or 1, len(jobs)))
            cluster = local_cluster(n)
            client = Client(cluster)
    try:
        n_workers = len(client.scheduler_info().get("workers", {}))
        where = scheduler or getattr(client.scheduler, "address", "local")
        tag = uuid.uuid4().hex[:8]
        futures = client.map(process_file, jobs, pure=False, key=[f"fleet-{tag}-{i}" for i in range(len(jobs))])
        index = {f.key: j for f, j in zip(futures, jobs)}
        bar = _bar(len(jobs), progress)
        rows, failures, joints = [], [], 0
        for fut in as_completed(futures):
            job = index[fut.key]
            try:
                res = fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker died or the task could not run
                failures.append(_failure(job, None, "worker", exc))
                res = None
            if res is not None:
                rows += res["rows"]
                failures += res["failures"]
                joints += res["joints"]
            bar.update(1)
            if failures:
                bar.set_postfix(failed=len({f["recording"] for f in failures}))
            fut.release()
        bar.close()
    finally:
        shutdown(client if own_client else None, cluster)
    return RunResult(rows, failures, len(jobs), joints, time.perf_counter() - t0, n_workers, str(where))


#: seconds each of client.close / cluster.close may take before the shutdown goes on without it
CLOSE_TIMEOUT_S = 30.0


def shutdown(client, cluster, timeout: float = CLOSE_TIMEOUT_S) -> list[int]:
    """Close ``client`` and the local ``cluster`` (either may be None) within ``timeout`` each, then end every
    process of the cluster's workers that is still alive (terminate, then kill after 5 s). A close that times
    out or raises (a loaded machine, a worker stuck in a task) no longer leaves live worker processes behind for
    the interpreter's exit to wait on. Returns the pids that had to be ended."""
    import psutil

    left = _cluster_processes(cluster, psutil)
    for what in (client, cluster):
        if what is None:
            continue
        try:
            what.close(timeout=timeout)
        except Exception as exc:  # noqa: BLE001 - go on with the rest of the shutdown
            print(f"fleet: closing the Dask {type(what).__name__} failed ({type(exc).__name__}: {exc}); "
                  "ending its processes", file=sys.stderr)
    left = [c for c in left if _alive(c, psutil)]
    for c in left:
        with _quiet(psutil):
            c.terminate()
    _, alive = psutil.wait_procs(left, timeout=5.0)
    for c in alive:
        with _quiet(psutil):
            c.kill()
    psutil.wait_procs(alive, timeout=5.0)
    return [c.pid for c in left]


def _cluster_processes(cluster, psutil) -> list:
    """The processes of a local cluster's workers (each worker's pid, ``Nanny.pid``, and its children), taken
    before it is closed; none for a remote scheduler (its processes are not this command's)."""
    out = []
    for w in list(getattr(cluster, "workers", {}).values()) if cluster is not None else []:
        pid = getattr(w, "pid", None)
        if not pid:
            continue
        with _quiet(psutil):
            p = psutil.Process(pid)
            out += [p, *p.children(recursive=True)]
    return out


def _alive(p, psutil) -> bool:
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except (psutil.NoSuchProcess, psutil.AccessDenied):
        return False


def _quiet(psutil):
    import contextlib

    return contextlib.suppress(psutil.NoSuchProcess, psutil.AccessDenied)


def _bar(total: int, enabled: bool):
    try:
        from tqdm import tqdm

        return tqdm(total=total, unit="file", desc="fleet", disable=not enabled, file=sys.stderr,
                    dynamic_ncols=True)
    except ImportError:   # pragma: no cover - tqdm is a dependency
        class _Quiet:
            def update(self, n): pass
            def set_postfix(self, **kw): pass
            def close(self): pass
        return _Quiet()


def is_finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False
