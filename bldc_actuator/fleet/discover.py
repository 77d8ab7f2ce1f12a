"""Which files a fleet run covers, and which nominal parameter file each one is diagnosed against."""

from __future__ import annotations

import fnmatch
import glob
from dataclasses import dataclass
from pathlib import Path

RECORDING_SUFFIXES = (".mcap", ".csv", ".tsv", ".txt")


@dataclass(frozen=True)
class Item:
    """One file to diagnose."""

    path: str          #: absolute path
    root: str          #: the pattern's directory part before the first wildcard (actuator ids are relative to it)


def static_root(pattern: str) -> Path:
    """``logs/**/*.mcap`` -> ``logs``; ``/a/b/c.csv`` -> ``/a/b``."""
    parts = Path(pattern).parts
    keep = []
    for part in parts:
        if any(c in part for c in "*?["):
            break
        keep.append(part)
    root = Path(*keep) if keep else Path(".")
    return root if root.is_dir() else root.parent


def expand(patterns: list[str]) -> list[Item]:
    """Recordings (:data:`RECORDING_SUFFIXES`) matching any pattern (``**`` recurses; a directory means every
    recording under it), sorted, each once. A pattern that matches nothing raises ValueError naming it."""
    seen: dict[str, Item] = {}
    for pat in patterns:
        p = Path(pat)
        if p.is_dir():
            root, matches = p, [str(x) for x in sorted(p.rglob("*")) if x.suffix.lower() in RECORDING_SUFFIXES]
        else:
            root, matches = static_root(pat), sorted(glob.glob(pat, recursive=True))
        matches = [m for m in matches if Path(m).is_file() and Path(m).suffix.lower() in RECORDING_SUFFIXES]
        if not matches:
            raise ValueError(f"{pat}: no file matches this pattern (quote it so the shell does not expand it)")
        for m in matches:
            a = str(Path(m).resolve())
            seen.setdefault(a, Item(a, str(root.resolve())))
    return sorted(seen.values(), key=lambda i: i.path)


def load_params_map(path: str | Path) -> list[tuple[str, str]]:
    """``--params-map`` YAML: ``{PATTERN: PARAMS_FILE}`` (file-name glob on the actuator id or the path, first
    match wins; relative parameter files are relative to the map file)."""
    import yaml

    path = Path(path)
    try:
        tree = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"--params-map {path}: cannot read: {exc}") from None
    if not isinstance(tree, dict) or not tree:
        raise ValueError(f"--params-map {path}: expected a mapping PATTERN: PARAMS_FILE, e.g. 'robot1/*: ak80_9.yaml'")
    out = []
    for pat, target in tree.items():
        t = Path(str(target))
        if not t.is_absolute():
            t = path.parent / t
        if not t.exists():
            raise ValueError(f"--params-map {path}: {pat}: parameter file {t} does not exist")
        out.append((str(pat), str(t)))
    return out


def params_for(params_map: list[tuple[str, str]], actuator_id: str, path: str) -> str | None:
    for pat, target in params_map:
        if fnmatch.fnmatch(actuator_id, pat) or fnmatch.fnmatch(path, pat) or fnmatch.fnmatch(path, f"*/{pat}"):
            return target
    return None
