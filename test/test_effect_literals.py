"""Effects are known through their registry, never by name (issue #24): a string constant equal to an effect's
name anywhere in ``bldc_actuator/`` outside ``diagnosis/effects/`` is a place that special-cases it. Each must
become a facet of the effect's record (``effect.route is Route.THERMAL``, ``effect.angle_locked``...).

A ratchet for now: :data:`ALLOWED` lists the files that still name effects and how often. The counts may only
shrink (a file whose count fell must lower its entry in the same commit), no file may be added, and the list must
reach empty."""

from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

from bldc_actuator.diagnosis.effects import registry
from bldc_actuator.params import SPECS

PKG = Path(__file__).resolve().parents[1] / "bldc_actuator"
REGISTRY_DIR = PKG / "diagnosis" / "effects"

#: the parameter schema and the model over it name parameter FIELDS, some of which share an effect's name
#: (``effects.coulomb_friction``, ``gear.backlash``, ``drive.dead_time``): there such a constant is the field
SCHEMA_MODULES = ("params.py", "model.py")

#: file (relative to bldc_actuator/) -> effect-name constants it still holds. MUST ONLY SHRINK, and reach empty:
#: when you remove literals from a file, lower (or delete) its entry here in the same commit.
ALLOWED = {
    "diagnosis/frame/candidates.py": 3,
    "diagnosis/report/stage.py": 6,
    "diagnosis/steady_state.py": 1,
    "diagnosis/torque_balance.py": 16,
    "fleet/health.py": 11,
}


def effect_literals(source: str, names, skip=frozenset()) -> Counter:
    """Effect-name string constants in ``source`` (docstrings and f-string text are constants too, but an
    identifier is never a whole docstring), by name; ``skip``: names not counted in this file."""
    out = Counter()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in names \
                and node.value not in skip:
            out[node.value] += 1
    return out


def _field_names() -> frozenset[str]:
    return frozenset(f.rsplit(".", 1)[-1] for f in SPECS)


def scan() -> dict[str, int]:
    names = frozenset(registry.names())
    fields = _field_names()
    counts = {}
    for path in sorted(PKG.rglob("*.py")):
        if REGISTRY_DIR in path.parents:
            continue
        rel = path.relative_to(PKG).as_posix()
        skip = fields if rel in SCHEMA_MODULES else frozenset()
        n = sum(effect_literals(path.read_text(), names, skip).values())
        if n:
            counts[rel] = n
    return counts


def test_the_scan_sees_an_effect_name_and_only_whole_names():
    names = frozenset(registry.names())
    src = 'x = "dead_time"\nif e in ("iron_loss", "cogging"):\n    y = f"dead_time {e}"\nz = "dead_time_sign"\n'
    assert effect_literals(src, names) == Counter({"dead_time": 1, "iron_loss": 1})
    assert effect_literals(src, names, skip=frozenset({"dead_time"})) == Counter({"iron_loss": 1})


def test_no_effect_name_outside_the_registry_beyond_the_ratchet():
    counts = scan()
    new = {f: n for f, n in counts.items() if f not in ALLOWED}
    assert new == {}, f"effect names outside diagnosis/effects/ (ask the registry for a facet instead): {new}"
    grown = {f: (n, ALLOWED[f]) for f, n in counts.items() if n > ALLOWED[f]}
    assert grown == {}, f"more effect-name literals than allowed (count, allowed): {grown}"


def test_the_ratchet_is_tight():
    """An entry above its file's count must be lowered: the allow-list only shrinks."""
    counts = scan()
    loose = {f: (counts.get(f, 0), n) for f, n in ALLOWED.items() if counts.get(f, 0) < n}
    assert loose == {}, f"lower these ALLOWED entries to the count (count, allowed): {loose}"


def test_every_effect_module_is_named_after_its_effect_and_its_facets_are_consistent():
    effects = registry.all()
    names = registry.names()
    assert len(names) == len(set(names)) and len(effects) >= 22
    for e in effects:
        assert (REGISTRY_DIR / f"{e.name}.py").is_file(), e.name
        for other in list(e.confusable) + list(e.hides_behind or ()):
            assert registry.known(other), (e.name, other)
        for p in e.params:
            if p.field is not None:
                assert p.field.split("[")[0] in SPECS, (e.name, p.field)
        for _, path in e.nominal:
            assert path in SPECS, (e.name, path)
        assert e.special == (e.equations[0] in ("thermal", "tracking", "torque_balance", "body")), e.name


def test_every_linear_candidate_has_its_forms_and_no_other_effect_is_searched_linearly():
    from bldc_actuator.diagnosis.effects import Route
    from bldc_actuator.diagnosis.frame import candidates

    lib = candidates.library()
    assert tuple(lib) == registry.names(registry.candidates())
    for name, cand in lib.items():
        linear = registry.get(name).route is Route.LINEAR
        assert (cand.variants is not None) == linear, name
        assert cand.record is registry.get(name)
    assert set(candidates.SPECIAL) == {n for n in lib if registry.get(n).special}
