"""ROS parameters of ``actuator_node``: model parameters generated from :data:`params.SPECS` plus the
node's own ``node.*`` parameters, with descriptors (description + unit, range, read-only).

Split from :mod:`bldc_actuator.node` so that the mapping SPECS -> ROS is one small, testable job.
Needs rclpy (rcl_interfaces); the physics modules do not.

Rules
-----
* every parameter is declared with a default in code: the node runs without any parameter file;
* ``preset`` (read-only string) names a preset (``ak80_9``) or a YAML path whose model values become the
  defaults; a parameter file or ``-p`` overrides still win over the preset;
* a ``datasheet`` block in a parameter file (``datasheet.kv``, ...) is converted to ``motor.*`` defaults
  the same way :func:`params.params_from_dict` does (explicit ``motor.*`` values win);
* parameters that are not ``runtime`` in SPECS are ``read_only``: ROS rejects changing them while running;
* an integer written where a double is expected (``bus_voltage: 48``) is accepted as ``48.0``;
* an unknown parameter is an error naming the nearest known one (typos must not pass silently), except
  ROS's own (``use_sim_time``, ``qos_overrides.*``, ``start_type_description_service``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.parameter import Parameter

from . import params as P

INF = math.inf

#: parameter holding the preset name or path (read-only)
PRESET = "preset"


@dataclass(frozen=True)
class NodeParam:
    """One ``node.*`` parameter (same fields as :class:`params.ParameterSpec` where they apply)."""

    name: str
    type: type
    default: Any
    unit: str
    description: str
    range: tuple[float, float] = (-INF, INF)
    runtime: bool = False
    choices: tuple = ()


#: the node's own parameters; ``runtime`` ones may change while running
NODE_PARAMS: dict[str, NodeParam] = {p.name: p for p in (
    NodeParam("node.publish_rate", float, 1000.0, "Hz", "rate (per second of SIMULATION time) of joint_states, "
              "phase currents, temperatures and q-axis state; in lock-step mode the control period is "
              "1/publish_rate", (1.0, 100000.0)),
    NodeParam("node.time_factor", float, 1.0, "", "simulation seconds per wall second: 1 = real time, 10 = ten "
              "times faster, 0 or .inf = as fast as possible", (0.0, INF), runtime=True),
    NodeParam("node.lock_step", bool, False, "", "advance exactly one control period (1/publish_rate) per "
              "received command instead of following the wall clock (controller testing)"),
    NodeParam("node.publish_clock", bool, False, "", "publish /clock (rosgraph_msgs/Clock) with the simulation "
              "time so that nodes with use_sim_time follow this actuator"),
    NodeParam("node.watchdog_timeout", float, 0.5, "s", "simulation seconds without a command after which the "
              "command drops to zero current (0 disables)", (0.0, 1e6), runtime=True),
    NodeParam("node.joint_name", str, "joint", "", "joint name in joint_states and frame_id of the headers"),
    NodeParam("node.commands_interface", str, "effort", "", "meaning of ~/commands (ros2_control "
              "ForwardCommandController): effort = output torque [N*m], current = q-axis current [A]",
              runtime=True, choices=("effort", "current")),
    NodeParam("node.record", str, "", "", "MCAP file to record to (commands received, everything published, "
              "parameters); empty = no recording"),
    NodeParam("node.diagnostics_rate", float, 10.0, "Hz", "rate (per second of simulation time) of "
              "/diagnostics", (0.01, 1000.0)),
    NodeParam("node.max_sim_time", float, 0.0, "s", "stop (and finish the recording) after this much "
              "simulation time; 0 = run until shut down", (0.0, 1e9)),
    NodeParam("node.joint_states_topic", str, "joint_states", "", "topic of the sensor_msgs/JointState with "
              "every joint (ros2_control's topic_based hardware interface reads /robot_joint_states)"),
    NodeParam("node.joint_commands_topic", str, "~/joint_commands", "", "topic of sensor_msgs/JointState "
              "commands, joints matched by name, effort = output torque [N*m] (ros2_control's topic_based "
              "hardware interface publishes /robot_joint_command); empty = off"),
    NodeParam("node.detail_rate", float, 0.0, "Hz", "rate (per second of simulation time) of the per-joint "
              "~/[<joint>/]q_axis_state, phase_currents and temperatures; 0 = every publish period (published on "
              "demand: only while subscribed, and always while recording)",
              (0.0, 100000.0)),
    NodeParam("node.joint_topics", str, "auto", "", "when the per-joint topics (~/[<joint>/]current_command, "
              "torque_command, load_torque, reset_fault and the four detail topics) exist: always = from the start; "
              "on_demand = a command subscription once a publisher on its topic appears, a detail publisher once "
              "a subscriber appears (graph checked every second; kept from then on); auto = always for one joint, "
              "on_demand with joints given. Recording always creates them all",
              choices=("auto", "always", "on_demand")),
)}

#: list of joint names (string array, top level): ``-p joints:="[hip, knee, ankle]"``; empty = one joint
#: (``node.joint_name``) with the single-actuator topic names
JOINTS = "joints"
#: per-joint parameters: ``joint.<name>.preset``, ``joint.<name>.params_file``, ``joint.<name>.<model param>``
JOINT_PREFIX = "joint."

#: an MJCF model whose joints the actuators drive (bldc_actuator.mujoco.CoupledSim); empty = actuators alone
MUJOCO_MODEL = "mujoco.model"

#: overrides that are neither model nor node parameters but legitimate (ROS itself)
_FOREIGN_OK_PREFIXES = ("use_sim_time", "qos_overrides.", "start_type_description_service")


def _range_text(lo, hi, lo_open=False) -> str:
    if lo == -INF and hi == INF:
        return ""
    left = "(" if lo_open else "["
    return f"range {left}{lo:g}, {hi:g}]"


def describe(spec, *, runtime: bool) -> ParameterDescriptor:
    """Descriptor for a :class:`params.ParameterSpec` or :class:`NodeParam`: description with unit and range,
    numeric range, ``read_only`` unless ``runtime``."""
    unit = f" [{spec.unit}]" if spec.unit else ""
    extras = [t for t in (_range_text(*spec.range, getattr(spec, "lo_open", False))
                          if spec.type in (int, float) else "",
                          f"one of: {', '.join(spec.choices)}" if spec.choices else "",
                          "changeable at run time" if runtime else
                          "read-only while running (set it in a parameter file or with -p)") if t]
    d = ParameterDescriptor(description=f"{spec.description}{unit}; " + "; ".join(extras),
                            read_only=not runtime)
    d.type = ros_type(spec.type).value
    # the enforced range is the field's PHYSICAL limits (its usual range, in the description, is a sanity limit:
    # a value a real system has must load, issue #14)
    lo, hi = getattr(spec, "limits", spec.range)[:2]
    if spec.type is float and math.isfinite(lo) and math.isfinite(hi):
        d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    elif spec.type is int and math.isfinite(lo) and math.isfinite(hi):
        d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
    if spec.choices:
        d.additional_constraints = "one of: " + ", ".join(spec.choices)
    return d


def ros_type(t: type) -> Parameter.Type:
    return {bool: Parameter.Type.BOOL, int: Parameter.Type.INTEGER, float: Parameter.Type.DOUBLE,
            str: Parameter.Type.STRING, tuple: Parameter.Type.DOUBLE_ARRAY}[t]


def to_ros(t: type, value: Any) -> Any:
    """Python value of a spec -> value rclpy accepts for that type."""
    if t is tuple:
        return [float(v) for v in value]
    if t is float:
        return float(value)
    return value


def from_ros(t: type, value: Any) -> Any:
    """Value read back from rclpy -> value :func:`params.from_flat` accepts."""
    if t is tuple:
        return tuple(float(v) for v in (value if value is not None else ()))
    return value


def _overrides(node) -> dict[str, Parameter]:
    # rclpy keeps parameter-file and -p values here until they are declared (no public accessor)
    return getattr(node, "_parameter_overrides", {}) or {}


def _coerce_override(node, name: str, t: type) -> None:
    """Accept an integer (or integer list) written where a double (list) is expected: 48 -> 48.0."""
    ov = _overrides(node)
    p = ov.get(name)
    if p is None:
        return
    if t is float and p.type_ == Parameter.Type.INTEGER:
        ov[name] = Parameter(name, Parameter.Type.DOUBLE, float(p.value))
    elif t is tuple and p.type_ == Parameter.Type.INTEGER_ARRAY:
        ov[name] = Parameter(name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in p.value])
    elif t is tuple and p.type_ in (Parameter.Type.DOUBLE, Parameter.Type.INTEGER):
        ov[name] = Parameter(name, Parameter.Type.DOUBLE_ARRAY, [float(p.value)])


def coerce_set(p: Parameter) -> Parameter:
    """A parameter set at run time (``ros2 param set ... drive.bus_voltage 48``): an integer (or integer list)
    for a double (list) becomes that double, as in a parameter file; anything else is returned unchanged (the
    type and range checks follow)."""
    spec = P.SPECS.get(p.name) or NODE_PARAMS.get(p.name)
    if spec is None:
        return p
    if spec.type is float and p.type_ == Parameter.Type.INTEGER:
        return Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
    if spec.type is tuple and p.type_ == Parameter.Type.INTEGER_ARRAY:
        return Parameter(p.name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in p.value])
    return p


def type_error(p: Parameter) -> str | None:
    """The error for a run-time value of the wrong type, naming the field, its type, range and unit; None when
    the type fits (rclpy's own text says only "expected 'Type.DOUBLE' got 'Type.STRING'")."""
    spec = P.SPECS.get(p.name) or NODE_PARAMS.get(p.name)
    if spec is None or p.type_ == ros_type(spec.type):
        return None
    lo, hi = getattr(spec, "limits", spec.range)[:2]
    rng = f" in [{lo:g}, {hi:g}]" if spec.type in (int, float) and (math.isfinite(lo) or math.isfinite(hi)) else ""
    unit = f" [{spec.unit}]" if spec.unit else ""
    return (f"{p.name}: expected a {ros_type(spec.type).name.lower()}{rng}{unit}, got {p.value!r} "
            f"({p.type_.name.lower()})")


def _declare(node, name: str, t: type, default: Any, descriptor: ParameterDescriptor, unit: str) -> Any:
    _coerce_override(node, name, t)
    try:
        if t is tuple and not default:
            p = node.declare_parameter(name, Parameter.Type.DOUBLE_ARRAY, descriptor)  # empty list: type only
        else:
            p = node.declare_parameter(name, to_ros(t, default), descriptor)
    except InvalidParameterTypeException as exc:
        raise P.ParameterError(name, f"wrong type: expected {ros_type(t).name.lower()}"
                               f"{f' [{unit}]' if unit else ''} ({exc})") from None
    except InvalidParameterValueException:
        given = _overrides(node).get(name)
        shown = given.value if given is not None else default
        lo, hi = (descriptor.floating_point_range[0].from_value, descriptor.floating_point_range[0].to_value) \
            if descriptor.floating_point_range else (descriptor.integer_range[0].from_value,
                                                     descriptor.integer_range[0].to_value) \
            if descriptor.integer_range else (-INF, INF)
        raise P.ParameterError(name, f"{shown!r} is outside [{lo:g}, {hi:g}] {unit}".rstrip()) from None
    return from_ros(t, p.value)


def declare_all(node) -> tuple[P.ActuatorParams, dict[str, Any], str]:
    """Declare ``preset``, every model parameter and every ``node.*`` parameter on ``node``.

    Returns ``(actuator_params, node_values, preset)``. Raises :class:`params.ParameterError` naming the
    field for a bad value, a bad preset or an unknown parameter in a model section / under ``node.``.
    """
    preset = node.declare_parameter(
        PRESET, "", ParameterDescriptor(
            description="preset name (e.g. ak80_9; see config/) or path of a parameter file whose model "
                        "values become the defaults; parameter-file / -p values still win; read-only",
            read_only=True)).value
    base = P.load_preset(preset) if preset else P.ActuatorParams()
    defaults = P.to_flat(base)
    datasheet = {k.split(".", 1)[1]: p.value for k, p in _overrides(node).items() if k.startswith("datasheet.")}
    if datasheet:
        for key, value in P.motor_from_datasheet(datasheet).items():
            defaults[key] = value
    flat: dict[str, Any] = {}
    for name, spec in P.SPECS.items():
        flat[name] = _declare(node, name, spec.type, defaults[name], describe(spec, runtime=spec.runtime),
                              spec.unit)
    node_values: dict[str, Any] = {}
    for name, spec in NODE_PARAMS.items():
        value = _declare(node, name, spec.type, spec.default, describe(spec, runtime=spec.runtime), spec.unit)
        node_values[name] = check_node_value(name, value)
    node_values[MUJOCO_MODEL] = node.declare_parameter(MUJOCO_MODEL, "", ParameterDescriptor(
        description="MJCF file of a robot: its joints named in joints / joint.<name>.* are driven by the "
                    "actuators and MuJoCo integrates the bodies (needs the mujoco extra); read-only",
        read_only=True)).value
    for name in _overrides(node):
        if (node.has_parameter(name) or name.startswith("datasheet.") or name.startswith(_FOREIGN_OK_PREFIXES)
                or name.startswith(JOINT_PREFIX) or name == JOINTS):
            continue
        section = name.split(".", 1)[0]
        if section in P.SECTIONS or section == "node":
            known = sorted(P.SPECS) if section in P.SECTIONS else sorted(NODE_PARAMS)
            raise P.ParameterError(name, "unknown parameter" + nearest_hint(name, known) + " (known in this section: "
                                   + ", ".join(k for k in known if k.startswith(section + ".")) + ")")
        raise P.ParameterError(name, "unknown parameter" + nearest_hint(name, _known_names()))
    return P.from_flat(flat), node_values, preset


def _known_names() -> list[str]:
    return [PRESET, JOINTS, MUJOCO_MODEL, *NODE_PARAMS, *P.SPECS]


def joint_names_in_overrides(node) -> list[str]:
    """The joint names of the ``joint.<name>.*`` overrides, in the order first given."""
    names: list[str] = []
    for key in _overrides(node):
        if key.startswith(JOINT_PREFIX) and key.count(".") >= 2:
            name = key.split(".")[1]
            if name not in names:
                names.append(name)
    return names


def nearest_hint(name: str, known: list[str]) -> str:
    """``"; did you mean 'preset'?"`` for the closest known name (or the known top-level names)."""
    import difflib

    close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    if close:
        return f"; did you mean {close[0]!r}?"
    top = sorted({k.split(".", 1)[0] + ("" if "." not in k else ".*") for k in known})
    return f" (known: {', '.join(top)}, joint.<name>.*)"


def check_node_value(name: str, value: Any) -> Any:
    """Range / choice check of a ``node.*`` value (rclpy checks numeric ranges too; this gives the unit)."""
    spec = NODE_PARAMS[name]
    if spec.choices and value not in spec.choices:
        raise P.ParameterError(name, f"expected one of {', '.join(spec.choices)}, got {value!r}")
    if spec.type is float:
        lo, hi = spec.range
        if math.isnan(value) or not (lo <= value <= hi):
            raise P.ParameterError(name, f"{value!r} is outside [{lo:g}, {hi:g}] {spec.unit}".rstrip())
    return value


def declare_joints(node, base: P.ActuatorParams, default_name: str,
                   default_names: list[str] | None = None) -> tuple[dict[str, P.ActuatorParams], bool]:
    """Declare ``joints`` and every ``joint.<name>.*`` parameter; return each joint's model parameters in
    ``joints`` order. A joint's parameters: its ``joint.<name>.preset`` or ``joint.<name>.params_file`` (a
    parameter YAML in the node's layout), else the node's own model parameters ``base``; then any
    ``joint.<name>.<model parameter>`` override (e.g. ``joint.knee.drive.bus_voltage``). ``joints`` not given:
    the joints ``default_names`` (a robot model's: those named in ``joint.<name>.*``), else one joint
    ``default_name``, with ``base``. Returns ``(params by joint, joints given explicitly)``. Raises
    :class:`params.ParameterError` naming the parameter."""
    ov = _overrides(node)
    given = ov.get(JOINTS)
    if given is not None and given.type_ == Parameter.Type.STRING and given.value:   # -p joints:=knee
        ov[JOINTS] = Parameter(JOINTS, Parameter.Type.STRING_ARRAY, [given.value])
    explicit = JOINTS in ov
    try:
        p = node.declare_parameter(JOINTS, list(default_names or [default_name]), ParameterDescriptor(
            description="joint names of this node, one simulated actuator each (e.g. [hip, knee, ankle]); "
                        "not given = one joint named node.joint_name with the single-actuator topic names; "
                        "read-only", read_only=True))
    except InvalidParameterTypeException as exc:
        raise P.ParameterError(JOINTS, f"wrong type: expected a list of joint names ({exc})") from None
    names = list(p.value or [])
    if not names:
        raise P.ParameterError(JOINTS, "expected at least one joint name")
    bad = [n for n in names if not n or not n.replace("_", "").isalnum() or not n[0].isalpha()]
    if bad or len(set(names)) != len(names):
        raise P.ParameterError(JOINTS, f"expected distinct names of letters, digits and '_' starting with a "
                               f"letter (they become topic names), got {names!r}")
    out: dict[str, P.ActuatorParams] = {}
    for name in names:
        prefix = f"{JOINT_PREFIX}{name}."
        mine = {k[len(prefix):]: v for k, v in ov.items() if k.startswith(prefix)}
        source = ""
        for key in ("preset", "params_file"):
            par = node.declare_parameter(prefix + key, "", ParameterDescriptor(
                description=f"{'preset name' if key == 'preset' else 'parameter YAML file'} for joint "
                            f"{name}; read-only", read_only=True))
            if par.value:
                if source:
                    raise P.ParameterError(prefix + key, f"give {prefix}preset or {prefix}params_file, not both")
                source = par.value
        try:
            params = P.load_preset(source) if source else base
        except (FileNotFoundError, P.ParameterError, ValueError) as exc:
            raise P.ParameterError(prefix + ("preset" if "preset" in mine else "params_file"), str(exc)) from None
        overrides: dict[str, Any] = {}
        for key, par in mine.items():
            if key in ("preset", "params_file"):
                continue
            if key not in P.SPECS:
                raise P.ParameterError(prefix + key, "unknown parameter (expected preset, params_file or a model "
                                       "parameter such as drive.bus_voltage)")
            spec = P.SPECS[key]
            _coerce_override(node, prefix + key, spec.type)
            value = _declare(node, prefix + key, spec.type, P.to_flat(params)[key],
                             describe(spec, runtime=False), spec.unit)
            overrides[key] = value
        out[name] = P.from_flat(overrides, base=params) if overrides else params
    for key in ov:
        if key.startswith(JOINT_PREFIX) and key.split(".")[1] not in out:
            raise P.ParameterError(key, f"no such joint (joints: {', '.join(out)})")
    return out, explicit
