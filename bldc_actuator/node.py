"""ROS 2 node ``actuator_node``: the virtual BLDC actuator (:class:`bldc_actuator.model.Actuator`) on topics.

Inputs (commands hold until replaced)
    ``~/current_command``  std_msgs/Float64            q-axis current [A]
    ``~/torque_command``   std_msgs/Float64            output torque [N*m]
    ``~/commands``         std_msgs/Float64MultiArray  ros2_control ForwardCommandController: one element,
                                                       meaning set by ``node.commands_interface``
    ``~/load_torque``      std_msgs/Float64            extra external load at the output [N*m]
    ``~/reset_fault``      std_msgs/Empty              clears a latched over-temperature trip
Outputs (stamped with SIMULATION time, at ``node.publish_rate`` per simulated second)
    ``joint_states``         sensor_msgs/JointState     output position [rad], velocity [rad/s], effort [N*m]
    ``~/phase_currents``     std_msgs/Float64MultiArray i_phase_a, i_phase_b, i_phase_c [A] (winding currents)
    ``~/q_axis_state``       std_msgs/Float64MultiArray :data:`Q_AXIS_FIELDS` (labelled layout)
    ``~/winding_temperature``, ``~/housing_temperature``  sensor_msgs/Temperature [degC]
    ``/diagnostics``         diagnostic_msgs/DiagnosticArray at ``node.diagnostics_rate`` (simulated)
    ``/clock``               rosgraph_msgs/Clock when ``node.publish_clock``

Time: a timer on the STEADY clock (never the node clock: with ``use_sim_time`` and our own ``/clock`` that
would deadlock) advances the model by ``time_factor`` x the elapsed wall time, in whole publish periods;
``time_factor`` 0 or inf runs as fast as possible (batches of periods between executor spins);
``node.lock_step`` advances exactly one period per received command instead.

Parameters: see :mod:`bldc_actuator.node_params`. ``actuator_node --help`` lists them.
"""

from __future__ import annotations

import gc
import math
import operator
import sys
import threading
import time
from collections import deque
from typing import Any

import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterEvent, SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
from rclpy.task import Future
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState, Temperature
from std_msgs.msg import Empty, Float64, Float64MultiArray, MultiArrayDimension

from . import node_params as NP
from .model import COMPILED, Actuator, warm_up
from .params import SPECS, ParameterError, from_flat

NODE_NAME = "bldc_actuator"

#: element order of ``~/q_axis_state`` (units: A, A, A, V, V, V, V, V, rad/s motor side, N*m motor side,
#: A, W, ohm, 1 if saturated, 1 if tripped); also in the message layout label, comma-separated
Q_AXIS_FIELDS = ("i_q", "i_d", "i_q_ref", "v_q", "v_d", "v_limit_q", "bus_voltage", "v_magnitude_q",
                 "omega", "torque_em", "current_limit_effective", "joule_power", "resistance_phase",
                 "voltage_saturated", "tripped")
PHASE_FIELDS = ("i_phase_a", "i_phase_b", "i_phase_c")
_Q_GET, _PHASE_GET = operator.itemgetter(*Q_AXIS_FIELDS), operator.itemgetter(*PHASE_FIELDS)

#: a command beyond this multiple of the drive's current limit (in current) is rejected as absurd;
#: commands between 1x and this are accepted and limited by the drive like a real one would
ABSURD_FACTOR = 10.0
#: diagnostics level ERROR once thermal derating has cut the current limit by more than this fraction
DERATE_ERROR_FRACTION = 0.5
#: longest wall time one timer callback may spend stepping before yielding to the executor [s]
MAX_BATCH_WALL = 0.02
#: subscription queue depth of the command topics
COMMAND_QUEUE_DEPTH = 100

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


def labelled_layout(msg: Float64MultiArray, labels: tuple[str, ...]) -> Float64MultiArray:
    msg.layout.dim = [MultiArrayDimension(label=",".join(labels), size=len(labels), stride=len(labels))]
    return msg


def layout_labels(msg: Float64MultiArray) -> list[str]:
    """Element names of a message published by this node (``~/q_axis_state``, ``~/phase_currents``)."""
    return msg.layout.dim[0].label.split(",") if msg.layout.dim else []


