"""What the test suite costs: runs ``bash scripts/test.sh`` (or a subset) with pytest's per-test durations and
prints the total wall time, the CPU time, each pytest pass, the slowest tests with their cost (setup + call +
teardown) and the share of the suite they take.

    .venv/bin/python benchmarks/bench_suite.py                        # the whole scripts/test.sh (both passes)
    .venv/bin/python benchmarks/bench_suite.py test/test_model.py     # a subset (one pass, as test.sh runs it)
    .venv/bin/python benchmarks/bench_suite.py --top 30 -- -n 2       # pytest arguments after --
    .venv/bin/python benchmarks/bench_suite.py --log run1.log         # read a saved pytest --durations=0 output

Wall times depend on what else runs on the machine: the load average before and after is printed with them;
per-test durations and the CPU time are the figures to compare between runs on a shared machine.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: pytest's --durations lines: "12.34s call     test/test_x.py::test_y[case]"
DURATION = re.compile(r"^\s*(\d+(?:\.\d+)?)s (setup|call|teardown)\s+(\S.*?)\s*$")
#: pytest's final summary line: "=== 3 failed, 120 passed, 2 skipped in 123.45s (0:02:03) ==="
SUMMARY = re.compile(r"^=*\s*(.*?) in (\d+(?:\.\d+)?)s\b")
#: scripts/test.sh's announcement of each pass
PASS_MARK = re.compile(r"^test\.sh: (.*)$")


@dataclass
class PassTimes:
    """One pytest run inside the log: its name, per-test seconds (setup+call+teardown), its own wall time."""
    name: str
    tests: dict[str, float] = field(default_factory=lambda: defaultdict(float))
    wall_s: float | None = None
    outcome: str = ""


def parse(lines) -> list[PassTimes]:
    passes: list[PassTimes] = []
    current = None
    for raw in lines:
        line = raw.rstrip("\n")
        m = PASS_MARK.match(line)
        if m:
            current = PassTimes(m.group(1))
            passes.append(current)
            continue
        m = DURATION.match(line)
        if m:
            if current is None:
                current = PassTimes("pytest")
                passes.append(current)
            current.tests[m.group(3)] += float(m.group(1))
            continue
        m = SUMMARY.match(line)
        if m and current is not None and current.wall_s is None and ("passed" in line or "failed" in line
                                                                     or "error" in line or "skipped" in line):
            current.wall_s, current.outcome = float(m.group(2)), m.group(1).strip()
    return [p for p in passes if p.tests or p.wall_s is not None]


def report(passes: list[PassTimes], top: int, wall_s: float | None = None, cpu_s: float | None = None,
           loads: tuple | None = None) -> str:
    out = []
    if loads:
        out.append(f"load average (1, 5, 15 min): before {loads[0]}, after {loads[1]}; cores {os.cpu_count()}")
    if wall_s is not None:
        out.append(f"total wall time: {wall_s:.1f} s ({wall_s / 60:.1f} min)")
    if cpu_s is not None:
        out.append(f"CPU time of the test processes (user + sys): {cpu_s:.1f} s ({cpu_s / 60:.1f} min)")
    for p in passes:
        summed = sum(p.tests.values())
        wall = f"{p.wall_s:.1f} s" if p.wall_s is not None else "?"
        out.append(f"pass '{p.name}': pytest wall {wall}; {len(p.tests)} tests, their durations sum to "
                   f"{summed:.1f} s; {p.outcome}")
    every = [(s, p.name, t) for p in passes for t, s in p.tests.items()]
    every.sort(key=lambda x: -x[0])
    total = sum(s for s, _, _ in every)
    if not every:
        return "\n".join(out + ["no per-test durations found (was pytest run with --durations=0?)"])
    head = every[:top]
    share = sum(s for s, _, _ in head)
    out.append(f"slowest {len(head)} of {len(every)} tests: {share:.1f} s = {100 * share / total:.0f} % of the "
               f"summed test time ({total:.1f} s)")
    multi = len(passes) > 1
    for s, name, t in head:
        where = f"  [{name}]" if multi else ""
        out.append(f"  {s:8.1f} s  {100 * s / total:5.1f} %  {t}{where}")
    per_file: dict[str, float] = defaultdict(float)
    for s, name, t in every:
        per_file[(t.split("::", 1)[0], name)] += s
    files = sorted(per_file.items(), key=lambda x: -x[1])[:top]
    out.append(f"slowest {len(files)} files:")
    for (f, name), s in files:
        where = f"  [{name}]" if multi else ""
        out.append(f"  {s:8.1f} s  {100 * s / total:5.1f} %  {f}{where}")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("paths", nargs="*", help="test files or node ids (default: the whole scripts/test.sh run)")
    ap.add_argument("--top", type=int, default=20, help="how many of the slowest tests to list (default 20)")
    ap.add_argument("--log", action="append", type=Path,
                    help="parse this saved pytest --durations=0 output instead of running (repeatable)")
    ap.add_argument("--save", type=Path, help="also write the run's full output to this file")
    argv = list(sys.argv[1:] if argv is None else argv)
    extra = argv[argv.index("--") + 1:] if "--" in argv else []      # after --: arguments for pytest
    args = ap.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    if args.top < 1:
        ap.error(f"--top {args.top}: expected a count >= 1 of tests to list")
    if args.log:
        lines = []
        for log in args.log:
            if not log.is_file():
                ap.error(f"--log {log}: no such file")
            lines += log.read_text(errors="replace").splitlines()
        print(report(parse(lines), args.top))
        return 0
    cmd = ["bash", str(REPO / "scripts" / "test.sh"), *args.paths, *extra]
    # durations of every test, in both passes of test.sh (PYTEST_ADDOPTS reaches each pytest it runs)
    env = dict(os.environ, PYTEST_ADDOPTS=(os.environ.get("PYTEST_ADDOPTS", "") + " --durations=0 --durations-min=0").strip())
    before = os.getloadavg()
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=os.getcwd(), env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    lines = []
    save = args.save.open("w") if args.save else None
    for line in proc.stdout:
        lines.append(line)
        if save:
            save.write(line)
        if not DURATION.match(line):        # the durations go into the summary, everything else shows
            sys.stdout.write(line)
    rc = proc.wait()
    wall = time.monotonic() - t0
    if save:
        save.close()
    after = os.getloadavg()
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    print(f"\n--- bench_suite: {' '.join(cmd)} (exit {rc})")
    print(report(parse(lines), args.top, wall, ru.ru_utime + ru.ru_stime,
                 (tuple(round(x, 1) for x in before), tuple(round(x, 1) for x in after))))
    return rc


if __name__ == "__main__":
    sys.exit(main())
