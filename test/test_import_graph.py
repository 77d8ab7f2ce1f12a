"""No import cycles inside the package (issues #7 and #9: pipeline <-> report, loaders <-> profiles), counting
imports inside functions too: a lazy import hides a cycle from Python, not from the reader."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "bldc_actuator"


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _graph() -> dict[str, set[str]]:
    mods = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        pkg = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = pkg.split(".")
                    base = base[: len(base) - (node.level - 1)]
                    stem = ".".join(base + ([node.module] if node.module else []))
                else:
                    stem = node.module or ""
                targets = [f"{stem}.{a.name}" for a in node.names] + [stem]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            for t in targets:
                while t and t not in mods:
                    t = t.rsplit(".", 1)[0] if "." in t else ""
                if t and t != mod and not mod.startswith(t + ".") and t != "bldc_actuator":
                    graph[mod].add(t)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_the_graph_sees_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": set()}) == [["a", "b"]]


def test_diagnosis_io_is_the_bottom_layer():
    """diagnosis/io (loaders, formats, profiles, quirks, cleaning) reads recordings into Signals: within the
    diagnosis it may use only ``signals`` and itself, never the method (search, judge, fit, report) above it."""
    g = _graph()
    io_mods = [m for m in g if m.startswith("bldc_actuator.diagnosis.io")]
    assert "bldc_actuator.diagnosis.io.cleaning" in io_mods and "bldc_actuator.diagnosis.io.loaders" in io_mods
    allowed = ("bldc_actuator.diagnosis.io", "bldc_actuator.diagnosis.signals")
    above = {m: sorted(t for t in g[m] if t.startswith("bldc_actuator.diagnosis")
                       and not any(t == a or t.startswith(a + ".") for a in allowed))
             for m in io_mods}
    assert {m: t for m, t in above.items() if t} == {}


def test_no_import_cycles_in_the_package():
    g = _graph()
    assert "bldc_actuator.diagnosis.io.input_profiles" in g["bldc_actuator.diagnosis.io.loaders"]
    assert _cycles(g) == []
