"""Column mapping for foreign recordings: canonical channel <- expression over a source column.

``--map current=iq_measured --map velocity=speed*9 --map torque=-adc_torque`` or a YAML file. Expressions:
``[k*][-]SOURCE[*k|/k|+k|-k]...`` applied left to right, i.e. ``value = scale * raw + offset``. SOURCE is a
CSV column name (quote it, ``"a-b"``, when it contains operators), ``#3`` (the 4th column of a header-less
CSV) or, for MCAP, ``topic.field[index]`` (``/joint_states.velocity[0]``, ``/motor/iq.data``, a labelled
Float64MultiArray element ``/x/q_axis_state.i_q``, a JointState entry by joint name
``/joint_states.velocity[wrist]``). A topic may be given by its unique suffix (``q_axis_state.i_q``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..signals import CANONICAL

#: mapping targets: the canonical channels plus the time axis
TARGETS = ("time",) + tuple(CANONICAL)


class LoadError(ValueError):
    """A recording cannot be read; the message names the file, and the line or field where it applies."""


# ============================================================================================ Mapping

_NUM = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_TRAIL = re.compile(r"\s*([*/+\-])\s*(" + _NUM + r")\s*$")
_LEAD_MUL = re.compile(r"^\s*(" + _NUM + r")\s*\*\s*")


def parse_expression(expr: str) -> tuple[str, float, float]:
    """``"-adc*2+0.5"`` -> (source ``adc``, scale -2, offset 0.5). Raises ValueError with the reason."""
    text = expr.strip()
    if not text:
        raise ValueError("empty expression")
    scale, offset = 1.0, 0.0
    m = _LEAD_MUL.match(text)
    if m:
        scale = float(m.group(1))
        text = text[m.end():]
    if text.startswith("-") and len(text) > 1 and not text[1].isdigit():
        scale = -scale
        text = text[1:].lstrip()
    ops: list[tuple[str, float]] = []
    if text.startswith('"') or text.startswith("'"):
        q = text[0]
        end = text.find(q, 1)
        if end < 0:
            raise ValueError(f"unterminated quote in {expr!r}")
        source, rest = text[1:end], text[end + 1:]
        while rest.strip():
            m = re.match(r"\s*([*/+\-])\s*(" + _NUM + r")", rest)
            if not m:
                raise ValueError(f"cannot read {rest.strip()!r} after the quoted name in {expr!r} "
                                 "(expected *k, /k, +k or -k)")
            ops.append((m.group(1), float(m.group(2))))
            rest = rest[m.end():]
    else:
        source = text
        while True:
            m = _TRAIL.search(source)
            if not m or m.start() == 0:
                break
            ops.insert(0, (m.group(1), float(m.group(2))))
            source = source[:m.start()]
        source = source.strip()
    if not source:
        raise ValueError(f"no source column in {expr!r}")
    for op, k in ops:
        if op == "*":
            scale, offset = scale * k, offset * k
        elif op == "/":
            if k == 0:
                raise ValueError(f"division by zero in {expr!r}")
            scale, offset = scale / k, offset / k
        elif op == "+":
            offset += k
        else:
            offset -= k
    return source, scale, offset


@dataclass
class Mapping:
    """canonical (or ``time``) -> source expression, with the parsed scale and offset per target."""

    columns: dict[str, str] = field(default_factory=dict)
    scale: dict[str, float] = field(default_factory=dict)
    offset: dict[str, float] = field(default_factory=dict)

    @classmethod
    def parse(cls, items: list[str] | tuple[str, ...]) -> "Mapping":
        """From ``["current=iq_measured", "velocity=speed*9", "torque=-adc_torque"]``."""
        m = cls()
        for item in items or ():
            if "=" not in item:
                raise ValueError(f"--map {item!r}: expected CANONICAL=EXPRESSION, e.g. velocity=speed*9")
            target, expr = item.split("=", 1)
            m.add(target.strip(), expr)
        return m

    @classmethod
    def from_yaml(cls, path: str | Path) -> "Mapping":
        """YAML ``{canonical: expression}`` or ``{columns: {...}, scale: {...}, offset: {...}}``."""
        import yaml

        path = Path(path)
        try:
            tree = yaml.safe_load(path.read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise ValueError(f"{path}: cannot read mapping file: {exc}") from None
        if not isinstance(tree, dict):
            raise ValueError(f"{path}: expected a mapping of canonical name -> expression")
        m = cls()
        if "columns" in tree and isinstance(tree["columns"], dict):
            for target, expr in tree["columns"].items():
                m.add(str(target), str(expr))
            for key in ("scale", "offset"):
                for target, value in (tree.get(key) or {}).items():
                    if target not in m.columns:
                        raise ValueError(f"{path}: {key}.{target} given without columns.{target}")
                    try:
                        v = float(value)
                    except (TypeError, ValueError):
                        raise ValueError(f"{path}: {key}.{target}: expected a number, got {value!r}") from None
                    if key == "scale":
                        m.scale[target] *= v
                        m.offset[target] *= v
                    else:
                        m.offset[target] += v
        else:
            for target, expr in tree.items():
                m.add(str(target), str(expr))
        return m

    def add(self, target: str, expr: str) -> None:
        if target not in TARGETS:
            raise ValueError(f"--map {target}=...: {target!r} is not a canonical name "
                             f"(known: {', '.join(TARGETS)})")
        try:
            source, scale, offset = parse_expression(expr)
        except ValueError as exc:
            raise ValueError(f"--map {target}={expr}: {exc}") from None
        self.columns[target] = source
        self.scale[target] = scale
        self.offset[target] = offset

    def apply(self, target: str, values: np.ndarray) -> np.ndarray:
        return values * self.scale.get(target, 1.0) + self.offset.get(target, 0.0)

    def describe(self) -> dict[str, str]:
        """target -> human-readable expression actually applied."""
        out = {}
        for t, src in self.columns.items():
            s, o = self.scale.get(t, 1.0), self.offset.get(t, 0.0)
            text = src if s == 1.0 else f"{s:g}*{src}"
            if o:
                text += f"{o:+g}"
            out[t] = text
        return out
