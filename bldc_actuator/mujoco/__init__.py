"""The actuator model under MuJoCo bodies (issue #17): :class:`CoupledSim` steps an MJCF model and one actuator
per named hinge/slide joint in lock-step; :mod:`.export` writes the closest MuJoCo ``<dcmotor>`` for a parameter
file and compares the two. Needs the ``mujoco`` extra (``pip install .[mujoco]``). See docs/mujoco.md.
"""

from .coupling import CoupledLedger, CoupledSim, JointState

__all__ = ["CoupledSim", "CoupledLedger", "JointState"]
