"""``bldc-actuator fleet``: diagnose every recording x joint of a fleet, track health parameters over time.

Examples::

    bldc-actuator fleet 'logs/**/*.mcap' --params config/ak80_9.yaml --out fleet_out
    bldc-actuator fleet 'logs/**/*' --params-map params_map.yaml --out fleet_out --workers 2
    bldc-actuator fleet 'logs/**/*.csv' --profile wide_joints --params p.yaml --out o --scheduler tcp://host:8786

Writes ``OUT/fleet.parquet`` and ``OUT/fleet.csv`` (one row per recording x joint x parameter),
``OUT/alerts.json`` (trend alerts, every tested series, failures) and ``OUT/report.html``.
Exit status: 0 done (failed files are reported in the outputs), 1 none of the files could be diagnosed,
2 bad input (an option, a pattern that matches nothing, a parameter file that does not validate).
Without ``--scheduler`` a local Dask cluster of ``--workers`` processes runs on this machine; with it,
the workers of that cluster must have bldc_actuator installed and see the files at the same paths.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("fleet", help="diagnose many recordings on Dask; trend alerts and an HTML report",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("patterns", nargs="+", help="files, directories or quoted glob patterns ('logs/**/*.mcap')")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--params", type=Path, help="nominal parameter YAML for every recording")
    src.add_argument("--params-map", type=Path, help="YAML {PATTERN: PARAMS_FILE}: per actuator id / path glob")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument("--profile", help="input profile NAME or FILE for every file (default: auto-detected)")
    p.add_argument("--map", dest="mapping", type=Path, help="a mapping YAML applied to every file (instead of a profile)")
    p.add_argument("--scheduler", help="address of an existing Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU count)")
    p.add_argument("--alpha", type=float, default=1e-3,
                   help="false-alarm rate of the drift (and shift) test per actuator-parameter series (default 0.001)")
    p.add_argument("--tolerance", action="append", metavar="[PARAMETER=]FRACTION",
                   help="off-nominal alert: relative tolerance, for every parameter (0.1) or one "
                        "(coulomb_friction=0.2); repeatable; default 0.1")
    p.add_argument("--k-sigma", type=float, default=5.0,
                   help="off-nominal alert: also this many combined uncertainties away (default 5)")
    p.add_argument("--reference", choices=("nominal", "fleet"), default="nominal",
                   help="off-nominal against the parameter file (default) or the fleet's own baseline for "
                        "the actuators sharing a parameter file (median of their first recordings)")
    p.add_argument("--limit", action="append", metavar="PARAMETER=VALUE",
                   help="a limit (SI) for a tracked parameter: the projected date it is reached "
                        "(e.g. --limit coulomb_friction=0.05); repeatable")
    p.add_argument("--min-change", type=float, default=0.0,
                   help="shift test: also require this relative change for an alert (e.g. 0.02 = 2 %%)")
    p.add_argument("--tracked-only", action="store_true",
                   help="fit the tracked health parameters only (skip the full diagnosis: faster)")
    p.add_argument("--holdout", type=float, default=0.3, help="held-out fraction of each recording")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=main)


def write_table(rows: list[dict], out: Path) -> None:
    import csv

    import pyarrow as pa
    import pyarrow.parquet as pq

    from .run import COLUMNS

    floats = {"value", "uncertainty", "nominal", "heldout_before", "heldout_after", "diagnose_value",
              "diagnose_uncertainty"}
    rows = dedupe(rows)
    data = {}
    for c in COLUMNS:
        if c in floats:
            data[c] = pa.array([_float(r.get(c)) for r in rows], type=pa.float64())
        elif c in ("accepted", "supported"):
            data[c] = pa.array([bool(r.get(c, False)) for r in rows], type=pa.bool_())
        else:
            data[c] = pa.array([str(r.get(c, "")) for r in rows], type=pa.string())
    pq.write_table(pa.table(data), out / "fleet.parquet")
    with (out / "fleet.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow([_csv(r.get(c, "")) for c in COLUMNS])


def dedupe(rows: list[dict]) -> list[dict]:
    """One row per recording x joint x parameter (the first; failure rows keep theirs)."""
    seen, out = set(), []
    for r in rows:
        key = (r.get("recording"), str(r.get("joint") or ""), r.get("parameter"), r.get("status") == "failed")
        if key in seen:
            continue
        seen.add(key)
        out.append(r)
    return out


def options_from(args):
    """argparse namespace -> :class:`.alerts.Options` (ValueError naming the option on bad input)."""
    from .alerts import Options, parse_assignments

    tol, default = {}, 0.1
    for item in args.tolerance or []:
        if "=" in item:
            tol.update(parse_assignments([item], "--tolerance"))
        else:
            try:
                default = float(item)
            except ValueError:
                raise ValueError(f"--tolerance: expected FRACTION or PARAMETER=FRACTION, got {item!r}") from None
    for k, v in tol.items() | {("(all)", default)}:
        if not 0 <= v < 10:
            raise ValueError(f"--tolerance {k}: expected a relative tolerance 0 <= x < 10 (0.1 = 10 %), got {v}")
    if not args.k_sigma > 0:
        raise ValueError(f"--k-sigma: expected > 0 combined uncertainties, got {args.k_sigma}")
    return Options(alpha=args.alpha, k_sigma=args.k_sigma, tolerance=tol, default_tolerance=default,
                   limits=parse_assignments(args.limit, "--limit"), reference=args.reference,
                   min_change=args.min_change)


def validate_params(files: list[tuple[str, str]]) -> None:
    """Load every nominal parameter file once before any work is sent out: a file that does not validate is
    a ValueError naming the option, the field, its expected range and unit (:class:`..params.ParameterError`),
    instead of a failure per recording on the workers."""
    from ..params import ParameterError, load_yaml

    for what, f in files:
        try:
            load_yaml(f)
        except ParameterError as exc:
            raise ValueError(f"{what}: invalid parameter file: {exc}") from None


#: exit codes: 0 done (some recordings may have failed, reported), 1 nothing could be diagnosed, 2 bad input
EXIT_NOTHING_DIAGNOSED = 1
EXIT_USAGE = 2


def _float(x):
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _csv(x):
    if isinstance(x, float):
        return f"{x:.9g}" if math.isfinite(x) else ""
    return x


def _json_safe(x):
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if hasattr(x, "item"):
        return _json_safe(x.item())
    return x


def main(args) -> int:
    from . import alerts as A
    from . import discover, html
    from .run import Job, run

    try:
        items = discover.expand(args.patterns)
        pmap = discover.load_params_map(args.params_map) if args.params_map else []
        if args.params and not args.params.exists():
            raise ValueError(f"--params {args.params}: no such file")
        validate_params([("--params", str(args.params))] if args.params else
                        [(f"--params-map {args.params_map}: {pat}", f) for pat, f in pmap])
        if args.workers is not None and args.workers < 1:
            raise ValueError(f"--workers: expected >= 1, got {args.workers}")
        if not 0 < args.alpha < 0.5:
            raise ValueError(f"--alpha: expected 0 < alpha < 0.5 (false-alarm rate per series), got {args.alpha}")
        opts = options_from(args)
    except ValueError as exc:
        print(f"bldc-actuator fleet: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if not items:
        print(f"bldc-actuator fleet: no files match {' '.join(args.patterns)}", file=sys.stderr)
        return EXIT_USAGE
    jobs = [Job(i.path, i.root, str(args.params) if args.params else None, pmap, args.profile,
                str(args.mapping) if args.mapping else None, not args.tracked_only, args.holdout) for i in items]
    where = args.scheduler or f"local cluster, {args.workers or 'CPU-count'} worker process(es)"
    print(f"fleet: {len(jobs)} file(s) on {where}", file=sys.stderr)
    try:
        res = run(jobs, scheduler=args.scheduler, workers=args.workers, progress=not args.no_progress)
    except (OSError, TimeoutError) as exc:
        print(f"bldc-actuator fleet: cannot reach the Dask scheduler {args.scheduler or '(local)'}: {exc}",
              file=sys.stderr)
        return EXIT_USAGE
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    rows = sorted(res.rows, key=lambda r: (r["actuator_id"], r["start_time"], r["recording"], str(r.get("joint") or ""),
                                          r["source"], r["parameter"]))
    failed_rows = [{"recording": f["recording"], "joint": f.get("joint", ""), "status": "failed",
                    "reason": f"{f['stage']}: {f['error']}", "source": "", "actuator_id": "", "start_time": ""}
                   for f in res.failures]
    rows = dedupe(rows)
    write_table(rows + failed_rows, out)
    ev = A.evaluate(rows, opts)
    recordings = len({(r["recording"], r["joint"]) for r in rows})
    issues = sorted({(r["recording"], r.get("joint", ""), r.get("data_issues", "")) for r in rows
                     if r.get("data_issues")})
    summary = {"files": res.files, "recordings": recordings, "seconds": res.seconds, "workers": res.workers,
               "input_profiles": {k: len({r["recording"] for r in rows if (r.get("profile") or "") == k})
                                  for k in sorted({r.get("profile") or "" for r in rows})},
               "scheduler": res.scheduler,
               "recordings_per_minute": 60.0 * recordings / res.seconds if res.seconds > 0 else None,
               "recordings_with_data_issues": len(issues)}
    doc = {"summary": summary, "options": ev["options"],
           "tests": {"off_nominal": "latest value vs reference: > tolerance AND > k_sigma combined sd AND the "
                                    "change supported by diagnose's finding rule (row field supported)",
                     "drifting": "weighted (1/sd^2) straight line vs time, slope / se > t quantile at alpha; "
                                 "se inflated by the fleet's pooled over-dispersion of the stated sd",
                     "shifted": ">= 8 recordings: robust z of median(recent) - median(baseline), calibrated "
                                "for alpha", "details": "docs/fleet.md"},
           "overdispersion": ev["pool"], "alerts": ev["alerts"], "series": ev["series"],
           "data_issues": [{"recording": a, "joint": b, "issues": c} for a, b, c in issues],
           "failures": [{k: v for k, v in f.items() if k != "traceback"} for f in res.failures]}
    (out / "alerts.json").write_text(json.dumps(_json_safe(doc), indent=1))
    html.write(out / "report.html", rows, ev, res.failures, summary)
    print(f"fleet: {recordings} recording x joint from {res.files} file(s) in {res.seconds:.1f} s "
          f"({summary['recordings_per_minute'] or 0:.1f} per minute, {res.workers} worker(s)); "
          f"{len(res.failures)} failure(s); {len(issues)} with data issues "
          f"({len({r['recording'] for r in rows if r.get('status') == 'warning'})} with warnings); "
          f"{len(ev['alerts'])} alert(s)")
    by_profile: dict[str, set] = {}
    for r in rows:
        by_profile.setdefault(r.get("profile") or "(own MCAP / canonical CSV)", set()).add(r["recording"])
    print("  input profiles: " + ", ".join(f"{k} x {len(v)}" for k, v in sorted(by_profile.items())))
    for a in ev["alerts"]:
        print(f"  ALERT {a['message']}")
    warned = sorted({(r["recording"], str(r.get("joint") or ""), r.get("reason", "")) for r in rows
                     if r.get("status") == "warning"})
    for rec, joint, why in warned[:20]:
        print(f"  WARNING {rec}{' [' + joint + ']' if joint else ''}: {why[:200]} (see data_issues)")
    if len(warned) > 20:
        print(f"  ... {len(warned) - 20} more recording(s) with warnings: {out / 'report.html'}")
    for f in res.failures:
        print(f"  FAILED {f['recording']}{' [' + str(f['joint']) + ']' if f.get('joint') else ''}: {f['error'][:200]}")
    print(f"wrote {out / 'fleet.parquet'}, {out / 'fleet.csv'}, {out / 'alerts.json'}, {out / 'report.html'}")
    diagnosed = {r["recording"] for r in rows if r.get("status") != "failed"}
    if not diagnosed:
        print(f"bldc-actuator fleet: none of the {res.files} file(s) could be diagnosed ({len(res.failures)} "
              f"failure(s), listed above and in {out / 'alerts.json'})", file=sys.stderr)
        return EXIT_NOTHING_DIAGNOSED
    return 0
