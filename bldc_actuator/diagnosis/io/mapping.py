"""Column mapping for foreign recordings: canonical channel <- expression over a source column.

``--map current=iq_measured --map velocity=speed*9 --map torque=-adc_torque`` or a YAML file. Expressions:
``[k*][-]SOURCE[*k|/k|+k|-k]...`` applied left to right, i.e. ``value = scale * raw + offset``. SOURCE is a
CSV column name (quote it, ``"a-b"``, when it contains operators), ``#3`` (the 4th column of a header-less
CSV) or, for MCAP, ``topic.field[index]`` (``/joint_states.velocity[0]``, ``/motor/iq.data``, a labelled
Float64MultiArray element ``/x/q_axis_state.i_q``, a JointState entry by joint name
``/joint_states.velocity[wrist]``). A topic may be given by its unique suffix (``q_axis_state.i_q``).

Expressions that combine columns (:class:`Expression`, CSV and JSON logs): ``voltage_q=duty*v_bus``,
``voltage_q=(pwm-0.5)*2*v_bus``, a sign from a direction bit ``voltage_q=duty*v_bus*(1-2*dir)``. The grammar is
a small whitelist over Python's :mod:`ast` (never ``eval``): column names (identifiers, dotted names, a quoted
``"name"`` or ``#k``), numbers, ``+ - * / **`` (a number as exponent), unary minus, parentheses, comparisons
(``< <= > >= == !=``, giving 1/0), and the functions :data:`FUNCTIONS` (``abs``, ``sign``, ``where(cond, a,
b)``, ``sqrt``, ``min``, ``max``, ``clip(x, lo, hi)``). An expression affine in one column stays a
(source, scale, offset) triple as before; one over several columns (or with a function) is kept as
:attr:`Mapping.combined` and evaluated by the loader over the columns it names.
"""

from __future__ import annotations

import ast
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


# ================================================================================ combined expressions

#: functions an expression may call: name -> (numpy implementation, number of arguments)
FUNCTIONS = {
    "abs": (np.abs, 1), "sign": (np.sign, 1), "sqrt": (np.sqrt, 1),
    "where": (lambda c, a, b: np.where(np.asarray(c) != 0, a, b), 3),
    "min": (np.minimum, 2), "max": (np.maximum, 2), "clip": (np.clip, 3),
}
_BINOPS = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide}
_CMPOPS = {ast.Lt: np.less, ast.LtE: np.less_equal, ast.Gt: np.greater, ast.GtE: np.greater_equal,
           ast.Eq: np.equal, ast.NotEq: np.not_equal}
_INDEX_REF = re.compile(r"#(-?\d+)")


