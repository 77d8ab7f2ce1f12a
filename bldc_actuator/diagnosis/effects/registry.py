"""The registry: the one way the diagnosis knows an effect (issue #24).

Every module of this package except :mod:`.record` and this one is an effect module holding ``EFFECT``; they are
found by name (:func:`pkgutil.iter_modules`), so adding an effect is adding one file (docs/effects.md). Lookups
by name (:func:`get`), in catalogue order (:func:`all`, :func:`names`) and by facet (:func:`where`,
:func:`by_param`, :func:`by_field`, :func:`torque_scale`, :func:`one`)."""

from __future__ import annotations

import functools
import importlib
import pkgutil
from typing import Callable, Iterable

from .forms import Forms
from .record import Effect, Route

_NOT_EFFECTS = frozenset({"record", "registry", "forms"})


_FORMS: dict[str, Forms | None] = {}


@functools.lru_cache(maxsize=1)
def _catalogue() -> dict[str, Effect]:
    from . import __path__ as here, __name__ as pkg

    found = []
    for info in pkgutil.iter_modules(here):
        if info.name in _NOT_EFFECTS or info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{pkg}.{info.name}")
        eff = getattr(mod, "EFFECT", None)
        if not isinstance(eff, Effect):
            raise TypeError(f"effect module {mod.__name__} must define EFFECT = Effect(...), got {type(eff).__name__}")
        if eff.name != info.name:
            raise ValueError(f"effect module {mod.__name__} holds effect {eff.name!r}: the module is named after its "
                             f"effect")
        found.append(eff)
        forms = getattr(mod, "FORMS", None)
        if forms is not None and not isinstance(forms, Forms):
            raise TypeError(f"effect module {mod.__name__}: FORMS must be a Forms(...), got {type(forms).__name__}")
        _FORMS[eff.name] = forms
    found.sort(key=lambda e: e.rank)
    ranks = [e.rank for e in found]
    if len(set(ranks)) != len(ranks):
        dup = sorted({r for r in ranks if ranks.count(r) > 1})
        raise ValueError(f"effect ranks must be unique, repeated: {dup}")
    return {e.name: e for e in found}


def all() -> tuple[Effect, ...]:  # noqa: A001 - the registry's own vocabulary (effects.registry.all())
    """Every effect, in catalogue order."""
    return tuple(_catalogue().values())


def names(effects: Iterable[Effect] | None = None) -> tuple[str, ...]:
    """The names of ``effects`` (default: every effect), in catalogue order."""
    return tuple(e.name for e in (all() if effects is None else effects))


def candidates() -> tuple[Effect, ...]:
    """The candidate effects (every effect but those the pipeline identifies on its own), in catalogue order."""
    return where(lambda e: e.candidate)


def get(name: str) -> Effect:
    """The effect called ``name``; KeyError naming the known ones otherwise."""
    try:
        return _catalogue()[name]
    except KeyError:
        raise KeyError(f"unknown effect {name!r}; known: {', '.join(_catalogue())}") from None


def forms(name: str) -> Forms | None:
    """The regressor forms an effect module holds (``FORMS``; a linear-route effect), or None."""
    get(name)
    return _FORMS.get(name)


def known(name: str) -> bool:
    return name in _catalogue()


def where(test: Callable[[Effect], bool]) -> tuple[Effect, ...]:
    """The effects for which ``test(effect)`` holds, in catalogue order."""
    return tuple(e for e in all() if test(e))


def one(test: Callable[[Effect], bool]) -> Effect:
    """The single effect with a facet (e.g. ``one(lambda e: e.route is Route.VOLTAGE_LIMIT)``)."""
    hits = where(test)
    if len(hits) != 1:
        raise LookupError(f"expected one effect, found {len(hits)}: {names(hits)}")
    return hits[0]


def by_route(route: Route) -> tuple[Effect, ...]:
    return where(lambda e: e.route is route)


def by_param(param: str) -> tuple[Effect, ...]:
    """The effects reporting a parameter called ``param``."""
    return where(lambda e: any(p.name == param for p in e.params))


def by_field(field: str) -> tuple[Effect, ...]:
    """The effects writing the parameter-file field ``field``."""
    return where(lambda e: any(p.field == field for p in e.params))


def torque_scale() -> Effect:
    """The effect whose ratio scales the torque side (the torque constant)."""
    return one(lambda e: e.torque_scale)


def is_special(name: str) -> bool:
    return get(name).special
