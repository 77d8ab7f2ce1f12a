"""The registry: the one way the diagnosis knows an effect (issue #24).

Every module of this package except :mod:`.record` and this one is an effect module holding ``EFFECT``; they are
found by name (:func:`pkgutil.iter_modules`), so adding an effect is adding one file (docs/effects.md). Lookups
by name (:func:`get`), in catalogue order (:func:`all`, :func:`names`) and by facet (:func:`where`,
:func:`by_param`, :func:`by_field`, :func:`torque_scale`, :func:`one`). :func:`add_path` lets the registry find
effect modules in a directory outside the package too (a plug-in file, written exactly as a module of this package)."""

from __future__ import annotations

import functools
import importlib
import os
import pkgutil
import sys
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


def add_path(path) -> None:
    """Find effect modules in the directory ``path`` as well: each ``<effect>.py`` there is read as a module of this
    package (its relative imports, ``from .record import Effect``, ``from .forms import Forms``, work as in the
    package), beside the package's own. The catalogue is read again; a duplicate name or rank is an error then."""
    from . import __path__ as here

    d = os.fspath(path)
    if not os.path.isdir(d):
        raise NotADirectoryError(f"effect plug-in path: expected a directory of effect modules, got {d!r}")
    if d not in here:
        here.append(d)
    _reset()


def remove_path(path) -> None:
    """Stop finding effect modules in ``path`` (:func:`add_path`); the catalogue is read again."""
    from . import __path__ as here, __name__ as pkg

    d = os.fspath(path)
    if d in here:
        here.remove(d)
        for name in [m for m, mod in sys.modules.items() if m.startswith(pkg + ".")
                     and os.path.dirname(getattr(mod, "__file__", "") or "") == d]:
            del sys.modules[name]
    _reset()


def _reset() -> None:
    _catalogue.cache_clear()
    _FORMS.clear()


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
