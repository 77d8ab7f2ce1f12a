"""Known quirks of a log format, as generic operations an input profile names (``quirks:`` in its YAML).

Every operation reports what it did as a :class:`~..signals.DataIssue` (or a note): nothing is changed
silently. The product holds no knowledge of a particular dataset; a profile says which operation applies
with which arguments (see ``config/input_profiles/*.yaml`` and docs/realdata.md).

Operations (``op:`` key)

``align_sign``   make ``channels`` (and ``aux`` arrays) agree in sign with a ``reference`` channel (the first
                 of a list that is present and not constant); ``compare: derivative`` compares the time
                 derivative of the first channel with the reference (an angle against a speed),
                 ``derivative_mean`` / ``mean`` compare means (slow, noisy motion); ``default``
                 (+1/-1) applies when the data cannot decide; ``limits`` (channel -> bound) excludes
                 implausible samples from the decision.
``mask_when``    mask (NaN) ``channels`` (or ``all``) where an expression over channels, aux arrays and
                 constants is true, in runs of at least ``min_duration_s``; reported with ``kind`` and
                 ``detail``.
``pick_by_ratio`` choose the expression for ``channel`` from the ratio of two columns (``ratio``) — a
                 column whose label does not match its content; each case is ``{near, tolerance, value,
                 detail}``; ``otherwise`` when no case matches.

Expressions are Python syntax restricted to numbers, names (canonical channels, aux arrays, ``gear_ratio``,
``pole_pairs``, ``pi``), ``+ - * / **``, comparisons, ``and``/``or``/``not`` (element-wise) and the
functions ``abs``, ``sqrt``, ``sign``, ``isfinite``.
"""

from __future__ import annotations

import ast
import math
import operator

import numpy as np

from ..signals import DataIssue, Signals

# ---------------------------------------------------------------------------------------- expressions

_BIN = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
        ast.Pow: operator.pow}
_CMP = {ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
        ast.Eq: operator.eq, ast.NotEq: operator.ne}
_FUNCS = {"abs": np.abs, "sqrt": np.sqrt, "sign": np.sign, "isfinite": np.isfinite}


class ExpressionError(ValueError):
    """An expression in a profile cannot be evaluated; the message names the expression and the reason."""


def evaluate(expr: str, names: dict[str, object]):
    """Evaluate a restricted expression element-wise over numpy arrays (see the module docstring)."""
    try:
        tree = ast.parse(expr, mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"expression {expr!r}: {exc.msg}") from None

    def ev(node):
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            return float(node.value)
        if isinstance(node, ast.Name):
            if node.id not in names:
                raise ExpressionError(f"expression {expr!r}: unknown name {node.id!r} (known: "
                                      f"{', '.join(sorted(names))})")
            return names[node.id]
        if isinstance(node, ast.BinOp) and type(node.op) in _BIN:
            return _BIN[type(node.op)](ev(node.left), ev(node.right))
        if isinstance(node, ast.UnaryOp):
            v = ev(node.operand)
            if isinstance(node.op, ast.USub):
                return -v
            if isinstance(node.op, ast.UAdd):
                return v
            if isinstance(node.op, ast.Not):
                return np.logical_not(v)
        if isinstance(node, ast.BoolOp):
            vals = [ev(v) for v in node.values]
            f = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
            out = vals[0]
            for v in vals[1:]:
                out = f(out, v)
            return out
        if isinstance(node, ast.Compare):
            left, out = ev(node.left), None
            for op, comp in zip(node.ops, node.comparators):
                if type(op) not in _CMP:
                    break
                right = ev(comp)
                r = _CMP[type(op)](left, right)
                out = r if out is None else np.logical_and(out, r)
                left = right
            else:
                return out
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCS \
                and len(node.args) == 1 and not node.keywords:
            return _FUNCS[node.func.id](ev(node.args[0]))
        raise ExpressionError(f"expression {expr!r}: {ast.dump(node)[:60]} is not allowed")

    with np.errstate(divide="ignore", invalid="ignore"):
        return ev(tree)


def names_of(sig: Signals, constants: dict | None = None) -> dict[str, object]:
    """Names an expression may use: channels, aux arrays, constants, ``pi``."""
    out: dict[str, object] = {"pi": math.pi}
    out.update({k: v for k, v in (constants or {}).items() if v is not None})
    out.update({k: v for k, v in sig.meta.get("aux", {}).items() if isinstance(v, np.ndarray)})
    out.update(sig.channels)
    return out


