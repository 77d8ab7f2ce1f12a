"""A Foxglove layout for the topics and joints one recording holds.

The shipped ``config/foxglove/actuator.json`` fits a single-joint node under its default name. A robot
recording (``joints`` given: per-joint topics under ``~/<joint>/``), another node name or namespace, or a
remapped ``joint_states`` needs its own: :func:`layout_for_recording` reads the file's channels (and the
first message of ``joint_states`` and of each ``q_axis_state`` for the joint order and the element labels)
and places only panels whose every path names a topic that is in the file. ``bldc-actuator record-info FILE
--foxglove-layout OUT.json`` writes it.

Per joint: output position/velocity and effort (``joint_states`` at the joint's index, with its commands),
q-axis currents and the voltage against the SVPWM limit (``q_axis_state`` elements found by their layout
labels), phase currents, temperatures; one tab per joint for a robot. Beside them: ``/diagnostics``.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

from .reader import read_raw, summarize

FLOAT64_ARRAY = "std_msgs/msg/Float64MultiArray"
FLOAT64 = "std_msgs/msg/Float64"
JOINT_STATE = "sensor_msgs/msg/JointState"
TEMPERATURE = "sensor_msgs/msg/Temperature"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
#: per-joint topic suffixes of actuator_node (``~/<suffix>`` or ``~/<joint>/<suffix>``) and their types
JOINT_TOPICS = {"q_axis_state": FLOAT64_ARRAY, "phase_currents": FLOAT64_ARRAY, "winding_temperature": TEMPERATURE,
                "housing_temperature": TEMPERATURE, "torque_command": FLOAT64, "current_command": FLOAT64}
#: q_axis_state elements plotted, by layout label: (panel, label, legend)
Q_PANELS = {"current": ("i_q", "i_d", "i_q_ref"), "voltage": ("v_magnitude_q", "v_limit_q")}


@dataclass
class JointTopics:
    """What one joint has in a recording (topic names as recorded; None where the file has no such topic)."""

    name: str                                   #: joint name ("" when the recording does not say)
    prefix: str                                 #: topic prefix, e.g. ``/bldc_actuator/knee``
    topics: dict[str, str] = field(default_factory=dict)   #: suffix -> topic, e.g. ``q_axis_state``
    q_labels: list[str] = field(default_factory=list)      #: q_axis_state layout labels (first message)
    joint_states_index: int | None = None      #: the joint's index in joint_states
    commands_index: int | None = None          #: the joint's element of ``~/commands``


@dataclass
class RecordingTopics:
    """The joints and shared topics of a recording, as the layout uses them."""

    joints: list[JointTopics]
    joint_states: str | None
    commands: str | None
    diagnostics: str | None
    channels: dict[str, str]                    #: every topic of the file -> type
    notes: list[str] = field(default_factory=list)


def _first_messages(path: Path, topics: Iterable[str]) -> dict[str, Any]:
    """The first decoded message (mcap_ros2, pure Python) of each of ``topics``; {} for what cannot be read."""
    wanted = set(topics)
    out: dict[str, Any] = {}
    if not wanted:
        return out
    try:
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory

        with open(path, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _schema, channel, _message, decoded in reader.iter_decoded_messages(topics=sorted(wanted)):
                out.setdefault(channel.topic, decoded)
                if len(out) == len(wanted):
                    break
        return out
    except Exception:  # noqa: BLE001 - an unfinalized or odd file: the record walker below reads it
        pass
    try:
        from mcap_ros2.decoder import DecoderFactory

        raw = read_raw(path, topics=wanted)
        factory = DecoderFactory()
        for cid, msgs in raw.messages.items():
            channel = raw.channels[cid]
            schema = raw.schemas.get(channel.schema_id)
            if msgs and schema is not None and schema.encoding:
                out[channel.topic] = factory.decoder_for(channel.message_encoding, schema)(min(msgs)[1])
    except Exception:  # noqa: BLE001 - labels and names then stay unknown (said in notes)
        pass
    return out


def _labels(msg: Any) -> list[str]:
    dims = getattr(getattr(msg, "layout", None), "dim", None) or []
    return [s.strip() for s in dims[0].label.split(",")] if dims and dims[0].label else []


def recording_topics(path) -> RecordingTopics:
    """Find the joints, their topics, the q_axis_state labels and joint order in the recording ``path``."""
    summary = summarize(path)
    channels = {t: info["type"] for t, info in summary["topics"].items()}
    meta = summary["metadata"]
    notes: list[str] = []
    # per-joint topic groups: the prefix before a known suffix, where the type matches the node's
    groups: dict[str, dict[str, str]] = {}
    for topic, typ in channels.items():
        prefix, _, suffix = topic.rpartition("/")
        if JOINT_TOPICS.get(suffix) == typ and prefix:
            groups.setdefault(prefix, {})[suffix] = topic
    groups = {p: g for p, g in groups.items() if set(g) - {"torque_command", "current_command"}}
    states = sorted(t for t, ty in channels.items() if ty == JOINT_STATE and t.endswith("joint_states"))
    joint_states = states[0] if states else None
    if len(states) > 1:
        notes.append(f"several joint_states topics ({', '.join(states)}): plotting {joint_states}")
    commands = next((t for t, ty in sorted(channels.items()) if ty == FLOAT64_ARRAY and t.endswith("/commands")), None)
    diagnostics = next((t for t, ty in sorted(channels.items()) if ty == DIAGNOSTICS), None)
    first = _first_messages(Path(path), [t for g in groups.values() if "q_axis_state" in g
                                         for t in [g["q_axis_state"]]] + ([joint_states] if joint_states else []))
    state_names = list(getattr(first.get(joint_states), "name", []) or []) if joint_states else []
    meta_joints = [j for j in str(meta.get("joints", "")).split(",") if j]
    order = meta_joints or state_names
    joints: list[JointTopics] = []
    for prefix, group in groups.items():
        last = prefix.rpartition("/")[2]
        if len(groups) > 1 or last in order and len(order) > 1:
            name = last
        else:
            name = meta.get("joint_name") or (order[0] if len(order) == 1 else "")
        jt = JointTopics(name=name, prefix=prefix, topics=dict(group))
        if "q_axis_state" in group:
            jt.q_labels = _labels(first.get(group["q_axis_state"]))
            if not jt.q_labels:
                notes.append(f"{group['q_axis_state']}: no labelled message in the file, its current and "
                             "voltage panels are left out")
        if state_names and name in state_names:
            jt.joint_states_index = state_names.index(name)
        elif len(groups) == 1 and len(state_names) == 1:
            jt.joint_states_index = 0
        elif joint_states:
            notes.append(f"joint {name or prefix!r} is not named in the first {joint_states} message: "
                         "its position/velocity/effort panels are left out")
        if commands:
            if name in order:
                jt.commands_index = order.index(name)
            elif len(groups) == 1:
                jt.commands_index = 0
        joints.append(jt)
    rank = {n: k for k, n in enumerate(order)}
    joints.sort(key=lambda j: (rank.get(j.name, len(rank)), j.prefix))
    if not joints:
        notes.append("no actuator_node joint topics (q_axis_state, phase_currents, temperatures) in the file")
    return RecordingTopics(joints, joint_states, commands, diagnostics, channels, notes)


# -------------------------------------------------------------------------------------------- the layout

def _path(value: str, label: str, header: bool) -> dict[str, Any]:
    return {"value": value, "enabled": True, "timestampMethod": "headerStamp" if header else "receiveTime",
            "label": label}


def _plot(title: str, paths: list[dict]) -> dict[str, Any]:
    return {"title": title, "paths": paths, "showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True,
            "legendDisplay": "floating", "showPlotValuesInLegend": True, "isSynced": True,
            "xAxisVal": "timestamp", "sidebarDimension": 240}


def _grid(ids: list[str]) -> Any:
    """A mosaic of panel ids: pairs side by side, the rows stacked (equal heights)."""
    rows = [{"direction": "row", "first": ids[k], "second": ids[k + 1]} if k + 1 < len(ids) else ids[k]
            for k in range(0, len(ids), 2)]

    def stack(items: list) -> Any:
        if len(items) == 1:
            return items[0]
        half = len(items) // 2
        return {"direction": "column", "splitPercentage": round(100 * half / len(items), 1),
                "first": stack(items[:half]), "second": stack(items[half:])}

    return stack(rows) if rows else None


def _joint_panels(rt: RecordingTopics, jt: JointTopics, tag: str) -> dict[str, dict]:
    who = f"{jt.name}: " if len(rt.joints) > 1 and jt.name else ""
    t = jt.topics
    panels: dict[str, dict] = {}
    js, k = rt.joint_states, jt.joint_states_index
    if js and k is not None:
        panels[f"Plot!position{tag}"] = _plot(f"{who}output position / velocity [rad, rad/s]", [
            _path(f"{js}.position[{k}]", "position", True), _path(f"{js}.velocity[{k}]", "velocity", True)])
    effort = []
    if js and k is not None:
        effort.append(_path(f"{js}.effort[{k}]", "effort", True))
    if "torque_command" in t:
        effort.append(_path(f"{t['torque_command']}.data", "torque_command", False))
    if rt.commands and jt.commands_index is not None:
        effort.append(_path(f"{rt.commands}.data[{jt.commands_index}]", f"commands[{jt.commands_index}]", False))
    if effort:
        panels[f"Plot!effort{tag}"] = _plot(f"{who}effort [N*m] and commands", effort)
    q, labels = t.get("q_axis_state"), jt.q_labels
    for panel, names in Q_PANELS.items():
        found = [(n, labels.index(n)) for n in names if q and n in labels]
        paths = [_path(f"{q}.data[{i}]", n, False) for n, i in found]
        if panel == "current" and "current_command" in t:
            paths.append(_path(f"{t['current_command']}.data", "current_command", False))
        if paths:
            what = ", ".join(f"{n} = element {i}" for n, i in found)
            title = ("q-axis current [A]" if panel == "current" else "voltage [V]: |v_dq| vs the SVPWM limit")
            panels[f"Plot!{panel}{tag}"] = _plot(f"{who}{title} ({what} of ~/q_axis_state)" if what else
                                                 f"{who}{title}", paths)
    if "phase_currents" in t:
        panels[f"Plot!phase{tag}"] = _plot(f"{who}phase currents [A]", [
            _path(f"{t['phase_currents']}.data[{i}]", f"i_phase_{c}", False) for i, c in enumerate("abc")])
    temps = [_path(f"{t[s]}.temperature", s.split("_")[0], True) for s in ("winding_temperature", "housing_temperature")
             if s in t]
    if temps:
        panels[f"Plot!temperature{tag}"] = _plot(f"{who}temperatures [degC]", temps)
    return panels


def layout(rt: RecordingTopics) -> dict[str, Any]:
    """The Foxglove layout (JSON-ready dict) for :func:`recording_topics`' result."""
    config: dict[str, dict] = {}
    per_joint: list[tuple[str, list[str]]] = []
    for n, jt in enumerate(rt.joints):
        tag = f"-{re.sub(r'[^A-Za-z0-9_]', '_', jt.name or str(n))}" if len(rt.joints) > 1 else ""
        panels = _joint_panels(rt, jt, tag)
        config.update(panels)
        if panels:
            per_joint.append((jt.name or jt.prefix, list(panels)))
    if len(per_joint) > 1:
        config["Tab!joints"] = {"activeTabIdx": 0,
                                "tabs": [{"title": name, "layout": _grid(ids)} for name, ids in per_joint]}
        main: Any = "Tab!joints"
    else:
        main = _grid(per_joint[0][1]) if per_joint else None
    side = None
    if rt.diagnostics:
        config["DiagnosticSummary!diagnostics"] = {"topicToRender": rt.diagnostics, "minLevel": 0, "pinnedIds": [],
                                                   "hardwareIdFilter": "", "sortByLevel": True}
        config["RawMessages!diagnostics"] = {"topicPath": rt.diagnostics, "diffEnabled": False,
                                             "diffMethod": "custom", "diffTopicPath": "",
                                             "showFullMessageForDiff": False}
        side = {"direction": "column", "first": "DiagnosticSummary!diagnostics", "second": "RawMessages!diagnostics"}
    if main is not None and side is not None:
        mosaic: Any = {"direction": "row", "splitPercentage": 70, "first": main, "second": side}
    else:
        mosaic = main if main is not None else side
    return {"configById": config, "globalVariables": {}, "userNodes": {}, "linkedGlobalVariables": [],
            "playbackConfig": {"speed": 1}, "layout": mosaic}


def layout_for_recording(path) -> tuple[dict[str, Any], RecordingTopics]:
    """(layout, what was found) for the recording ``path``."""
    rt = recording_topics(path)
    return layout(rt), rt


def referenced_topics(doc: Mapping[str, Any]) -> set[str]:
    """Every topic a layout's panels read (plot paths, ``topicPath``, ``topicToRender``). ROS topic names hold
    no ``.``: a message path's topic is the text before its first ``.`` (or ``{`` filter)."""
    refs: list[str] = []
    for cfg in doc.get("configById", {}).values():
        refs += [p["value"] for p in cfg.get("paths", [])]
        refs += [cfg[k] for k in ("topicPath", "topicToRender") if cfg.get(k)]
    return {re.split(r"[.{\[]", ref, maxsplit=1)[0] for ref in refs}


def write_layout(recording_path, out_path) -> RecordingTopics:
    """Write the layout of ``recording_path`` to ``out_path`` (JSON); return what was found."""
    doc, rt = layout_for_recording(recording_path)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=2) + "\n")
    return rt
