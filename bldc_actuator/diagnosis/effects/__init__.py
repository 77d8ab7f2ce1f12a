"""The diagnosis's effects as plugins (issue #24): one module per effect, each holding ``EFFECT``, an
:class:`~.record.Effect`; :mod:`.registry` is how the rest of the diagnosis knows them. See docs/effects.md."""

from . import registry
from .record import Bounds, Effect, Param, Route, Story, WriteBack

__all__ = ["Bounds", "Effect", "Param", "Route", "Story", "WriteBack", "registry"]
