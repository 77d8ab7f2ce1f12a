"""The actuator model under MuJoCo bodies (issue #17): :class:`CoupledSim` steps an MJCF model and one actuator
per named hinge/slide joint in lock-step; :mod:`.export` writes the closest MuJoCo ``<dcmotor>`` for a parameter
file and compares the two. Needs the ``mujoco`` extra (``pip install .[mujoco]``). See docs/mujoco.md.

The names below load on first use, so ``bldc-actuator --help`` works without MuJoCo installed.
"""

from __future__ import annotations

__all__ = ["CoupledSim", "CoupledLedger", "JointState"]


def __getattr__(name: str):
    if name in __all__:
        from . import coupling

        return getattr(coupling, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
