#!/usr/bin/env python3
"""The README's per-case table of the concealed benchmark, from a results JSON written by run_concealed.py:

    python benchmarks/concealed_readme_table.py [benchmarks/results/concealed.json]

One row a case: hidden effects, SNR and channel, what diagnose named, the main parameter true -> estimate, and
the simulated held-out verdict with the two channels that improved most (relative)."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _fmt(x) -> str:
    if isinstance(x, bool):             # a flag (the drive's decoupling_enabled)
        return str(x).lower()
    if isinstance(x, str):
        return x
    return "–" if x is None else format(x, ".3g")


def _improved(detail: str, n: int = 2) -> str:
    parts = []
    for m in re.finditer(r"(\w+) ([\d.e+-]+)→([\d.e+-]+)", detail or ""):
        a, b = float(m.group(2)), float(m.group(3))
        if a > 0 and b < 0.99 * a:
            parts.append((b / a, f"{m.group(1)} {m.group(2)}→{m.group(3)}"))
    return "; ".join(p for _, p in sorted(parts)[:n])


def table(results: dict) -> str:
    rows = ["| case | hidden effect(s) | SNR (channel) | named by diagnose | main parameter true → estimate | "
            "simulated held-out, updated vs nominal parameters (channels that improved most) |",
            "|---|---|---|---|---|---|"]
    for c in results["cases"]:
        hid = ", ".join(c["hidden"]) or "(none)"
        ch = "voltage" if c["channel"] == "voltage_q" else c["channel"]
        snr = "–" if not c["hidden"] else f"{c['snr']:.2f} ({ch})"
        found = ", ".join(c["found"]) or "(nothing)"
        par = "; ".join(f"{_fmt(e['true_value'])}→{_fmt(e['estimate'])}" for e in c["effects"]) or "–"
        sim = c["simulated"] or "unchanged"
        if sim == "better":
            sim = "better: " + _improved(c.get("simulated_detail", ""))
        rows.append(f"| {c['case']} | {hid} | {snr} | {found} | {par} | {sim} |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else REPO / "benchmarks" / "results" / "concealed.json"
    print(table(json.loads(path.read_text())), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
