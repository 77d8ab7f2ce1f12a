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


D = "bldc_actuator.diagnosis"
#: the method's stages, each a package whose ``stage`` module is its one entry point (issue #14)
STAGES = ("search", "judge", "fit", "report")
#: what the shared frame (equation error, effect library, selection, window replays) may use within the diagnosis
FRAME_MAY_USE = ("frame", "io", "signals", "significance", "results", "threads", "effects")


def _top(mod: str) -> str:
    """The diagnosis subpackage or module a module belongs to: ``D.judge.stage`` -> ``judge``; '' outside D."""
    return mod[len(D) + 1:].split(".")[0] if mod.startswith(D + ".") else ""


def _layer_violations(graph: dict[str, set[str]]) -> list[str]:
    out = []
    for mod, targets in graph.items():
        own = _top(mod)
        for t in sorted(targets):
            dst = _top(t)
            if not own or not dst or dst == own:
                continue
            if own in STAGES and dst in STAGES:
                out.append(f"stage {own} imports stage {dst}: {mod} -> {t}")
            elif own == "frame" and dst not in FRAME_MAY_USE:
                out.append(f"frame imports {dst}: {mod} -> {t}")
            elif dst in STAGES and t == f"{D}.{dst}.stage" and own != "pipeline":
                out.append(f"a stage entry point imported outside the pipeline: {mod} -> {t}")
    return out


def test_the_layer_check_sees_a_stage_importing_another_and_frame_importing_a_stage():
    g = {f"{D}.report.stage": {f"{D}.search.stage", f"{D}.frame.locate", f"{D}.records"},
         f"{D}.frame.simulate": {f"{D}.judge.simulated", f"{D}.significance"},
         f"{D}.cli": {f"{D}.fit.stage"},
         f"{D}.pipeline": {f"{D}.search.stage", f"{D}.judge.stage"}}
    assert _layer_violations(g) == [
        f"stage report imports stage search: {D}.report.stage -> {D}.search.stage",
        f"frame imports judge: {D}.frame.simulate -> {D}.judge.simulated",
        f"a stage entry point imported outside the pipeline: {D}.cli -> {D}.fit.stage",
    ]


def test_diagnosis_stages_import_frame_io_results_never_each_other():
    """search/ judge/ fit/ report/ each hold a ``stage`` module (one entry point) and its helpers; they use the
    shared frame, io, records and results, never another stage (the pipeline chains them); the frame imports no
    stage; there is no ``stages`` package left."""
    g = _graph()
    assert not any(m == f"{D}.stages" or m.startswith(f"{D}.stages.") for m in g)
    for s in STAGES:
        assert f"{D}.{s}.stage" in g, s
        assert f"{D}.{s}.stage" in g[f"{D}.pipeline"], s
    assert f"{D}.frame.simulate" in g[f"{D}.judge.simulated"]  # the check reads real imports
    assert _layer_violations(g) == []


def test_the_effect_registry_sits_below_every_layer():
    """diagnosis/effects (the effect records and their registry, issue #24) is imported by the frame, the stages
    and the tools beside them, so it imports nothing of the diagnosis itself."""
    g = _graph()
    mods = [m for m in g if m == f"{D}.effects" or m.startswith(f"{D}.effects.")]
    assert f"{D}.effects.registry" in mods and f"{D}.effects.dead_time" in mods
    assert f"{D}.effects" in g[f"{D}.frame.candidates"] or f"{D}.effects.registry" in g[f"{D}.frame.candidates"]
    up = {m: sorted(t for t in g[m] if t.startswith(D + ".") and _top(t) != "effects") for m in mods}
    assert {m: t for m, t in up.items() if t} == {}
