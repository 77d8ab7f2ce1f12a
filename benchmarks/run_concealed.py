#!/usr/bin/env python3
"""Concealed-effect benchmark of ``bldc-actuator diagnose`` (issue 4, "Proof"): one command.

    .venv/bin/python benchmarks/run_concealed.py            # all cases
    .venv/bin/python benchmarks/run_concealed.py --quick    # the small subset the test runs
    .venv/bin/python benchmarks/run_concealed.py --cases coulomb null_mixed --regenerate
    .venv-peers/bin/python benchmarks/run_concealed.py --set thirdparty   # truth: motulator (peers venv)
    .venv-peers/bin/python benchmarks/run_concealed.py --set gem          # truth: gym-electric-motor (peers venv)
    PYTHONPATH=. .venv-peers/bin/python benchmarks/run_concealed.py --set fresh   # truth: own ODEs, not the kernel
                                                                          # (seed offset 0 published; >= 1 held back)

1. generates every case with the independent truth simulator (``benchmarks/concealed``): training and
   held-out CSV, the nominal parameter file, the truth JSON — cached under ``--data`` and regenerated only
   when the generator's sources change (``--regenerate`` forces it);
2. runs ``bldc-actuator diagnose`` on each case (the CLI, as a user would, in a subprocess; wall time
   includes interpreter start-up);
3. scores each report against the truth, prints the table and writes ``<out>/concealed.md`` and
   ``<out>/concealed.json``.

Exit status: 0 when every case ran; 1 when a diagnose run failed; the false-positive count is in the
table and JSON (the benchmark reports, it does not gate).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.concealed import cases as C  # noqa: E402
from benchmarks.concealed import scoring  # noqa: E402

GENERATOR_SOURCES = ("truth.py", "truth_kernel.c", "excitation.py", "cases.py", "oracle.py")


def generator_hash(case_set: str = "builtin") -> str:
    """The builtin set: one stamp of its generator's sources (every case regenerates when one changes). The
    third-party sets: the stamp of their simulation module and library versions; each case's recordings carry
    their own key on top of it (``case_kit.recording_key``: that code and the case's recording spec)."""
    if case_set == "thirdparty":
        from benchmarks.concealed import thirdparty

        return thirdparty.code_stamp()
    if case_set == "gem":
        from benchmarks.concealed import gem_cases

        return gem_cases.code_stamp()
    if case_set == "fresh":
        from benchmarks.concealed import fresh_cases

        return fresh_cases.code_stamp()
    h = hashlib.sha256()
    for name in GENERATOR_SOURCES:
        h.update((REPO / "benchmarks" / "concealed" / name).read_bytes())
    import numpy

    h.update(numpy.__version__.encode())
    return h.hexdigest()[:16]


def ensure_data(cases, data_dir: Path, regenerate: bool, log, case_set: str = "builtin") -> dict[str, dict]:
    """Generate the cases whose files are missing or stale; return their truth dicts."""
    if case_set in ("thirdparty", "gem", "fresh"):
        # per-case recording keys; the truth and nominal files are rewritten from the cases on every run
        if case_set == "thirdparty":
            from benchmarks.concealed import thirdparty as S
        elif case_set == "fresh":
            from benchmarks.concealed import fresh_cases as S
        else:
            from benchmarks.concealed import gem_cases as S
        t0 = time.perf_counter()
        truths, made = S.ensure(cases, data_dir, regenerate=regenerate, progress=lambda m: log("  " + m))
        if made:
            log(f"  generated {len(made)} case(s) in {time.perf_counter() - t0:.1f} s (wall); simulation time per "
                f"case (training + held-out, summed over the workers):")
            for name in made:
                t = truths[name]
                log(f"    {name:28s} {t.get('generation_seconds') or float('nan'):6.1f} s  "
                    f"({t['train']['duration_s']:.0f} s + {t['heldout']['duration_s']:.0f} s recorded, "
                    f"log {t['log'].get('rate', 1000.0):g} Hz)")
        log(f"recordings in {data_dir}: {len(cases) - len(made)} cached, {len(made)} simulated (code "
            f"{generator_hash(case_set)}); truth and nominal files rewritten from the case definitions")
        return truths
    stamp = generator_hash(case_set)
    todo = []
    for case in cases:
        d = data_dir / case.name
        ok = all((d / f).exists() for f in ("train.csv", "heldout.csv", "params.yaml", "truth.json"))
        if ok and not regenerate and (d / ".generator").exists() and (d / ".generator").read_text() == stamp:
            continue
        todo.append(case)
    if todo:
        log(f"generating {len(todo)} case(s) with the truth simulator -> {data_dir}")
        t0 = time.perf_counter()
        made = C.generate(todo, data_dir, progress=lambda m: log("  " + m))
        for case in todo:
            (data_dir / case.name / ".generator").write_text(stamp)
        log(f"  generated in {time.perf_counter() - t0:.1f} s (wall); simulation time per case, summed over its "
            f"recordings (training, held-out, twins):")
        for case in todo:
            t = made[case.name]
            log(f"    {case.name:28s} {t.get('generation_seconds', float('nan')):6.1f} s  "
                f"({t['train']['duration_s']:.0f} s + {t['heldout']['duration_s']:.0f} s recorded, "
                f"log {t['log'].get('rate', 1000.0):g} Hz)")
    else:
        log(f"using cached recordings in {data_dir} (generator {stamp})")
    return {c.name: scoring.load_json(data_dir / c.name / "truth.json") for c in cases}


def _diagnose_cli() -> list[str]:
    return [sys.executable, "-m", "bldc_actuator.cli", "diagnose"]


def heldout_option() -> str | None:
    """The diagnose CLI's option for a held-out recording, if it has one (read from its --help)."""
    try:
        out = subprocess.run(_diagnose_cli() + ["--help"], capture_output=True, text=True, timeout=120,
                             env=_env()).stdout
    except (OSError, subprocess.TimeoutExpired):
        return None
    for opt in ("--holdout-file", "--held-out-file", "--heldout-file", "--held-out", "--heldout", "--validation"):
        if opt in out:
            return opt
    return None


def _env() -> dict:
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", MPLBACKEND="Agg")
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def run_case(case_dir: Path, out_dir: Path, held_opt: str | None, timeout: float, extra: list[str]) -> tuple:
    """Run diagnose on one case; return (report dict or None, wall time, error text or None)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    report_json = out_dir / "report.json"
    report_json.unlink(missing_ok=True)
    cmd = _diagnose_cli() + [str(case_dir / "train.csv"), "--params", str(case_dir / "params.yaml"),
                             "--json", str(report_json), "--report", str(out_dir / "report")]
    if held_opt:
        cmd += [held_opt, str(case_dir / "heldout.csv")]
    cmd += extra
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=_env())
    except subprocess.TimeoutExpired:
        return None, time.perf_counter() - t0, f"timeout after {timeout:.0f} s"
    wall = time.perf_counter() - t0
    (out_dir / "diagnose.log").write_text(f"$ {' '.join(cmd)}\n--- stdout ---\n{proc.stdout}\n--- stderr ---\n{proc.stderr}")
    if not report_json.exists():
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        return None, wall, f"exit {proc.returncode}, no JSON report: {' | '.join(tail)}"
    try:
        return scoring.load_json(report_json), wall, None
    except json.JSONDecodeError as exc:
        return None, wall, f"unreadable JSON report: {exc}"


def concealment_table(cases, truths) -> str:
    """Effect RMS vs noise RMS per channel, from the noise-free and effect-free twins."""
    lines = [f"{'case':28s} {'channel':9s} {'effect RMS':>11s} {'noise RMS':>10s} {'SNR':>5s}  "
             f"{'current: effect / noise A':>25s}  {'voltage_q: effect / noise V':>27s}  oracle (form known): estimate, error"]
    for case in cases:
        t = truths[case.name]
        c = t["concealment"]
        unit = "A" if c["channel"] == "current" else "V"
        o = t.get("oracle") or {}
        ora = (f"{o['parameter']} {o['estimate']:.4g} (true {o['true']:.4g}, {100 * o['rel_error']:.0f} %)"
               if o.get("estimate") is not None else "–")
        lines.append(f"{case.name:28s} {c['channel']:9s} {c['effect_rms']:9.4f} {unit} {c['noise_rms']:8.4f} {unit} "
                     f"{c['snr']:5.2f}  {c['current']['effect_rms']:11.4f} / {c['current']['noise_rms']:.4f}  "
                     f"{c['voltage_q']['effect_rms']:13.4f} / {c['voltage_q']['noise_rms']:.4f}  {ora}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--set", dest="case_set", choices=("builtin", "thirdparty", "gem", "fresh"), default="builtin",
                    help="builtin: the project's own truth simulator (benchmarks/concealed/truth.py); thirdparty: "
                         "motulator's PMSM drive as the truth (benchmarks/concealed/thirdparty.py; run in the peers "
                         "venv, bash benchmarks/peers/setup.sh); gem: gym-electric-motor's PMSM as the truth under a "
                         "drive written outside it (benchmarks/concealed/gem_cases.py; peers venv); fresh: issue #24's fresh set, "
                         "plant and drive ODEs written without the kernel (benchmarks/concealed/fresh_cases.py): "
                         "seed offset 0 is the published baseline, seed offsets >= 1 are HELD BACK (never tune on "
                         "them; run them only at the end)")
    ap.add_argument("--cases", nargs="*", help="case names (default: all)")
    ap.add_argument("--quick", action="store_true", help="only the fast subset (also run by test/test_concealed.py)")
    ap.add_argument("--seed-offset", type=int, default=0,
                    help="fresh noise and excitation seeds for every case (0 = the published ones); a check that "
                         "the diagnoser was not tuned to one draw (--set fresh: offsets >= 1 are held back)")
    ap.add_argument("--data", type=Path, default=None,
                    help="where generated recordings are cached (default: benchmarks/.cache/concealed[-seedsK])")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results",
                    help="where concealed.md / concealed.json go (default: benchmarks/results)")
    ap.add_argument("--runs", type=Path, default=None,
                    help="where diagnose writes each case's report (default: <data>/../concealed_runs)")
    ap.add_argument("--regenerate", action="store_true", help="regenerate recordings even if cached")
    ap.add_argument("--generate-only", action="store_true", help="generate and print the concealment table only")
    ap.add_argument("--timeout", type=float, default=300.0, help="per-case diagnose timeout [s]")
    ap.add_argument("--diagnose-arg", action="append", default=[], help="extra argument passed to diagnose")
    ap.add_argument("--update-doc", type=Path, nargs="?", const=REPO / "docs" / "benchmark.md",
                    help="also replace the results block of docs/benchmark.md (between its markers)")
    args = ap.parse_args(argv)

    def log(msg):
        print(msg, flush=True)

    if args.case_set == "thirdparty":
        from benchmarks.concealed import thirdparty as S
    elif args.case_set == "gem":
        from benchmarks.concealed import gem_cases as S
    elif args.case_set == "fresh":
        from benchmarks.concealed import fresh_cases as S
    else:
        S = C
    cases = list(S.CASES)
    if args.quick:
        cases = [c for c in cases if getattr(c, "quick", False)]
    if args.cases:
        cases = [S.get_case(n) for n in args.cases]
    cases = [S.reseeded(c, args.seed_offset) for c in cases]
    set_stem = {"builtin": "concealed", "thirdparty": "thirdparty", "gem": "gem", "fresh": "fresh"}[args.case_set]
    if args.data is None:
        args.data = REPO / "benchmarks" / ".cache" / (set_stem + (f"-seeds{args.seed_offset}" if args.seed_offset else ""))
    t_start = time.perf_counter()
    truths = ensure_data(cases, args.data, args.regenerate, log, args.case_set)
    log("\nconcealment (training recording; effect = full − effect-free twin, noise = full − ideal-sensor twin):")
    log(concealment_table(cases, truths))
    if args.generate_only:
        return 0

    held = heldout_option()
    log(f"\ndiagnose: {' '.join(_diagnose_cli()[1:])} (held-out recording "
        f"{'passed with ' + held if held else 'not passed: the CLI has no held-out option, it splits'})")
    from bldc_actuator.params import ParameterWarning, load_yaml

    scores = []
    failed = 0
    run_dir = args.runs or args.data.parent / (args.data.name + "_runs")
    for k, case in enumerate(cases, start=1):
        log(f"[{k}/{len(cases)}] {case.name}: hidden {', '.join(case.effects) or 'nothing'} ...")
        report, wall, err = run_case(args.data / case.name, run_dir / case.name, held, args.timeout,
                                     [*getattr(S, "DIAGNOSE_ARGS", ()), *getattr(case, "diagnose_args", ()),
                                      *args.diagnose_arg])
        with warnings.catch_warnings():     # the case's diagnose run has printed its own parameter warnings
            warnings.simplefilter("ignore", ParameterWarning)
            nominal = load_yaml(args.data / case.name / "params.yaml").to_flat()
        s = scoring.score_case(truths[case.name], report, nominal, wall_time=wall, error=err)
        scores.append(s)
        failed += err is not None
        log(f"      named: {', '.join(s.found) or 'nothing'}; "
            f"{'ERROR ' + err if err else 'ok' if s.ok else 'missed ' + str(s.missed) + ' extra ' + str(s.false_positives)}"
            f" ({wall:.1f} s)")
    summary = scoring.summarise(scores)
    table = scoring.text_table(scores, truths)
    log("\n" + table + "\n")
    log(scoring.summary_text(summary))
    log(f"\ntotal {time.perf_counter() - t_start:.0f} s")

    args.out.mkdir(parents=True, exist_ok=True)
    stem = set_stem + (f"-seeds{args.seed_offset}" if args.seed_offset else "") + ("-quick" if args.quick else "")
    meta = {"generator": generator_hash(args.case_set), "set": args.case_set,
            "python": platform.python_version(), "machine": platform.machine(),
            "cpus": os.cpu_count(), "date": time.strftime("%Y-%m-%d %H:%M:%S"),
            "git": _git_head(), "heldout_option": held, "quick": args.quick, "seed_offset": args.seed_offset}
    (args.out / f"{stem}.json").write_text(json.dumps(
        {"meta": meta, "summary": summary, "cases": [s.to_dict() for s in scores],
         "truth": {n: {k: v for k, v in t.items() if k != "ranges"} for n, t in truths.items()}},
        indent=2, default=float) + "\n")
    md = ["# Concealed-effect benchmark: results" + {"thirdparty": " (third-party truth: motulator)",
                                                     "gem": " (third-party truth: gym-electric-motor)",
                                                     "fresh": " (fresh set: own ODE truth, not the kernel)"}.get(
                                                         args.case_set, ""), "",
          f"Generated by `benchmarks/run_concealed.py` ({meta['date']}, git {meta['git']}, generator {meta['generator']}).",
          "Method: docs/benchmark.md.", "", "## Summary", "", "```", scoring.summary_text(summary), "```", "",
          "## Cases", "", scoring.markdown_table(scores, truths), "", "## Concealment", "", "```",
          concealment_table(cases, truths), "```", ""]
    fp = [s for s in scores if s.false_positives]
    if fp:
        md += ["## False positives", ""]
        for s in fp:
            for d in s.false_positive_detail:
                md.append(f"- **{s.case}** named `{d['effect']}`: held-out {d.get('held_out')}; evidence: "
                          f"{json.dumps(d.get('evidence'), default=str)[:400]}")
        md.append("")
    (args.out / f"{stem}.md").write_text("\n".join(md))
    if args.update_doc:
        update_doc(args.update_doc, meta, summary, scores, truths, cases,
                   *{"thirdparty": (TP_BEGIN, TP_END), "gem": (GEM_BEGIN, GEM_END),
                     "fresh": (FRESH_BEGIN, FRESH_END)}.get(args.case_set, (BEGIN, END)))
    log(f"wrote {args.out / (stem + '.md')} and {args.out / (stem + '.json')}")
    return 1 if failed else 0


BEGIN, END = "<!-- concealed-results:begin -->", "<!-- concealed-results:end -->"
TP_BEGIN, TP_END = "<!-- thirdparty-results:begin -->", "<!-- thirdparty-results:end -->"
GEM_BEGIN, GEM_END = "<!-- gem-results:begin -->", "<!-- gem-results:end -->"
FRESH_BEGIN, FRESH_END = "<!-- fresh-results:begin -->", "<!-- fresh-results:end -->"


def update_doc(path: Path, meta, summary, scores, truths, cases, BEGIN=BEGIN, END=END) -> None:
    """Replace the block between the markers of ``path`` with the latest summary, table and concealment."""
    text = path.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{path}: markers {BEGIN} / {END} not found")
    block = "\n".join([BEGIN, "", f"Run of {meta['date']} (git {meta['git']}, generator {meta['generator']}, "
                        f"{meta['cpus']} CPUs{', quick subset' if meta['quick'] else ''}"
                        f"{', seed offset ' + str(meta['seed_offset']) if meta['seed_offset'] else ''}):", "", "```",
                        scoring.summary_text(summary), "```", "", scoring.markdown_table(scores, truths), "",
                        "Concealment (training recordings):", "", "```", concealment_table(cases, truths), "```", "",
                        END])
    head, rest = text.split(BEGIN, 1)
    path.write_text(head + block + rest.split(END, 1)[1])
    print(f"updated {path}")


def _git_head() -> str:
    """Short commit, with ``+uncommitted diagnosis`` when the diagnoser's files differ from it."""
    try:
        head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, timeout=10).stdout.strip() or "?"
        dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "bldc_actuator"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return head + (" +uncommitted bldc_actuator changes" if dirty else "")
    except OSError:
        return "?"


if __name__ == "__main__":
    sys.exit(main())