def _column_name(node: ast.AST) -> str | None:
    """The column a node names: an identifier, a dotted name (``a.b``), ``name[k]``, a quoted string, ``#k``."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.Attribute):
        base = _column_name(node.value)
        return None if base is None else f"{base}.{node.attr}"
    if isinstance(node, ast.Subscript):
        base = _column_name(node.value)
        sl = node.slice
        if base is not None and isinstance(sl, (ast.Constant, ast.Name)):
            return f"{base}[{sl.value if isinstance(sl, ast.Constant) else sl.id}]"
    return None


@dataclass(frozen=True)
class Expression:
    """A mapping expression parsed into a whitelisted tree: :attr:`columns` it reads, :meth:`evaluate` over
    arrays, :meth:`affine` when it is ``scale * column + offset`` of one column."""

    text: str
    tree: ast.AST = field(repr=False, compare=False)
    columns: tuple[str, ...] = ()

    @classmethod
    def parse(cls, text: str) -> "Expression":
        """Raises ValueError naming the expression and what is not allowed in it."""
        src = text.strip()
        if not src:
            raise ValueError("empty expression")
        py = _INDEX_REF.sub(lambda m: repr(f"#{m.group(1)}"), src)
        try:
            tree = ast.parse(py, mode="eval").body
        except SyntaxError:
            raise ValueError(f"cannot parse {text!r} (expected column names, numbers, + - * /, parentheses and "
                             f"{', '.join(FUNCTIONS)})") from None
        cols: list[str] = []
        cls._check(tree, text, cols)
        return cls(src, tree, tuple(dict.fromkeys(cols)))

    @classmethod
    def _check(cls, node: ast.AST, text: str, cols: list[str]) -> None:
        name = _column_name(node)
        if name is not None:
            cols.append(name)
            return
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            return
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            return cls._check(node.operand, text, cols)
        if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
            cls._check(node.left, text, cols)
            return cls._check(node.right, text, cols)
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            cls._check(node.left, text, cols)
            if not (isinstance(node.right, ast.Constant) and isinstance(node.right.value, (int, float))):
                raise ValueError(f"{text!r}: the exponent of ** must be a number")
            return
        if isinstance(node, ast.Compare) and len(node.ops) == 1 and type(node.ops[0]) in _CMPOPS:
            cls._check(node.left, text, cols)
            return cls._check(node.comparators[0], text, cols)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and not node.keywords:
            fn = FUNCTIONS.get(node.func.id)
            if fn is None:
                raise ValueError(f"{text!r}: unknown function {node.func.id!r} (allowed: {', '.join(FUNCTIONS)})")
            if len(node.args) != fn[1]:
                raise ValueError(f"{text!r}: {node.func.id}() takes {fn[1]} argument(s), got {len(node.args)}")
            for a in node.args:
                cls._check(a, text, cols)
            return
        raise ValueError(f"{text!r}: {ast.unparse(node)!r} is not allowed (column names, numbers, + - * / **, "
                         f"comparisons, parentheses and {', '.join(FUNCTIONS)} only)")

    def evaluate(self, values: dict[str, np.ndarray], available: list[str] | None = None) -> np.ndarray:
        """The expression over ``values`` (column name -> array). An unknown column raises ValueError naming the
        expression, the column and the columns ``available`` (default: the keys of ``values``)."""
        missing = [c for c in self.columns if c not in values]
        if missing:
            have = available if available is not None else list(values)
            raise ValueError(f"expression {self.text!r}: no column {missing[0]!r} (columns: {', '.join(have)})")
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.asarray(self._eval(self.tree, values), float)

    def _eval(self, node, values):
        name = _column_name(node)
        if name is not None:
            return np.asarray(values[name], float)
        if isinstance(node, ast.Constant):
            return float(node.value)
        if isinstance(node, ast.UnaryOp):
            v = self._eval(node.operand, values)
            return -v if isinstance(node.op, ast.USub) else v
        if isinstance(node, ast.BinOp):
            a, b = self._eval(node.left, values), self._eval(node.right, values)
            return np.power(a, b) if isinstance(node.op, ast.Pow) else _BINOPS[type(node.op)](a, b)
        if isinstance(node, ast.Compare):
            a, b = self._eval(node.left, values), self._eval(node.comparators[0], values)
            return _CMPOPS[type(node.ops[0])](a, b).astype(float)
        fn = FUNCTIONS[node.func.id][0]
        return fn(*[self._eval(a, values) for a in node.args])

    def affine(self) -> tuple[str, float, float] | None:
        """(column, scale, offset) when the expression is ``scale * column + offset`` of one column, else None."""
        form = self._affine(self.tree)
        if form is None or form[0] is None or form[1] == 0.0:
            return None
        return form

    def _affine(self, node):
        """(column | None, scale, offset) of an affine form in at most one column, else None."""
        name = _column_name(node)
        if name is not None:
            return name, 1.0, 0.0
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            return None, 0.0, float(node.value)
        if isinstance(node, ast.UnaryOp):
            f = self._affine(node.operand)
            return None if f is None else (f[0], -f[1], -f[2]) if isinstance(node.op, ast.USub) else f
        if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
            a, b = self._affine(node.left), self._affine(node.right)
            if a is None or b is None:
                return None
            if isinstance(node.op, (ast.Add, ast.Sub)):
                if a[0] is not None and b[0] is not None and a[0] != b[0]:
                    return None
                k = 1.0 if isinstance(node.op, ast.Add) else -1.0
                return a[0] or b[0], a[1] + k * b[1], a[2] + k * b[2]
            if isinstance(node.op, ast.Mult):
                if a[0] is not None and b[0] is not None:
                    return None
                c, (col, s, o) = (b[2], a) if b[0] is None else (a[2], b)
                return col, s * c, o * c
            if b[0] is not None or b[2] == 0.0:
                return None
            return a[0], a[1] / b[2], a[2] / b[2]
        return None


def compile_expression(expr: str) -> tuple[str, float, float] | Expression:
    """``expr`` as (source, scale, offset) when it is affine in one column (the form every reader takes), else
    an :class:`Expression` over several columns. Text the grammar cannot read (an MCAP reference such as
    ``/joint_states.velocity[0]``) goes to :func:`parse_expression`, and so does every source with a bracket:
    a header with its unit (``t [s]``, ``i_q [A]*2``) is one column, as before the expression grammar (which would
    read ``t [s]`` as ``t`` indexed by ``s``); a name the grammar cannot read otherwise is quoted (``"motor-speed"``)."""
    text = expr.strip()
    if "[" in text or "{" in text:      # units in brackets, MCAP references, {j} templates
        return parse_expression(expr)
    try:
        e = Expression.parse(expr)
    except ValueError as exc:
        if text.startswith("/"):      # MCAP references
            return parse_expression(expr)
        raise exc from None
    form = e.affine()
    if form is not None:
        return form
    if not e.columns:
        raise ValueError(f"no source column in {expr!r}")
    return e


@dataclass
class Mapping:
    """canonical (or ``time``) -> source expression, with the parsed scale and offset per target."""

    columns: dict[str, str] = field(default_factory=dict)
    scale: dict[str, float] = field(default_factory=dict)
    offset: dict[str, float] = field(default_factory=dict)
    #: targets computed from several columns (``voltage_q=duty*v_bus``): target -> :class:`Expression`
    combined: dict[str, Expression] = field(default_factory=dict)

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
            form = compile_expression(expr)
        except ValueError as exc:
            raise ValueError(f"--map {target}={expr}: {exc}") from None
        self.combined.pop(target, None)
        self.columns.pop(target, None)
        if isinstance(form, Expression):
            if target == "time":
                raise ValueError(f"--map time={expr}: the time axis must be one column (scaled, offset), "
                                 f"not a combination of {', '.join(form.columns)}")
            self.combined[target] = form
            return
        source, scale, offset = form
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
        for t, e in self.combined.items():
            out[t] = e.text
        return out

    def update(self, other: "Mapping") -> None:
        """``other``'s targets replace this mapping's (``--map`` over ``--map-file``)."""
        for t in list(other.columns) + list(other.combined):
            self.columns.pop(t, None)
            self.combined.pop(t, None)
        self.columns.update(other.columns)
        self.scale.update(other.scale)
        self.offset.update(other.offset)
        self.combined.update(other.combined)

    @property
    def has_columns(self) -> bool:
        """Anything mapped (single-column or combined)."""
        return bool(self.columns or self.combined)

    def combined_sources(self) -> dict[str, str]:
        """Extra columns the combined targets read, as ``aux`` entries (name -> quoted column expression)."""
        return {_aux_key(c): f'"{c}"' for e in self.combined.values() for c in e.columns
                if not c.startswith("#")} | {_aux_key(c): c for e in self.combined.values() for c in e.columns
                                             if c.startswith("#")}

    def apply_combined(self, sig, header: list[str] | None = None, where: str = "") -> None:
        """Evaluate the combined targets over the aux columns :meth:`combined_sources` had read into
        ``sig.meta["aux"]`` (then removed from it); raises LoadError naming the expression, the missing column and
        the file's columns."""
        aux = sig.meta.setdefault("aux", {})
        missing = set(sig.meta.get("aux_missing") or ())
        have = header if header is not None else list(sig.meta.get("header") or [])
        for target, e in self.combined.items():
            vals = {c: aux[_aux_key(c)] for c in e.columns if _aux_key(c) not in missing and _aux_key(c) in aux}
            try:
                sig.channels[target] = e.evaluate(vals, have)
            except ValueError as exc:
                raise LoadError(f"{where or sig.source}: --map {target}={e.text}: {exc}") from None
            sig.meta.setdefault("semantics", {})[target] = f"expression {e.text}"
            sig.meta.setdefault("mapping", {})[target] = e.text
        used = {c for e in self.combined.values() for c in e.columns}
        for c in used:
            aux.pop(_aux_key(c), None)
        if sig.meta.get("aux_missing"):
            sig.meta["aux_missing"] = [a for a in sig.meta["aux_missing"] if not a.startswith(_AUX_PREFIX)]
        if sig.meta.get("unused_columns"):
            sig.meta["unused_columns"] = [c for c in sig.meta["unused_columns"] if c not in used]


_AUX_PREFIX = "__expr__:"


def _aux_key(column: str) -> str:
    return _AUX_PREFIX + column
