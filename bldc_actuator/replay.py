"""Re-simulate a run of ``actuator_node`` from its MCAP recording alone.

The node records (see :mod:`bldc_actuator.node`): the parameters at the start (first ``bldc_actuator``
metadata record), every command it received with the simulation time it was applied at as log time,
``~/load_torque`` and ``~/reset_fault`` messages, runtime parameter changes on ``/parameter_events``, and
everything it published. Replaying the inputs through a fresh :class:`Actuator` at the recorded times
reproduces the recorded outputs (same arithmetic, same order) — a check that a recording is complete.

The node's command watchdog is replayed too (``node.watchdog_timeout``); lock-step and free-running runs
replay the same way, because the node applies inputs between whole publish periods.
"""

from __future__ import annotations

import math
from typing import Any

from .model import Actuator
from .params import SPECS, from_flat

COMMAND_SUFFIXES = {"/current_command": "current", "/torque_command": "torque", "/commands": "commands"}


def _initial_parameters(recording) -> dict[str, Any]:
    from .recording import PARAMETERS_KEY, parameters_from_yaml

    for name, data in recording.metadata_records:
        if name == "bldc_actuator" and PARAMETERS_KEY in data:
            return parameters_from_yaml(data[PARAMETERS_KEY])
    if recording.parameters is None:
        raise ValueError("recording holds no parameters")
    return dict(recording.parameters)


def _parameter_value(msg) -> Any:
    from rclpy.parameter import parameter_value_to_python

    return parameter_value_to_python(msg.value)


def resimulate(recording, joint_states_topic: str | None = None) -> list[tuple[int, dict]]:
    """Replay ``recording`` (a :class:`bldc_actuator.recording.Recording`); return ``[(t_ns, outputs)]``
    at every recorded joint_states stamp (``outputs`` as :meth:`Actuator.outputs`)."""
    flat = _initial_parameters(recording)
    model = {k: v for k, v in flat.items() if k in SPECS}
    params = from_flat(model)
    watchdog_ns = int(round(float(flat.get("node.watchdog_timeout", 0.0)) * 1e9))
    interface = flat.get("node.commands_interface", "effort")
    act = Actuator(params)
    if joint_states_topic is None:
        joint_states_topic = next(t for t, ty in recording.types.items() if ty == "sensor_msgs/msg/JointState")
    events: list[tuple[int, int, str, Any]] = []   # (t_ns, order, kind, payload)
    order = 0
    for topic, msgs in recording.topics.items():
        kind = None
        for suffix, k in COMMAND_SUFFIXES.items():
            if topic.endswith(suffix):
                kind = k
        if topic.endswith("/load_torque"):
            kind = "load"
        elif topic.endswith("/reset_fault"):
            kind = "reset"
        elif topic == "/parameter_events":
            kind = "params"
        if kind is None:
            continue
        for t, m in msgs:
            events.append((t, order, kind, m))
            order += 1
    events.sort(key=lambda e: (e[0], e[1]))
    stamps = [t for t, _ in recording.topics.get(joint_states_topic, [])]
    out: list[tuple[int, dict]] = []
    last_cmd: int | None = None
    watchdog = False
    i = 0
    for target in stamps:
        while act.t_ns < target or (i < len(events) and events[i][0] <= act.t_ns):
            while i < len(events) and events[i][0] <= act.t_ns:
                t, _, kind, m = events[i]
                i += 1
                if kind in ("current", "torque", "commands"):
                    if kind == "commands":
                        if len(m.data) != 1:
                            continue
                        value, kind = float(m.data[0]), ("torque" if interface == "effort" else "current")
                    else:
                        value = m.data
                    limit = 10.0 * act.params.drive.current_limit
                    if kind == "torque":
                        limit *= act.params.motor.torque_constant_q * act.params.gear.gear_ratio
                    if not math.isfinite(value) or abs(value) > limit:
                        continue
                    (act.set_current_command if kind == "current" else act.set_torque_command)(value)
                    last_cmd, watchdog = act.t_ns, False
                elif kind == "load":
                    if math.isfinite(m.data):
                        act.set_load_torque(m.data)
                elif kind == "reset":
                    act.reset_fault()
                elif kind == "params":
                    changes = {p.name: _parameter_value(p) for p in m.changed_parameters}
                    model_changes = {k: v for k, v in changes.items() if k in SPECS}
                    if model_changes:
                        act.update_params(from_flat(model_changes, base=act.params))
                    if "node.watchdog_timeout" in changes:
                        watchdog_ns = int(round(changes["node.watchdog_timeout"] * 1e9))
                    if "node.commands_interface" in changes:
                        interface = changes["node.commands_interface"]
            if act.t_ns >= target:
                break
            if watchdog_ns > 0 and last_cmd is not None and not watchdog and act.t_ns - last_cmd >= watchdog_ns:
                watchdog = True
                act.set_current_command(0.0)
            act.step_ns(target - act.t_ns)   # stamps are one publish period apart: the node's own steps
        out.append((act.t_ns, act.outputs()))
    return out