def _stamp(t_ns: int) -> TimeMsg:
    return TimeMsg(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


class _Joint:
    """One simulated actuator of the node: its model, command state, topics and diagnostics window."""

    def __init__(self, name: str, params, index: int):
        self.name, self.index, self.params = name, index, params
        self.actuator = Actuator(params)
        self.command_kind = "current"            # "current" [A] | "torque" [N*m]
        self.command_value = 0.0
        self.last_command_ns: int | None = None  # watchdog armed by the first command
        self.watchdog_active = False
        self.commands_received = 0
        self.commands_rejected = 0
        self.last_rejection = ""
        self.load_torque_extra = 0.0
        self.win_saturated = 0
        self.win_rejected = 0
        self.last_outputs: dict | None = None
        # ROS entities (set by the node)
        self.pub_phase = self.pub_q = self.pub_tw = self.pub_th = None
        self.sub_current = self.sub_torque = self.sub_load = self.sub_reset = None
        self.m_phase = labelled_layout(Float64MultiArray(), PHASE_FIELDS)
        self.m_q = labelled_layout(Float64MultiArray(), Q_AXIS_FIELDS)
        self.m_tw, self.m_th = Temperature(), Temperature()
        self.m_tw.header.frame_id = self.m_th.header.frame_id = name

    def absurd_limit(self, kind: str) -> float:
        """|command| beyond this is rejected as absurd (A, or N*m at the output)."""
        i_max = ABSURD_FACTOR * self.params.drive.current_limit
        if kind == "current":
            return i_max
        return i_max * self.params.motor.torque_constant_q * self.params.gear.gear_ratio


def _joint_attr(name: str):
    """Single-joint compatibility: ``node.<name>`` is joint 0's attribute."""
    return property(lambda self: getattr(self.joints[0], name),
                    lambda self, value: setattr(self.joints[0], name, value))


class ActuatorNode(Node):
    """The actuator node: one or several joints (``joints`` parameter), each a simulated actuator.
    Construct after ``rclpy.init``; add to an executor; ``done`` completes when ``node.max_sim_time`` is
    reached. Call :meth:`close` (or ``destroy_node``) to finish a recording.

    One joint (default): the topics of the module docstring. Several joints: ``joint_states`` holds all of
    them, ``~/commands`` takes one value per joint in ``joints`` order, and every per-joint topic moves under
    ``~/<joint>/`` (``~/knee/torque_command``, ``~/knee/q_axis_state``, ...)."""

    actuator = _joint_attr("actuator")
    params = _joint_attr("params")
    command_kind = _joint_attr("command_kind")
    command_value = _joint_attr("command_value")
    watchdog_active = _joint_attr("watchdog_active")
    load_torque_extra = _joint_attr("load_torque_extra")
    _last_command_ns = _joint_attr("last_command_ns")
    pub_phase = _joint_attr("pub_phase")
    pub_q = _joint_attr("pub_q")
    pub_tw = _joint_attr("pub_tw")
    pub_th = _joint_attr("pub_th")
    sub_current = _joint_attr("sub_current")
    sub_torque = _joint_attr("sub_torque")
    sub_load = _joint_attr("sub_load")
    sub_reset = _joint_attr("sub_reset")
    _m_phase = _joint_attr("m_phase")
    _m_q = _joint_attr("m_q")

    def __init__(self, node_name: str = NODE_NAME, *, namespace: str | None = None, context=None,
                 cli_args: list[str] | None = None, parameter_overrides: list[Parameter] | None = None,
                 start: bool = True):
        super().__init__(node_name, namespace=namespace, context=context, cli_args=cli_args,
                         parameter_overrides=parameter_overrides)
        self._lock = threading.RLock()
        self.recorder = None
        self.recording_error = ""   # set once a write to the recording failed
        self._timer = None
        self.done = Future()
        try:
            base, nv, self.preset = NP.declare_all(self)
            joint_params, explicit = NP.declare_joints(self, base, nv["node.joint_name"])
        except BaseException:
            self.destroy_node()
            raise
        self.node_values = nv
        # compile (or load from numba's cache) the physics kernel now, before simulation time is tied to the
        # wall clock: a first step that compiles would otherwise be a slip of seconds
        self.kernel_warm_up_s = warm_up()
        self.joints = [_Joint(name, p, k) for k, (name, p) in enumerate(joint_params.items())]
        self.multi = explicit   # joints given: per-joint topics under ~/<joint>/
        self.joint_name = self.joints[0].name
        self.period_ns = int(round(1e9 / nv["node.publish_rate"]))
        self.diag_period_ns = max(self.period_ns, int(round(1e9 / nv["node.diagnostics_rate"])))
        self.detail_period_ns = max(self.period_ns, int(round(1e9 / nv["node.detail_rate"]))) \
            if nv["node.detail_rate"] > 0 else self.period_ns
        self.lock_step = nv["node.lock_step"]
        self.max_sim_ns = int(round(nv["node.max_sim_time"] * 1e9))
        self._watchdog_ns = int(round(nv["node.watchdog_timeout"] * 1e9))
        self._time_factor = nv["node.time_factor"]
        self._commands_interface = nv["node.commands_interface"]

        self.commands_received = 0
        self.commands_rejected = 0
        self.last_rejection = ""
        self.rejections: deque[str] = deque(maxlen=100)   # recent rejection reasons, newest last
        # diagnostics window
        self._next_diag_ns = 0
        self._next_detail_ns = 0
        self._win_periods = 0
        self._win_wall0 = time.monotonic_ns()
        self._win_sim0 = 0
        self.real_time_factor = float("nan")
        self.slips = 0
        self._win_slips = 0
        self.periods = 0

        qos = QoSProfile(depth=10)
        self._qos = qos
        self.pub_joint = self.create_publisher(JointState, nv["node.joint_states_topic"], qos)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos)
        self.pub_clock = self.create_publisher(ClockMsg, "/clock", qos) if nv["node.publish_clock"] else None
        # deep command queues: in lock-step mode every command counts (one period each), even in bursts
        cq = QoSProfile(depth=COMMAND_QUEUE_DEPTH)
        for j in self.joints:
            pre = f"~/{j.name}/" if self.multi else "~/"
            j.pub_phase = self.create_publisher(Float64MultiArray, pre + "phase_currents", qos)
            j.pub_q = self.create_publisher(Float64MultiArray, pre + "q_axis_state", qos)
            j.pub_tw = self.create_publisher(Temperature, pre + "winding_temperature", qos)
            j.pub_th = self.create_publisher(Temperature, pre + "housing_temperature", qos)
            j.sub_current = self.create_subscription(
                Float64, pre + "current_command", lambda m, j=j: self._on_scalar(j, j.sub_current, "current", m), cq)
            j.sub_torque = self.create_subscription(
                Float64, pre + "torque_command", lambda m, j=j: self._on_scalar(j, j.sub_torque, "torque", m), cq)
            j.sub_load = self.create_subscription(Float64, pre + "load_torque", lambda m, j=j: self._on_load(j, m), cq)
            j.sub_reset = self.create_subscription(Empty, pre + "reset_fault", lambda m, j=j: self._on_reset(j, m), qos)
        self.sub_commands = self.create_subscription(Float64MultiArray, "~/commands", self._on_commands, cq)
        topic = nv["node.joint_commands_topic"]
        self.sub_joint_commands = self.create_subscription(JointState, topic, self._on_joint_commands, cq) \
            if topic else None

        # reusable messages (rclpy serialises at publish; reuse is safe)
        self._m_joint = JointState(name=[j.name for j in self.joints])
        self._m_joint.header.frame_id = self.joint_name if not self.multi else ""
        self._m_clock = ClockMsg()
        self._stamp_now = TimeMsg()

        record = nv["node.record"]
        if record:
            self._open_recorder(record)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        if start:
            self.start()

    # ------------------------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Publish the initial state and start stepping (a steady-clock timer unless lock-step)."""
        with self._lock:
            self._publish_state()
            if self._timer is None and not self.lock_step:
                self._anchor()
                # the timer wakes twice per publish period: a period becomes due at most half a period
                # before it is published, whatever the timer's phase (publish lateness p99 at 1 kHz: see
                # benchmarks/bench_node.py); a wake-up with nothing due costs a few microseconds
                self._timer = self.create_timer(max(0.5 * self.period_ns * 1e-9, 5e-4), self._on_tick,
                                                clock=self._steady)

    def close(self) -> None:
        """Stop stepping and finalise the recording (idempotent)."""
        with self._lock:
            if self._timer is not None:
                self.destroy_timer(self._timer)
                self._timer = None
            if self.recorder is not None:
                rec, self.recorder = self.recorder, None
                try:
                    rec.close()
                except Exception as exc:  # noqa: BLE001 - e.g. the disk filled while finalizing
                    self.recording_error = f"recording stopped: {exc}"
                # after a shutdown the node's logger cannot publish to /rosout any more
                # (and a logger of the node's name would try to), so use an unrelated name then
                logger = self.get_logger() if self.context.ok() else rclpy.logging.get_logger("actuator_node_exit")
                if self.recording_error:
                    logger.error(self.recording_error)
                else:
                    logger.info(f"recording finished: {self.node_values['node.record']}")

    def destroy_node(self):
        try:
            self.close()
        finally:
            return super().destroy_node()

    @property
    def t_ns(self) -> int:
        """Simulation time [ns]."""
        return self.joints[0].actuator.t_ns

    @property
    def finished(self) -> bool:
        return self.done.done()

    # ------------------------------------------------------------------------------------ stepping

    def _anchor(self) -> None:
        """Tie simulation time to the steady clock now (half a period ahead, so ticks land mid-period)."""
        f = self._time_factor
        self._anchor_sim = self.t_ns
        self._anchor_wall = time.monotonic_ns() - (int(self.period_ns / (2 * f)) if 0 < f < math.inf else 0)

    @property
    def as_fast_as_possible(self) -> bool:
        return self._time_factor == 0.0 or math.isinf(self._time_factor)

    def _on_tick(self) -> None:
        with self._lock:
            if self.finished or not self.context.ok():   # shutting down (Ctrl-C): publishing would fail
                return
            try:
                self._tick()
            except Exception:
                if self.context.ok():
                    raise
                # the context was shut down (signal) in the middle of the batch: a normal stop

    def _tick(self) -> None:
        now = time.monotonic_ns()
        if self.as_fast_as_possible:
            deadline = time.perf_counter() + MAX_BATCH_WALL
            while not self.finished:
                self._advance_period()
                if time.perf_counter() >= deadline:
                    break
            return
        target = self._anchor_sim + int((now - self._anchor_wall) * self._time_factor)
        n = (target - self.t_ns) // self.period_ns
        limit = max(1, int(MAX_BATCH_WALL * self._time_factor * 1e9 / self.period_ns))
        if n > limit:  # cannot keep up: drop the debt instead of bursting later
            self.slips += 1
            self._win_slips += 1
            self._anchor_sim = self.t_ns + limit * self.period_ns
            self._anchor_wall = now
            n = limit
        for _ in range(n):
            self._advance_period()
            if self.finished:
                break

    def advance(self, periods: int = 1) -> None:
        """Advance ``periods`` publish periods now (public for tests, benchmarks and embedding)."""
        with self._lock:
            for _ in range(periods):
                if self.finished:
                    break
                self._advance_period()

    def _advance_period(self) -> None:
        t = self.t_ns
        step = self.period_ns
        if self.max_sim_ns:
            step = min(step, self.max_sim_ns - t)
        for j in self.joints:
            if (self._watchdog_ns > 0 and j.last_command_ns is not None and not j.watchdog_active
                    and t - j.last_command_ns >= self._watchdog_ns):
                j.watchdog_active = True
                j.actuator.set_current_command(0.0)
                self.get_logger().warning(
                    f"command watchdog{'' if not self.multi else ' (' + j.name + ')'}: no command for "
                    f"{self._watchdog_ns * 1e-9:g} s of simulation time; current command set to zero until "
                    "the next command")
            if step > 0:
                j.actuator.step_ns(step)
        self.periods += 1
        self._publish_state()
        if self.max_sim_ns and self.t_ns >= self.max_sim_ns and not self.done.done():
            self.get_logger().info(f"node.max_sim_time reached ({self.t_ns * 1e-9:g} s)")
            self.done.set_result(self.t_ns)

    # ------------------------------------------------------------------------------------ publishing

    def _publish_state(self) -> None:
        t_ns = self.t_ns
        stamp = self._stamp_now          # one Time message, updated in place (all of this period's headers)
        stamp.sec, stamp.nanosec = divmod(t_ns, 1_000_000_000)
        outs = [j.actuator.outputs() for j in self.joints]
        m = self._m_joint
        m.header.stamp = stamp
        m.position = [o["position_out"] for o in outs]      # Python floats (outputs() of one actuator)
        m.velocity = [o["velocity_out"] for o in outs]
        m.effort = [o["effort_out"] for o in outs]
        if self.pub_clock is not None:
            self._m_clock.clock = stamp
            self._publish(self.pub_clock, self._m_clock, t_ns)
        self._publish(self.pub_joint, m, t_ns)
        detail = t_ns >= self._next_detail_ns
        if detail:
            self._next_detail_ns = t_ns - t_ns % self.detail_period_ns + self.detail_period_ns
        for j, o in zip(self.joints, outs):
            j.last_outputs = o
            j.win_saturated += bool(o["voltage_saturated"])
            if detail:
                j.m_phase.data = list(map(float, _PHASE_GET(o)))
                j.m_q.data = list(map(float, _Q_GET(o)))
                j.m_tw.header.stamp = j.m_th.header.stamp = stamp
                j.m_tw.temperature = float(o["T_winding"])
                j.m_th.temperature = float(o["T_housing"])
                for pub, msg in ((j.pub_phase, j.m_phase), (j.pub_q, j.m_q), (j.pub_tw, j.m_tw),
                                 (j.pub_th, j.m_th)):
                    self._publish(pub, msg, t_ns)
        self._win_periods += 1
        if t_ns >= self._next_diag_ns:
            self._publish_diagnostics(outs, t_ns)
            self._next_diag_ns = t_ns - t_ns % self.diag_period_ns + self.diag_period_ns

    def _publish(self, pub, msg, t_ns: int) -> None:
        """Publish; when recording, serialise once and hand the same CDR bytes to DDS and the recorder."""
        rec = self.recorder
        if rec is None:
            pub.publish(msg)
            return
        if rec.closed:   # finalised from outside (atexit, a signal finalizer): stop recording quietly
            self.recorder = None
            pub.publish(msg)
            return
        data = serialize_message(msg)
        pub.publish(data)
        try:
            rec.write_serialized(pub.topic_name, data, t_ns)
        except Exception as exc:  # noqa: BLE001 - a recording fault never stops the actuator
            self._recording_failed(exc)

    def diagnostic_status(self, o: dict | None = None, joint: int = 0) -> DiagnosticStatus:
        """The current diagnostics entry of one joint (level, message, key values); also resets the window."""
        status = self._joint_status(self.joints[joint], o)
        self._reset_window()
        return status

    def _reset_window(self) -> None:
        self._win_periods = self._win_slips = 0
        for j in self.joints:
            j.win_saturated = j.win_rejected = 0
        self._win_wall0, self._win_sim0 = time.monotonic_ns(), self.t_ns

    def _joint_status(self, j: _Joint, o: dict | None) -> DiagnosticStatus:
        act, p = j.actuator, j.params
        o = act.outputs() if o is None else o
        t_ns = act.t_ns
        wall = time.monotonic_ns()
        if wall > self._win_wall0 and t_ns > self._win_sim0:
            self.real_time_factor = (t_ns - self._win_sim0) / (wall - self._win_wall0)
        sat = j.win_saturated / self._win_periods if self._win_periods else 0.0
        level, why = OK, []
        lim_eff, lim = float(o["current_limit_effective"]), p.drive.current_limit
        T_w = float(o["T_winding"])
        reset_topic = f"~/{j.name}/reset_fault" if self.multi else "~/reset_fault"
        if o["tripped"]:
            level = ERROR
            why.append(f"over-temperature TRIP (winding {T_w:.1f} degC, trip at {p.drive.trip_temperature:g}); "
                       f"latched: publish std_msgs/Empty on {reset_topic}")
        elif lim_eff < (1.0 - DERATE_ERROR_FRACTION) * lim:
            level = ERROR
            why.append(f"thermal derating beyond {DERATE_ERROR_FRACTION:.0%}: current limit {lim_eff:.2f} of "
                       f"{lim:g} A (winding {T_w:.1f} degC)")
        elif T_w > p.drive.derate_temperature:
            level = WARN
            why.append(f"thermal derating: winding {T_w:.1f} degC > {p.drive.derate_temperature:g}; "
                       f"current limit {lim_eff:.2f} of {lim:g} A")
        if sat > 0:
            level = max(level, WARN)
            why.append(f"voltage saturation {sat:.0%} of the last {self._win_periods} periods")
        if j.watchdog_active:
            level = max(level, WARN)
            why.append(f"command watchdog: no command for {self._watchdog_ns * 1e-9:g} s, holding zero current")
        if j.win_rejected:
            level = max(level, WARN)
            why.append(f"{j.win_rejected} command(s) rejected: {j.last_rejection}")
        if self.recording_error:
            level = ERROR
            why.append(self.recording_error)
        if self._win_slips:
            level = max(level, WARN)
            why.append(f"cannot keep time_factor {self._time_factor:g} (achieved {self.real_time_factor:.2f})")
        values = {
            "sim_time [s]": f"{t_ns * 1e-9:.6f}",
            "real_time_factor": f"{self.real_time_factor:.3f}",
            "mode": "lock_step" if self.lock_step else
                    "as_fast_as_possible" if self.as_fast_as_possible else f"time_factor {self._time_factor:g}",
            "command": f"{j.command_kind} {j.command_value:g}",
            "i_q [A]": f"{o['i_q']:.4f}", "i_q_ref [A]": f"{o['i_q_ref']:.4f}",
            "v_magnitude_q [V]": f"{o['v_magnitude_q']:.4f}", "v_limit_q [V]": f"{o['v_limit_q']:.4f}",
            "voltage_saturated_fraction": f"{sat:.3f}",
            "velocity_out [rad/s]": f"{o['velocity_out']:.4f}", "effort_out [N*m]": f"{o['effort_out']:.4f}",
            "winding_temperature [degC]": f"{T_w:.3f}",
            "housing_temperature [degC]": f"{o['T_housing']:.3f}",
            "current_limit_effective [A]": f"{lim_eff:.4f}",
            "tripped": str(bool(o["tripped"])).lower(),
            "watchdog_active": str(j.watchdog_active).lower(),
            "commands_received": str(j.commands_received),
            "commands_rejected": str(j.commands_rejected),
            "last_rejection": j.last_rejection,
            "recording": self.recording_error or (str(self.node_values["node.record"]) if self.recorder else "off"),
        }
        name = f"{self.get_fully_qualified_name()}: " + (j.name if self.multi else "actuator")
        return DiagnosticStatus(level=level, name=name, message="; ".join(why) if why else "OK",
                                hardware_id=j.name, values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def diagnostic_statuses(self, outs: list[dict] | None = None) -> list[DiagnosticStatus]:
        """One diagnostics status per joint (and the window reset)."""
        outs = outs or [None] * len(self.joints)
        statuses = [self._joint_status(j, o) for j, o in zip(self.joints, outs)]
        self._reset_window()
        return statuses

    def _publish_diagnostics(self, outs: list[dict], t_ns: int) -> None:
        msg = DiagnosticArray(status=self.diagnostic_statuses(outs))
        msg.header.stamp = _stamp(t_ns)
        self._publish(self.pub_diag, msg, t_ns)

    # ------------------------------------------------------------------------------------ commands

    def _reject(self, j: _Joint | None, topic: str, reason: str) -> None:
        self.commands_rejected += 1
        self.last_rejection = f"{topic}: {reason}"
        self.rejections.append(self.last_rejection)
        for jj in ([j] if j is not None else self.joints):
            jj.commands_rejected += 1
            jj.win_rejected += 1
            jj.last_rejection = self.last_rejection
        self.get_logger().warning(f"rejected command on {topic}: {reason}", throttle_duration_sec=1.0)

    def _record_in(self, sub, msg) -> None:
        if self.recorder is not None:
            self._write(sub.topic_name, msg, self.t_ns)

    def _apply(self, j: _Joint, topic: str, kind: str, value) -> bool:
        """Validate and apply one joint's command; False (and counted, reported) when rejected."""
        unit = "A" if kind == "current" else "N*m"
        if not isinstance(value, float) or not math.isfinite(value):
            self._reject(j, topic, f"{kind} command{self._for(j)} must be a finite number [{unit}], got {value!r}")
            return False
        if abs(value) > j.absurd_limit(kind):
            self._reject(j, topic, f"{kind} command{self._for(j)} {value:g} {unit} is absurd (more than "
                         f"{ABSURD_FACTOR:g} x drive.current_limit: |value| <= {j.absurd_limit(kind):g} {unit})")
            return False
        try:
            if kind == "current":
                j.actuator.set_current_command(value)
            else:
                j.actuator.set_torque_command(value)
        except Exception as exc:  # noqa: BLE001 - the node never dies on a message
            self._reject(j, topic, f"{type(exc).__name__}: {exc}")
            return False
        j.command_kind, j.command_value = kind, value
        j.commands_received += 1
        self.commands_received += 1
        j.last_command_ns = j.actuator.t_ns
        if j.watchdog_active:
            j.watchdog_active = False
            self.get_logger().info(f"command watchdog cleared{self._for(j)}: commands are back")
        return True

    def _for(self, j: _Joint) -> str:
        return f" for joint {j.name}" if self.multi else ""

    def _lock_step_period(self) -> None:
        """In lock-step mode a command (also a rejected one, so a controller waiting for joint_states never
        stalls) advances one period."""
        if self.lock_step and not self.finished:
            self._advance_period()

    def _on_scalar(self, j: _Joint, sub, kind: str, msg: Float64) -> None:
        self._record_in(sub, msg)
        with self._lock:
            self._apply(j, sub.topic_name, kind, msg.data)
            if not self.multi:   # several joints: only whole-robot commands advance a lock-step period
                self._lock_step_period()

    def _on_commands(self, msg: Float64MultiArray) -> None:
        """ros2_control ForwardCommandController convention: one value per joint, ``joints`` order."""
        self._record_in(self.sub_commands, msg)
        kind = "torque" if self._commands_interface == "effort" else "current"
        topic = self.sub_commands.topic_name
        with self._lock:
            if len(msg.data) != len(self.joints):
                names = ", ".join(j.name for j in self.joints)
                self._reject(None, topic, f"expected {len(self.joints)} element(s) ({self._commands_interface} "
                             f"for {names}), got {len(msg.data)}")
            else:
                for j, value in zip(self.joints, msg.data):
                    self._apply(j, topic, kind, float(value))
            self._lock_step_period()

    def _on_joint_commands(self, msg: JointState) -> None:
        """sensor_msgs/JointState commands as ros2_control's topic_based hardware interface sends them: all
        joint names; ``effort`` filled for joints with an effort command interface (in ``name`` order).
        Position or velocity commands are rejected (this node is a torque-controlled actuator)."""
        self._record_in(self.sub_joint_commands, msg)
        topic = self.sub_joint_commands.topic_name
        with self._lock:
            by_name = {j.name: j for j in self.joints}
            names = list(msg.name)
            if (len(msg.position) or len(msg.velocity)) and not len(msg.effort):
                self._reject(None, topic, "position/velocity commands are not supported: give each joint only "
                             "<command_interface name=\"effort\"/> (output torque [N*m]) in <ros2_control>")
            elif len(msg.effort) != len(names):
                self._reject(None, topic, f"expected one effort per name ({len(names)} names, "
                             f"{len(msg.effort)} efforts); mixed command interfaces are not supported")
            else:
                unknown = [n for n in names if n not in by_name]
                if unknown:
                    self._reject(None, topic, f"unknown joint(s) {', '.join(unknown)} "
                                 f"(this node has {', '.join(by_name)})")
                for name, value in zip(names, msg.effort):
                    if name in by_name:
                        self._apply(by_name[name], topic, "torque", float(value))
            self._lock_step_period()

    def _on_load(self, j: _Joint, msg: Float64) -> None:
        self._record_in(j.sub_load, msg)
        with self._lock:
            v = msg.data
            if not math.isfinite(v) or abs(v) > SPECS["load.load_torque"].range[1]:
                self._reject(j, j.sub_load.topic_name, f"load torque must be finite and within "
                             f"+-{SPECS['load.load_torque'].range[1]:g} N*m, got {v!r}")
                return
            j.actuator.set_load_torque(v)
            j.load_torque_extra = v

    def _on_reset(self, j: _Joint, msg: Empty) -> None:
        self._record_in(j.sub_reset, msg)
        with self._lock:
            was = j.actuator.state.tripped
            j.actuator.reset_fault()
            self.get_logger().info(f"fault reset{self._for(j)}" + ("" if was else " (no trip was latched)"))

    # ------------------------------------------------------------------------------------ parameters

    def _on_set_parameters(self, plist: list[Parameter]) -> SetParametersResult:
        model: dict[str, Any] = {}
        node: dict[str, Any] = {}
        try:
            for p in plist:
                if p.name in SPECS:
                    model[p.name] = NP.from_ros(SPECS[p.name].type, p.value)
                elif p.name in NP.NODE_PARAMS:
                    node[p.name] = NP.check_node_value(p.name, p.value)
            new = [from_flat(model, base=j.params) for j in self.joints] if model else None
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        with self._lock:
            if new is not None:   # a node-level model parameter applies to every joint
                for j, params in zip(self.joints, new):
                    j.actuator.update_params(params)
                    j.params = params
            for name, value in node.items():
                self.node_values[name] = value
                if name == "node.time_factor":
                    self._time_factor = value
                    if not self.lock_step:
                        self._anchor()
                elif name == "node.watchdog_timeout":
                    self._watchdog_ns = int(round(value * 1e9))
                elif name == "node.commands_interface":
                    self._commands_interface = value
            if self.recorder is not None and (model or node):
                ev = ParameterEvent(node=self.get_fully_qualified_name(),
                                    changed_parameters=[p.to_parameter_msg() for p in plist])
                ev.stamp = _stamp(self.t_ns)
                self._write("/parameter_events", ev, self.t_ns)
                if self.recorder is not None:
                    try:
                        self.recorder.set_parameters(self.all_parameters())
                    except Exception as exc:  # noqa: BLE001
                        self._recording_failed(exc)
        return SetParametersResult(successful=True)

    def all_parameters(self) -> dict[str, Any]:
        """Flat dict of everything that defines the run: every model parameter (of the first joint), ``node.*``,
        ``preset``; with several joints also ``joints`` and every joint's full set as ``joint.<name>.<param>``."""
        flat = lambda p: {k: (list(v) if isinstance(v, tuple) else v) for k, v in p.to_flat().items()}  # noqa: E731
        out: dict[str, Any] = flat(self.joints[0].params)
        out.update(self.node_values)
        out["preset"] = self.preset
        if self.multi:
            out[NP.JOINTS] = [j.name for j in self.joints]
            for j in self.joints:
                out.update({f"{NP.JOINT_PREFIX}{j.name}.{k}": v for k, v in flat(j.params).items()})
        return out

    # ------------------------------------------------------------------------------------ recording

    def _write(self, topic: str, msg, t_ns: int) -> None:
        rec = self.recorder
        if rec.closed:   # finalised from outside (signal finalizer, atexit): stop recording quietly
            self.recorder = None
            return
        try:
            rec.write(topic, msg, t_ns)
        except Exception as exc:  # noqa: BLE001 - a recording fault never stops the actuator
            self._recording_failed(exc)

    def _recording_failed(self, exc: BaseException) -> None:
        """A write to the recording failed (disk full, I/O error, ...): stop recording, say so once (log and
        /diagnostics ERROR until the node ends), and carry on simulating and publishing."""
        rec, self.recorder = self.recorder, None
        if rec is not None and not rec.closed:
            try:
                rec.close()
            except Exception:  # noqa: BLE001 - the file is already as complete as it can be
                pass
        self.recording_error = f"recording stopped: {exc}"
        self.get_logger().error(f"{self.recording_error}; the actuator keeps running without recording")

    def _open_recorder(self, path: str) -> None:
        from .recording import McapRecorder

        meta = {"node": self.get_fully_qualified_name(), "joint_name": self.joint_name,
                "joints": ",".join(j.name for j in self.joints),
                "time": "log_time = simulation time [ns]", "package": "bldc_actuator"}
        self.recorder = McapRecorder(path, parameters=self.all_parameters(), metadata=meta)
        topics = [(self.pub_joint, JointState), (self.pub_diag, DiagnosticArray),
                  (self.sub_commands, Float64MultiArray)]
        if self.sub_joint_commands is not None:
            topics.append((self.sub_joint_commands, JointState))
        for j in self.joints:
            topics += [(j.pub_phase, Float64MultiArray), (j.pub_q, Float64MultiArray), (j.pub_tw, Temperature),
                       (j.pub_th, Temperature), (j.sub_current, Float64), (j.sub_torque, Float64),
                       (j.sub_load, Float64), (j.sub_reset, Empty)]
        if self.pub_clock is not None:
            topics.append((self.pub_clock, ClockMsg))
        for ent, mtype in topics:
            self.recorder.add_topic(ent.topic_name, mtype, self._qos)
        self.recorder.add_topic("/parameter_events", ParameterEvent, self._qos)
        self.get_logger().info(f"recording to {path}")


# ---------------------------------------------------------------------------------------------- main

USAGE = """\
usage: actuator_node [--record PATH] [--executor events|single] [--ros-args --params-file FILE -p name:=value ...]

Virtual BLDC actuator node (bldc_actuator): one joint, or a whole robot with -p joints:="[hip, knee, ankle]".
Every model parameter has a default: it runs without a parameter file. --record PATH records commands,
outputs and parameters to an MCAP file (same as -p node.record:=PATH). --executor: events (rclpy's
EventsExecutor, the default where it exists: less CPU, faster lock-step) or single (SingleThreadedExecutor).
Stops on Ctrl-C / SIGTERM, or after node.max_sim_time seconds of simulation.

Topics (relative to the namespace; ~ = the node's private namespace; with joints given, the per-joint topics
are ~/<joint>/...):
  in : ~/current_command, ~/torque_command (std_msgs/Float64, per joint), ~/commands
       (std_msgs/Float64MultiArray, one value per joint in joints order), ~/load_torque (std_msgs/Float64,
       per joint), ~/reset_fault (std_msgs/Empty, per joint), node.joint_commands_topic (sensor_msgs/JointState
       effort by joint name: ros2_control's topic_based hardware interface)
  out: node.joint_states_topic (joint_states: every joint), ~/phase_currents, ~/q_axis_state,
       ~/winding_temperature, ~/housing_temperature (per joint, at node.detail_rate), /diagnostics (one status
       per joint), /clock (node.publish_clock)

Per-joint parameters: joint.<name>.preset, joint.<name>.params_file, joint.<name>.<model parameter>.

Parameters:
"""


def _parameter_help() -> str:
    lines = []
    for name, spec in list(NP.NODE_PARAMS.items()) + list(SPECS.items()):
        unit = f" [{spec.unit}]" if spec.unit else ""
        rt = "" if spec.runtime else " (read-only)"
        default = list(spec.default) if isinstance(spec.default, tuple) else spec.default
        lines.append(f"  {name} = {default!r}{unit}{rt}: {spec.description}")
    lines.append("  preset = '' (read-only): preset name (config/*.yaml) or parameter file for the model defaults")
    return "\n".join(lines) + "\n"


def split_node_flags(argv: list[str]) -> tuple[list[str], dict[str, str]]:
    """Remove this program's own flags (``--record PATH``, ``--executor KIND``, also ``--flag=value``) from
    ``argv`` before rclpy sees it; only outside ``--ros-args ... --``. Returns ``(rest, {flag: value})``."""
    out: list[str] = []
    flags: dict[str, str] = {}
    i, in_ros = 0, False
    while i < len(argv):
        a = argv[i]
        if a == "--ros-args":
            in_ros = True
        elif a == "--":
            in_ros = False
        name = a.split("=", 1)[0]
        if not in_ros and name in OWN_FLAGS:
            if "=" in a:
                flags[name[2:]] = a.split("=", 1)[1]
                i += 1
                continue
            if i + 1 >= len(argv):
                raise SystemExit(f"actuator_node: {a} needs a value ({OWN_FLAGS[a]})")
            flags[name[2:]] = argv[i + 1]
            i += 2
            continue
        out.append(a)
        i += 1
    return out, flags


#: flags of ``actuator_node`` itself (not ROS arguments)
OWN_FLAGS = {"--record": "PATH", "--executor": "events|single"}


def make_executor(kind: str | None = None, context=None):
    """``events`` (rclpy.experimental.EventsExecutor, ROS 2 Kilted+; the default where it exists) or
    ``single`` (SingleThreadedExecutor; the default on older ROS 2). Measured (benchmarks/bench_node.py,
    12 joints at 1 kHz): events keeps 1000 Hz on a third of a core, single needs a whole one, and events makes
    lock-step round trips about 5x faster."""
    if kind in (None, "events"):
        try:
            from rclpy.experimental import EventsExecutor

            return EventsExecutor(context=context)
        except ImportError:
            if kind == "events":
                raise SystemExit("actuator_node: --executor events needs rclpy.experimental.EventsExecutor "
                                 "(ROS 2 Kilted or newer); use --executor single") from None
    elif kind not in (None, "single"):
        raise SystemExit(f"actuator_node: --executor must be events or single, got {kind!r}")
    return SingleThreadedExecutor(context=context)


def _soft_sigint() -> None:
    """First Ctrl-C: only rclpy's handler acts (it shuts the context down; the spin loop ends, the recording
    is finalised in order) instead of a KeyboardInterrupt landing in the middle of a callback. A second
    Ctrl-C raises KeyboardInterrupt as usual."""
    import signal

    if threading.current_thread() is not threading.main_thread():
        return
    count = [0]

    def handler(signum, frame):
        count[0] += 1
        if count[0] > 1:
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv if argv is None else argv)
    if any(a in ("-h", "--help") for a in argv[1:argv.index("--ros-args") if "--ros-args" in argv else None]):
        print(USAGE + _parameter_help(), end="")
        return 0
    args, flags = split_node_flags(argv)
    record = flags.get("record")
    _soft_sigint()
    rclpy.init(args=args)
    node = None
    executor = make_executor(flags.get("executor"))
    try:
        overrides = [Parameter("node.record", Parameter.Type.STRING, record)] if record else None
        try:
            node = ActuatorNode(parameter_overrides=overrides)
        except (ParameterError, FileNotFoundError) as exc:
            print(f"actuator_node: parameter error: {exc}", file=sys.stderr)
            return 2
        executor.add_node(node)
        # everything built so far lives as long as the node: take it out of the garbage collector's scans
        # (shorter collector pauses, publish lateness p99 below 1 ms at 1 kHz for 12 joints)
        gc.collect()
        gc.freeze()
        node.get_logger().info(
            f"running: {'lock-step' if node.lock_step else 'time_factor ' + str(node.node_values['node.time_factor'])}"
            f", {len(node.joints)} joint(s), publish {1e9 / node.period_ns:g} Hz, physics "
            f"{node.params.drive.current_loop_rate:g} Hz; kernel ready in {node.kernel_warm_up_s:.2f} s "
            f"({'compiled' if COMPILED else 'pure Python'})")
        # with a timeout: EventsExecutor's spin_until_future_complete without one never returns (Kilted)
        while not node.done.done() and rclpy.ok():
            executor.spin_until_future_complete(node.done, timeout_sec=0.25)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass                    # Ctrl-C / SIGTERM: rclpy shut the context down; finish below
    except Exception:
        if rclpy.ok():
            raise               # a real error (the recording is still finalized below)
        # shut down while a callback was publishing ("publisher's context is invalid"): a normal stop
    finally:
        if node is not None:
            node.close()
            executor.remove_node(node)
            node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