# ------------------------------------------------------------------------------------------ helpers

def _premask(sig: Signals, name: str, n: int) -> None:
    """Count samples masked (and reported) here, so that cleaning does not report them again."""
    pm = sig.meta.setdefault("premasked", {})
    pm[name] = pm.get(name, 0) + int(n)


def sign_against(ref: np.ndarray, x: np.ndarray, ok: np.ndarray) -> tuple[int, str]:
    """Sign of x relative to ref: (+1|-1|0, evidence). Correlation when ref varies, else mean product."""
    ok = ok & np.isfinite(ref) & np.isfinite(x)
    if ok.sum() < 10:
        return 0, "too few samples"
    r, y = ref[ok], x[ok]
    if np.std(r) > 1e-9 * max(1.0, np.abs(r).max()) and np.std(y) > 0:
        c = float(np.corrcoef(r, y)[0, 1])
        if abs(c) >= 0.3:
            return (1 if c > 0 else -1), f"correlation {c:+.3f} over {ok.sum()} samples"
        return 0, f"correlation only {c:+.3f}"
    my, sy = float(np.mean(y)), float(np.std(y)) / math.sqrt(len(y))
    if abs(np.mean(r)) > 0 and abs(my) > 5 * sy:
        s = 1 if np.mean(r) * my > 0 else -1
        return s, f"constant reference {np.mean(r):+.3g} vs mean {my:+.3g}"
    return 0, "reference constant and the channel not clearly signed"


def _sign_of_means(ref: np.ndarray, x: np.ndarray, ok: np.ndarray) -> tuple[int, str]:
    """Sign from the means of two channels, each clearly non-zero (5 standard errors)."""
    out = []
    for v in (ref, x):
        v = v[ok & np.isfinite(v)]
        if len(v) < 10:
            return 0, "too few samples"
        m, se = float(np.mean(v)), float(np.std(v)) / math.sqrt(len(v))
        if abs(m) <= 5 * se:
            return 0, f"mean {m:+.3g} not clearly signed"
        out.append(m)
    return (1 if out[0] * out[1] > 0 else -1), f"means {out[0]:+.3g} vs {out[1]:+.3g}"


def _plausible(sig: Signals, limits: dict) -> np.ndarray:
    ok = np.ones(len(sig.time), bool)
    for name, bound in (limits or {}).items():
        x = sig.channels.get(name)
        if x is not None:
            ok &= np.isfinite(x) & (np.abs(x) < float(bound))
    return ok


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


# --------------------------------------------------------------------------------------- operations

def align_sign(sig: Signals, spec: dict, constants: dict) -> None:
    chans = [c for c in spec.get("channels", []) if c in sig.channels]
    aux = [a for a in spec.get("aux", []) if a in sig.meta.get("aux", {})]
    if not chans:
        return
    refs = spec.get("reference", [])
    refs = [refs] if isinstance(refs, str) else list(refs)
    ref_name = None
    for r in refs:
        v = sig.channels.get(r)
        if v is not None and np.any(v[np.isfinite(v)] != 0):
            ref_name = r
            break
    first = sig.channels[chans[0]]
    ok = _plausible(sig, spec.get("limits"))
    compare = str(spec.get("compare", "value"))
    x = first
    if compare.startswith("derivative"):
        good = np.isfinite(first)
        x = np.full(len(first), np.nan)
        if good.sum() > 2:
            x[good] = np.gradient(first[good], sig.time[good])
    if not ref_name:
        s, why = 0, "no reference channel present"
    elif compare.endswith("mean"):
        s, why = _sign_of_means(sig.channels[ref_name], x, ok)
    else:
        s, why = sign_against(sig.channels[ref_name], x, ok)
    default = spec.get("default")
    if s == 0 and default is not None:
        s, why = int(default), f"undetermined ({why}); the profile's default ({int(default):+d}) applied"
        if spec.get("default_reason"):
            why += f": {spec['default_reason']}"
    if s == 0:
        sig.meta["notes"].append(f"sign of {', '.join(chans)} vs {ref_name}: undetermined ({why}); kept as recorded")
        return
    if s > 0:
        return
    for c in chans:
        sig.channels[c] = -sig.channels[c]
    for a in aux:
        sig.meta["aux"][a] = -sig.meta["aux"][a]
    what = f"the {'derivative of ' if str(spec.get('compare', '')).startswith('derivative') else ''}{chans[0]}"
    sig.issues.append(DataIssue(
        "sign_convention", chans[0], int(ok.sum()), None,
        f"{chans[0]}: {what} has the opposite sign of {ref_name or 'the reference'} ({why})"
        + (f"; {spec['because']}" if spec.get("because") else ""),
        f"negated {', '.join(chans + aux)}"))


