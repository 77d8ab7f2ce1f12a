"""The recording's joints matched to the MJCF's joints by name, with a rename map where they differ."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping

import mujoco

#: joint types with one axis (a coupled actuator's joint)
AXIAL = {int(mujoco.mjtJoint.mjJNT_HINGE): "hinge", int(mujoco.mjtJoint.mjJNT_SLIDE): "slide"}


@dataclass(frozen=True)
class JointMatch:
    """One recorded joint and the MJCF joint it drives."""

    recording: str      #: the joint's name in the recording (``joint0``, ``FL_knee``...)
    model: str          #: the MJCF joint's name
    joint_id: int
    dof: int            #: its index in ``qvel`` / ``qfrc_*``
    qpos: int           #: its index in ``qpos``
    kind: str           #: "hinge" | "slide"


@dataclass(frozen=True)
class JointMap:
    """Every recorded joint's MJCF joint, in the recording's order, and the model's joints no recording drives
    (held at the model's reference pose ``qpos0``, at rest)."""

    joints: tuple[JointMatch, ...]
    unrecorded: tuple[str, ...]

    @property
    def recording_names(self) -> list[str]:
        return [j.recording for j in self.joints]

    def to_dict(self) -> dict:
        return {"joints": {j.recording: j.model for j in self.joints}, "unrecorded_model_joints": list(self.unrecorded)}


def parse_joint_map(items: str | Iterable[str] | None) -> dict[str, str]:
    """``"a=b,c=d"`` (or a list of ``a=b``) -> ``{recording name: MJCF joint name}``."""
    if items is None:
        return {}
    parts = items.split(",") if isinstance(items, str) else [p for s in items for p in str(s).split(",")]
    out: dict[str, str] = {}
    for part in parts:
        part = part.strip()
        if not part:
            continue
        a, sep, b = part.partition("=")
        if not sep or not a.strip() or not b.strip():
            raise ValueError(f"--joint-map: expected RECORDING_JOINT=MJCF_JOINT entries separated by commas, got "
                             f"{part!r}")
        if a.strip() in out:
            raise ValueError(f"--joint-map: recording joint {a.strip()!r} is mapped twice")
        out[a.strip()] = b.strip()
    return out


def model_joints(model: mujoco.MjModel) -> list[str]:
    return [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}" for j in range(model.njnt)]


def match(recording_joints: Iterable[str], model: mujoco.MjModel,
          rename: Mapping[str, str] | None = None) -> JointMap:
    """Match each recorded joint to the MJCF joint of the same name, or of the name ``rename`` gives it.

    Raises ValueError naming the joint: a rename of a joint the recording does not hold, a name the model does
    not hold (with the model's joints), a joint that is not a hinge or slide, two recorded joints on one MJCF
    joint."""
    recorded = list(recording_joints)
    rename = dict(rename or {})
    unknown = [a for a in rename if a not in recorded]
    if unknown:
        raise ValueError(f"--joint-map: no joint {', '.join(map(repr, unknown))} in the recording (it holds: "
                         f"{', '.join(recorded)})")
    have = model_joints(model)
    out, used = [], {}
    for name in recorded:
        target = rename.get(name, name)
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, target)
        if jid < 0:
            hint = "" if name in rename else " (name it with --joint-map RECORDING_JOINT=MJCF_JOINT)"
            raise ValueError(f"joint {name!r}: the MJCF model has no joint {target!r}{hint}; its joints: "
                             f"{', '.join(have)}")
        kind = AXIAL.get(int(model.jnt_type[jid]))
        if kind is None:
            raise ValueError(f"joint {name!r}: MJCF joint {target!r} is not a hinge or slide (type "
                             f"{int(model.jnt_type[jid])}): an actuator drives one axis")
        if target in used:
            raise ValueError(f"joint {name!r}: MJCF joint {target!r} is already matched to recorded joint "
                             f"{used[target]!r}")
        used[target] = name
        out.append(JointMatch(name, target, int(jid), int(model.jnt_dofadr[jid]), int(model.jnt_qposadr[jid]), kind))
    rest = tuple(n for n in have if n not in used)
    return JointMap(tuple(out), rest)