def mask_when(sig: Signals, spec: dict, constants: dict) -> None:
    cond = evaluate(spec["when"], names_of(sig, constants))
    cond = np.broadcast_to(np.asarray(cond, bool), sig.time.shape) & True
    cond = np.where(np.isnan(cond.astype(float)), False, cond)
    min_s = float(spec.get("min_duration_s", 0.0))
    runs = [(a, b) for a, b in _runs(cond) if sig.time[b - 1] - sig.time[a] >= min_s]
    if not runs:
        return
    mask = np.zeros(len(sig.time), bool)
    for a, b in runs:
        mask[a:b] = True
    targets = list(sig.channels) if spec.get("channels", "all") == "all" else \
        [c for c in spec["channels"] if c in sig.channels]
    for name in targets:
        x = sig.channels[name]
        _premask(sig, name, int(np.sum(mask & np.isfinite(x))))
        x[mask] = np.nan
    n = int(mask.sum())
    a, b = max(runs, key=lambda r: r[1] - r[0])
    t0 = float(sig.time[runs[0][0]])
    detail = str(spec.get("detail", "")).strip() or f"condition {spec['when']}"
    where = (f"{n} sample(s) in {len(runs)} window(s), first at t={t0:.4g}, longest t={sig.time[a]:.4g}.."
             f"{sig.time[b - 1]:.4g}")
    sig.issues.append(DataIssue(spec.get("kind", "outlier"), spec.get("report_channel", targets[0] if targets else "time"), n, t0,
                                f"{', '.join(targets)}: {detail} ({where}; condition: {spec['when']})",
                                spec.get("action", "masked (NaN), excluded from fits")))


def pick_by_ratio(sig: Signals, spec: dict, constants: dict) -> None:
    names = names_of(sig, constants)
    try:
        r = np.asarray(evaluate(spec["ratio"], names), float)
    except ExpressionError:
        r = np.array([])                          # a column of the ratio is absent: no case can match
    r = r[np.isfinite(r) & (r != 0)]
    ratio = float(np.median(r)) if len(r) else float("nan")
    chosen = None
    for case in spec.get("cases", []):
        if math.isfinite(ratio) and abs(ratio / float(case["near"]) - 1) < float(case.get("tolerance", 0.01)):
            chosen = case
            break
    target = spec["channel"]
    if chosen is not None:
        sig.channels[target] = np.asarray(evaluate(chosen["value"], names), float) * np.ones(len(sig.time))
        sig.meta["semantics"][target] = f"{chosen['value']} (column ratio {ratio:.5g}, profile case)"
        sig.issues.append(DataIssue("unit_suspect", target, len(r), None,
                                    f"{target}: {chosen.get('detail', '')} (median ratio {spec['ratio']} = {ratio:.5g})",
                                    f"{target} = {chosen['value']}"))
    elif spec.get("otherwise"):
        sig.channels[target] = np.asarray(evaluate(spec["otherwise"], names), float) * np.ones(len(sig.time))
        sig.meta["semantics"][target] = spec["otherwise"]
        if len(r):
            sig.meta["notes"].append(f"{target}: ratio {spec['ratio']} = {ratio:.5g} matches no case; "
                                     f"{spec['otherwise']} used")


OPERATIONS = {"align_sign": align_sign, "mask_when": mask_when, "pick_by_ratio": pick_by_ratio}


def apply(sig: Signals, quirks: list[dict], constants: dict | None = None, where: str = "profile") -> None:
    """Apply the profile's quirks in order."""
    for k, spec in enumerate(quirks or []):
        op = spec.get("op")
        if op not in OPERATIONS:
            raise ValueError(f"{where}: quirks[{k}].op: {op!r} is not one of {', '.join(OPERATIONS)}")
        OPERATIONS[op](sig, spec, constants or {})
