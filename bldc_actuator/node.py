"""ROS 2 node ``actuator_node``: the virtual BLDC actuators of a plant (:mod:`bldc_actuator.plant`) on topics.

This module is the ROS wiring (parameters, topics, messages, timer, recording) around the ROS-free
:class:`bldc_actuator.scheduler.Scheduler`, which steps the plant, keeps lock-step, the watchdog, the command
checks and the diagnostics levels.

Inputs (commands hold until replaced; with ``joints`` given the per-joint topics are ``~/<joint>/...`` and,
by default, exist only once the graph shows a peer for them: see ``node.joint_topics``)
    ``~/current_command``  std_msgs/Float64            q-axis current [A]
    ``~/torque_command``   std_msgs/Float64            output torque [N*m]
    ``~/commands``         std_msgs/Float64MultiArray  ros2_control ForwardCommandController: one element per
                                                       joint, meaning set by ``node.commands_interface``
    ``node.joint_commands_topic`` sensor_msgs/JointState  effort [N*m] by joint name (ros2_control's
                                                       topic-based hardware interface)
    ``~/load_torque``      std_msgs/Float64            extra external load at the output [N*m]
    ``~/reset_fault``      std_msgs/Empty              clears a latched over-temperature trip
Outputs (stamped with SIMULATION time, at ``node.publish_rate`` per simulated second)
    ``joint_states``         sensor_msgs/JointState     output position [rad], velocity [rad/s], effort [N*m]
    ``~/phase_currents``     std_msgs/Float64MultiArray i_phase_a, i_phase_b, i_phase_c [A] (winding currents)
    ``~/q_axis_state``       std_msgs/Float64MultiArray :data:`Q_AXIS_FIELDS` (labelled layout)
    ``~/winding_temperature``, ``~/housing_temperature``  sensor_msgs/Temperature [degC]
    (the four detail topics at ``node.detail_rate``, on demand: only while something subscribes to them,
    or always while recording)
    ``/diagnostics``         diagnostic_msgs/DiagnosticArray at ``node.diagnostics_rate`` (simulated); every
                             change of a joint's level is also logged on the console
    ``/clock``               rosgraph_msgs/Clock when ``node.publish_clock``

Time: a timer on the STEADY clock (never the node clock: with ``use_sim_time`` and our own ``/clock`` that
would deadlock) wakes once per period of wall time and the scheduler advances the plant by ``time_factor`` x
the elapsed wall time, in whole publish periods; ``time_factor`` 0 or inf runs as fast as possible (batches
of periods between executor spins); ``node.lock_step`` advances exactly one period per received command.

Parameters: see :mod:`bldc_actuator.node_params`. ``actuator_node --help`` lists them.
"""

from __future__ import annotations

import gc
import inspect
import operator
import sys
import threading
import time
from array import array
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
from .model import COMPILED, warm_up
from .params import SPECS, ParameterError, current_loop_warning, from_flat, sanity_warnings
from .plant import ActuatorPlant
from .scheduler import Health, JointCommand, Scheduler, SchedulerConfig

NODE_NAME = "bldc_actuator"

#: element order of ``~/q_axis_state`` (units: A, A, A, V, V, V, V, V, rad/s motor side, N*m motor side,
#: A, W, ohm, 1 if saturated, 1 if tripped); also in the message layout label, comma-separated
Q_AXIS_FIELDS = ("i_q", "i_d", "i_q_ref", "v_q", "v_d", "v_limit_q", "bus_voltage", "v_magnitude_q",
                 "omega", "torque_em", "current_limit_effective", "joule_power", "resistance_phase",
                 "voltage_saturated", "tripped")
PHASE_FIELDS = ("i_phase_a", "i_phase_b", "i_phase_c")
_Q_GET, _PHASE_GET = operator.itemgetter(*Q_AXIS_FIELDS), operator.itemgetter(*PHASE_FIELDS)

#: subscription queue depth of the command topics
COMMAND_QUEUE_DEPTH = 100
#: wall time between checks of which detail topics have subscribers [ns]
DETAIL_REFRESH_NS = 100_000_000

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
_LEVEL_BYTES = tuple(bytes([level]) for level in range(3))


def labelled_layout(msg: Float64MultiArray, labels: tuple[str, ...]) -> Float64MultiArray:
    msg.layout.dim = [MultiArrayDimension(label=",".join(labels), size=len(labels), stride=len(labels))]
    return msg


def layout_labels(msg: Float64MultiArray) -> list[str]:
    """Element names of a message published by this node (``~/q_axis_state``, ``~/phase_currents``)."""
    return msg.layout.dim[0].label.split(",") if msg.layout.dim else []


def _stamp(t_ns: int) -> TimeMsg:
    return TimeMsg(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


#: per-joint command topics (subscriptions) and detail topics (publishers), with the JointTopics attribute
#: that holds each entity (None until created: see ``node.joint_topics``)
COMMAND_TOPICS = {"current_command": "sub_current", "torque_command": "sub_torque", "load_torque": "sub_load",
                  "reset_fault": "sub_reset"}
DETAIL_TOPICS = {"phase_currents": "pub_phase", "q_axis_state": "pub_q", "winding_temperature": "pub_tw",
                 "housing_temperature": "pub_th"}
#: wall time between looks at the ROS graph for per-joint topics created on demand [s]
GRAPH_POLL_S = 1.0


def _timer_callback(method):
    """``method`` as a plain function that carries its (empty) signature: rclpy's EventsExecutor inspects a timer
    callback's signature at EVERY call (looking for a TimerInfo parameter), ~13 us for a bound method, ~2 us for
    this (1 kHz: a point of a core)."""
    def callback():
        method()
    callback.__signature__ = inspect.Signature()
    return callback


class JointTopics:
    """One joint's ROS entities: publishers, subscriptions (attributes None while not created, see
    ``node.joint_topics``) and the reusable detail messages (their header stamp is the node's one stamp,
    updated in place every period)."""

    def __init__(self, name: str, stamp: TimeMsg, prefix: str):
        self.name = name
        self.prefix = prefix    # relative topic prefix: "~/" or "~/<joint>/"
        self.pub_phase = self.pub_q = self.pub_tw = self.pub_th = None
        self.sub_current = self.sub_torque = self.sub_load = self.sub_reset = None
        self.m_phase = labelled_layout(Float64MultiArray(), PHASE_FIELDS)
        self.m_q = labelled_layout(Float64MultiArray(), Q_AXIS_FIELDS)
        self.m_tw, self.m_th = Temperature(), Temperature()
        for m in (self.m_tw, self.m_th):
            m.header.frame_id = name
            m.header.stamp = stamp

    def detail(self) -> dict:
        """``{detail topic: fill(outputs) -> message}``."""
        m_phase, m_q, m_tw, m_th = self.m_phase, self.m_q, self.m_tw, self.m_th

        def phase(o):
            m_phase.data = array("d", _PHASE_GET(o))
            return m_phase

        def q(o):
            m_q.data = array("d", _Q_GET(o))
            return m_q

        def tw(o):
            m_tw.temperature = float(o["T_winding"])
            return m_tw

        def th(o):
            m_th.temperature = float(o["T_housing"])
            return m_th

        return {"phase_currents": phase, "q_axis_state": q, "winding_temperature": tw, "housing_temperature": th}


class ActuatorNode(Node):
    """The actuator node: one or several joints (``joints`` parameter), each a simulated actuator of
    :attr:`plant` (:class:`~bldc_actuator.plant.ActuatorPlant`), stepped by :attr:`scheduler`. Construct after
    ``rclpy.init``; add to an executor; ``done`` completes when ``node.max_sim_time`` is reached. Call
    :meth:`close` (or ``destroy_node``) to finish a recording.

    One joint (default): the topics of the module docstring. Several joints: ``joint_states`` holds all of
    them, ``~/commands`` takes one value per joint in ``joints`` order, and every per-joint topic moves under
    ``~/<joint>/`` (``~/knee/torque_command``, ``~/knee/q_axis_state``, ...). Per joint: :attr:`joints`
    (command state and counters, :class:`~bldc_actuator.scheduler.JointCommand`), :attr:`topics` (its ROS
    entities), ``plant.outputs(name)`` / ``plant.params(name)`` (its physics)."""

    def __init__(self, node_name: str = NODE_NAME, *, namespace: str | None = None, context=None,
                 cli_args: list[str] | None = None, parameter_overrides: list[Parameter] | None = None,
                 start: bool = True):
        super().__init__(node_name, namespace=namespace, context=context, cli_args=cli_args,
                         parameter_overrides=parameter_overrides)
        self._lock = threading.RLock()
        self.recorder = None
        self.recording_error = ""   # set once a write to the recording failed
        self._timer = self._graph_timer = None
        self.done = Future()
        try:
            base, nv, self.preset = NP.declare_all(self)
            self.mujoco_model = nv[NP.MUJOCO_MODEL]
            names = NP.joint_names_in_overrides(self) if self.mujoco_model else None
            joint_params, explicit = NP.declare_joints(self, base, nv["node.joint_name"], names)
            if self.mujoco_model and not (explicit or names):
                raise ParameterError(NP.MUJOCO_MODEL, "name the robot's joints the actuators drive: "
                                     "joints:=[...] or joint.<name>.preset:=...")
        except BaseException:
            self.destroy_node()
            raise
        self.node_values = nv
        # the robot's topics first: a first compile of the kernel (below) takes 8 s of CPU, a minute and more on a
        # busy machine, and the node and its joint_states, diagnostics and command topics are discoverable all
        # that time (the middleware's threads do not need this one); they carry data once the loop runs
        qos = QoSProfile(depth=10)
        self._qos = qos
        self.pub_joint = self.create_publisher(JointState, nv["node.joint_states_topic"], qos)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos)
        self.pub_clock = self.create_publisher(ClockMsg, "/clock", qos) if nv["node.publish_clock"] else None
        # deep command queues: in lock-step mode every command counts (one period each), even in bursts
        cq = self._cq = QoSProfile(depth=COMMAND_QUEUE_DEPTH)
        self.sub_commands = self.create_subscription(Float64MultiArray, "~/commands", self._on_commands, cq)
        topic = nv["node.joint_commands_topic"]
        self.sub_joint_commands = self.create_subscription(JointState, topic, self._on_joint_commands, cq) \
            if topic else None
        # compile (or load from numba's cache) the physics kernel now, before simulation time is tied to the
        # wall clock: a first step that compiles would otherwise be a slip of seconds
        self.kernel_warm_up_s = warm_up()
        # joints given (or a robot): per-joint topics under ~/<joint>/
        self.multi = explicit or bool(self.mujoco_model)
        period_ns = int(round(1e9 / nv["node.publish_rate"]))
        try:
            self.plant = self._make_plant(joint_params, period_ns)
        except BaseException:
            self.destroy_node()
            raise
        # values outside their usual range (accepted: sanity limits) and a current loop the motor can outrun
        # (it diverges at speed): said at start-up, and the same for a value set at run time
        self._log_sanity({name: sanity_warnings(p) for name, p in joint_params.items()})
        config = SchedulerConfig(
            period_ns=period_ns, time_factor=nv["node.time_factor"], lock_step=nv["node.lock_step"],
            watchdog_ns=int(round(nv["node.watchdog_timeout"] * 1e9)),
            max_sim_ns=int(round(nv["node.max_sim_time"] * 1e9)),
            diag_period_ns=max(period_ns, int(round(1e9 / nv["node.diagnostics_rate"]))),
            detail_period_ns=max(period_ns, int(round(1e9 / nv["node.detail_rate"])))
            if nv["node.detail_rate"] > 0 else period_ns,
            commands_interface=nv["node.commands_interface"], name_joints=self.multi)
        self.scheduler = Scheduler(self.plant, config, log=self.get_logger(), on_period=self._on_period,
                                   on_finished=self._on_finished)
        self.joints: list[JointCommand] = self.scheduler.joints
        self._stamp_now = TimeMsg()   # one Time message, updated in place: every header of a period shares it
        self.topics = [JointTopics(j.name, self._stamp_now, f"~/{j.name}/" if self.multi else "~/")
                       for j in self.joints]

        self._detail_all: list = []   # (joint index, publisher, fill) of every detail publisher created
        self._detail_live: list = []
        self._next_detail_refresh = 0
        # the per-joint topics: all now, or each once the graph shows a peer for it (node.joint_topics)
        mode = nv["node.joint_topics"]
        self.joint_topics_on_demand = (mode == "on_demand" or (mode == "auto" and self.multi)) \
            and not nv["node.record"]   # (a recording registers every topic up front)
        self._pending: list[tuple[str, bool, int, str]] = []   # (resolved name, is command, joint, topic)
        for k, jt in enumerate(self.topics):
            for topic in (*COMMAND_TOPICS, *DETAIL_TOPICS):
                if self.joint_topics_on_demand:
                    self._pending.append((self.resolve_topic_name(jt.prefix + topic), topic in COMMAND_TOPICS,
                                          k, topic))
                else:
                    self._create_joint_entity(k, topic)
        # resolved names, looked up once (a topic_name property call per message costs)
        self._commands_topic = self.sub_commands.topic_name
        self._joint_commands_topic = self.sub_joint_commands.topic_name if self.sub_joint_commands else ""

        # reusable messages (rclpy serialises at publish; reuse is safe): the JointState shares the
        # scheduler's position/velocity/effort arrays and the period stamp, so a period changes no field
        m = self._m_joint = JointState(name=[j.name for j in self.joints])
        m.header.frame_id = self.joints[0].name if not self.multi else ""
        m.header.stamp = self._stamp_now
        m.position, m.velocity, m.effort = self.scheduler.position, self.scheduler.velocity, self.scheduler.effort
        self.scheduler.share_joint_state(m.position, m.velocity, m.effort)   # (the setters copied them)
        self._m_clock = ClockMsg(clock=self._stamp_now)
        self._m_diag: DiagnosticArray | None = None   # built at the first diagnostics, then updated in place
        # the full outputs on detail periods only once a detail topic has a subscriber (see _refresh_detail)
        self.scheduler.detail_wanted = False
        # a robot model: the whole multibody's state (free base included) at the detail cadence, recorded
        self.pub_body = None
        if self.mujoco_model:
            self.pub_body = self.create_publisher(Float64MultiArray, "~/mujoco/body_state", qos)
            self._m_body = labelled_layout(Float64MultiArray(), self.plant.body_state_labels())

        record = nv["node.record"]
        if record:
            self._open_recorder(record)
        self._type_errors: dict[str, str] = {}   # run-time values of the wrong type (see _pre_set_parameters)
        # (an rclpy without pre-set callbacks refuses an integer for a double by its own type check, as before)
        if hasattr(self, "add_pre_set_parameters_callback"):
            self.add_pre_set_parameters_callback(self._pre_set_parameters)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        if self._pending:
            self._graph_timer = self.create_timer(GRAPH_POLL_S, _timer_callback(self._discover), clock=self._steady)
        if start:
            self.start()

    def _create_joint_entity(self, k: int, topic: str) -> None:
        """Create joint ``k``'s subscription (a :data:`COMMAND_TOPICS` topic) or publisher (a
        :data:`DETAIL_TOPICS` topic)."""
        j, jt = self.joints[k], self.topics[k]
        name = jt.prefix + topic
        if topic in DETAIL_TOPICS:
            mtype = Temperature if topic.endswith("temperature") else Float64MultiArray
            pub = self.create_publisher(mtype, name, self._qos)
            setattr(jt, DETAIL_TOPICS[topic], pub)
            self._detail_all.append((k, pub, jt.detail()[topic]))
            self._next_detail_refresh = 0   # look at its subscribers at the next detail period
            return
        if topic == "reset_fault":
            sub = self.create_subscription(Empty, name, lambda m: self._on_reset(j, jt, m), self._qos)
        elif topic == "load_torque":
            sub = self.create_subscription(Float64, name, lambda m: self._on_load(j, jt, m), self._cq)
        else:
            kind = topic.split("_")[0]   # current | torque
            attr = COMMAND_TOPICS[topic]
            sub = self.create_subscription(Float64, name,
                                           lambda m: self._on_scalar(j, getattr(jt, attr), kind, m), self._cq)
        setattr(jt, COMMAND_TOPICS[topic], sub)

    def _discover(self) -> None:
        """``node.joint_topics`` on demand (every :data:`GRAPH_POLL_S` s of wall time): create the per-joint
        subscriptions whose topic has a publisher and the detail publishers whose topic has a subscriber. One
        graph query lists the topics; only those named in it are counted. Created entities stay (a controller
        that restarts finds its subscription matched at once; nothing is torn down under a queued message)."""
        try:
            graph = {name for name, _ in self.get_topic_names_and_types()}
        except Exception:  # noqa: BLE001 - shutting down: the next poll (if any) tries again
            return
        still = []
        with self._lock:
            for item in self._pending:
                name, command, k, topic = item
                if name in graph and (self.count_publishers(name) if command else self.count_subscribers(name)):
                    self._create_joint_entity(k, topic)
                    self.get_logger().info(f"{name}: a {'publisher' if command else 'subscriber'} appeared; "
                                           f"{'subscribed' if command else 'publishing'} from now on")
                else:
                    still.append(item)
            self._pending = still
            if not still and self._graph_timer is not None:   # every per-joint topic exists: stop looking
                self.destroy_timer(self._graph_timer)
                self._graph_timer = None

    def _make_plant(self, joint_params, period_ns: int):
        """The actuators alone (:class:`ActuatorPlant`) or, with ``mujoco.model``, under the robot's bodies
        (:class:`bldc_actuator.mujoco.CoupledSim`: MuJoCo integrates the bodies, the joint states are theirs)."""
        if not self.mujoco_model:   # the current loop's warning: logged per joint by __init__, not again here
            return ActuatorPlant(joint_params, warn=False)
        try:
            from .mujoco.coupling import CoupledSim
        except ModuleNotFoundError as exc:
            raise ParameterError(NP.MUJOCO_MODEL, f"needs MuJoCo (pip install .[mujoco]): {exc}") from None
        try:
            plant = CoupledSim(self.mujoco_model, joint_params, warn=False)
        except ValueError as exc:
            raise ParameterError(NP.MUJOCO_MODEL, str(exc)) from None
        h_ns = int(round(plant.timestep * 1e9))
        if period_ns % h_ns:
            raise ParameterError("node.publish_rate", f"the publish period ({period_ns} ns) must be a whole number "
                                 f"of the model's body steps (option/timestep {h_ns} ns)")
        self.get_logger().info(f"mujoco: {self.mujoco_model}, body step {h_ns * 1e-6:g} ms, joints "
                               f"{', '.join(plant.joints)} coupled (rotor inertia as armature, drive, thermal)")
        return plant

    # ------------------------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Publish the initial state and start stepping (a steady-clock timer unless lock-step)."""
        with self._lock:
            self._on_period(*self.scheduler.first_period())
            if self._timer is None and not self.scheduler.config.lock_step:
                self._start_timer()

    def _start_timer(self) -> None:
        # created right after the anchor: the wake-ups fall a tenth of a period after each period became due
        self.scheduler.start()
        self._timer = self.create_timer(self.scheduler.wake_period_ns * 1e-9, _timer_callback(self._on_tick),
                                        clock=self._steady)

    def close(self) -> None:
        """Stop stepping and finalise the recording (idempotent)."""
        with self._lock:
            if self._timer is not None:
                self.destroy_timer(self._timer)
                self._timer = None
            if self._graph_timer is not None:
                self.destroy_timer(self._graph_timer)
                self._graph_timer = None
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

    # node-level views of the scheduler (one joint or many)
    t_ns = property(lambda self: self.scheduler.t_ns, doc="simulation time [ns]")
    periods = property(lambda self: self.scheduler.periods, doc="periods advanced")
    slips = property(lambda self: self.scheduler.slips, doc="wake-ups that dropped a debt of wall time")
    period_ns = property(lambda self: self.scheduler.config.period_ns, doc="publish period [ns] (simulation)")
    lock_step = property(lambda self: self.scheduler.config.lock_step)
    commands_received = property(lambda self: self.scheduler.commands_received)
    commands_rejected = property(lambda self: self.scheduler.commands_rejected)
    last_rejection = property(lambda self: self.scheduler.last_rejection)
    rejections = property(lambda self: self.scheduler.rejections, doc="recent rejection reasons, newest last")
    real_time_factor = property(lambda self: self.scheduler.real_time_factor)

    @property
    def finished(self) -> bool:
        return self.done.done()

    # ------------------------------------------------------------------------------------ stepping

    def _on_tick(self) -> None:
        with self._lock:
            if self.scheduler.finished:
                return
            try:
                self.scheduler.tick()
            except Exception:
                if self.context.ok():
                    raise
                # the context was shut down (Ctrl-C, a signal): publishing failed; a normal stop

    def advance(self, periods: int = 1) -> None:
        """Advance ``periods`` publish periods now (public for tests, benchmarks and embedding)."""
        with self._lock:
            self.scheduler.advance(periods)

    def _on_finished(self, t_ns: int) -> None:
        if not self.done.done():
            self.done.set_result(t_ns)

    # ------------------------------------------------------------------------------------ publishing

    def _on_period(self, t_ns: int, outs: list[dict] | None, detail: bool, diag: bool) -> None:
        stamp = self._stamp_now
        stamp.sec, stamp.nanosec = divmod(t_ns, 1_000_000_000)
        publish = self._publish
        if self.pub_clock is not None:
            publish(self.pub_clock, self._m_clock, t_ns)
        if self.recorder is None:
            self.pub_joint.publish(self._m_joint)
        else:
            publish(self.pub_joint, self._m_joint, t_ns)
        if detail and (self._detail_all or self.pub_body is not None):   # (any detail topic created)
            now = time.monotonic_ns()
            if now >= self._next_detail_refresh:
                self._refresh_detail(now)
            if self._detail_live:
                if outs is None:   # (a subscriber appeared this period)
                    outs = self.plant.all_outputs()
                for k, pub, fill in self._detail_live:
                    publish(pub, fill(outs[k]), t_ns)
            if self.pub_body is not None and (self.recorder is not None or self.pub_body.get_subscription_count()):
                self._m_body.data = self.plant.body_state().tolist()
                publish(self.pub_body, self._m_body, t_ns)
        if diag:
            self._publish_diagnostics(outs, t_ns)

    def _refresh_detail(self, now: int) -> None:
        """The detail topics to publish: all while recording, else those with a subscriber (on demand)."""
        everything = self.recorder is not None
        self._detail_live = [d for d in self._detail_all if everything or d[1].get_subscription_count() > 0]
        self.scheduler.detail_wanted = bool(self._detail_live)
        self._next_detail_refresh = now + DETAIL_REFRESH_NS

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

    def _status(self, h: Health) -> DiagnosticStatus:
        name = f"{self.get_fully_qualified_name()}: " + (h.joint if self.multi else "actuator")
        return DiagnosticStatus(level=_LEVEL_BYTES[h.level], name=name, message=h.message, hardware_id=h.joint,
                                values=[KeyValue(key=k, value=v) for k, v in h.values.items()])

    def diagnostic_statuses(self, outs: list[dict] | None = None) -> list[DiagnosticStatus]:
        """One diagnostics status per joint (over the window since the last one, which this resets); new
        messages (the published ones are reused)."""
        return [self._status(h) for h in self._health(outs)]

    def diagnostic_status(self, joint: int = 0) -> DiagnosticStatus:
        """The current diagnostics entry of one joint (level, message, key values); also resets the window."""
        return self.diagnostic_statuses()[joint]

    def _health(self, outs: list[dict] | None):
        rec = self.recording_error or (str(self.node_values["node.record"]) if self.recorder else "off")
        return self.scheduler.health(outs, error=self.recording_error, values={"recording": rec})

    def _publish_diagnostics(self, outs: list[dict], t_ns: int) -> None:
        """Publish /diagnostics: one reusable DiagnosticArray whose statuses and key values are updated in place
        (building 12 statuses of ~20 KeyValue messages anew cost more than serialising them)."""
        health = self._health(outs)
        msg = self._m_diag
        if msg is None:
            msg = self._m_diag = DiagnosticArray(status=[self._status(h) for h in health])
            self._diag_keys = [tuple(h.values) for h in health]
        else:
            keys = self._diag_keys
            for k, (st, h) in enumerate(zip(msg.status, health)):
                st.level = _LEVEL_BYTES[h.level]
                st.message = h.message
                if keys[k] == tuple(h.values):
                    for kv, value in zip(st.values, h.values.values()):
                        kv.value = value
                else:   # (the set of keys changed: rebuild this status)
                    msg.status[k] = self._status(h)
                    keys[k] = tuple(h.values)
        stamp = msg.header.stamp
        stamp.sec, stamp.nanosec = divmod(t_ns, 1_000_000_000)
        self._publish(self.pub_diag, msg, t_ns)

    # ------------------------------------------------------------------------------------ commands

    def _record_in(self, sub, msg) -> None:
        if self.recorder is not None:
            self._write(sub.topic_name, msg, self.t_ns)

    def _on_scalar(self, j: JointCommand, sub, kind: str, msg: Float64) -> None:
        self._record_in(sub, msg)
        with self._lock:
            self.scheduler.command(j, kind, msg.data, sub.topic_name)
            if not self.multi:   # several joints: only whole-robot commands advance a lock-step period
                self.scheduler.lock_step_period()

    def _on_commands(self, msg: Float64MultiArray) -> None:
        """ros2_control ForwardCommandController convention: one value per joint, ``joints`` order."""
        if self.recorder is not None:
            self._write(self._commands_topic, msg, self.t_ns)
        with self._lock:
            self.scheduler.commands(msg.data, self._commands_topic)
            self.scheduler.lock_step_period()

    def _on_joint_commands(self, msg: JointState) -> None:
        """sensor_msgs/JointState commands as ros2_control's topic_based hardware interface sends them (see
        :meth:`bldc_actuator.scheduler.Scheduler.joint_commands`)."""
        self._record_in(self.sub_joint_commands, msg)
        with self._lock:
            self.scheduler.joint_commands(msg.name, msg.position, msg.velocity, msg.effort,
                                          self._joint_commands_topic)
            self.scheduler.lock_step_period()

    def _on_load(self, j: JointCommand, jt: JointTopics, msg: Float64) -> None:
        self._record_in(jt.sub_load, msg)
        with self._lock:
            self.scheduler.load_torque(j, msg.data, jt.sub_load.topic_name, SPECS["load.load_torque"].range[1])

    def _on_reset(self, j: JointCommand, jt: JointTopics, msg: Empty) -> None:
        self._record_in(jt.sub_reset, msg)
        with self._lock:
            self.scheduler.reset_fault(j)

    # ------------------------------------------------------------------------------------ parameters

    def _log_sanity(self, warnings: dict[str, list[str]]) -> None:
        """Log each joint's sanity warnings (:func:`params.sanity_warnings`); joints with the same warning
        share one line."""
        lines: dict[str, list[str]] = {}
        for joint, msgs in warnings.items():
            for msg in msgs:
                lines.setdefault(msg, []).append(joint)
        for msg, joints in lines.items():
            self.get_logger().warning(f"joint {', '.join(joints)}: {msg}")

    def _pre_set_parameters(self, plist: list[Parameter]) -> list[Parameter]:
        """Before rclpy's type check: an integer for a double (``ros2 param set ... drive.bus_voltage 48``) is
        that double, as in a parameter file; a value of another wrong type is kept back (the current value
        stands in) and refused by :meth:`_on_set_parameters` with a message naming the field, its type, range
        and unit."""
        self._type_errors = {}
        out = []
        for p in plist:
            p = NP.coerce_set(p)
            err = NP.type_error(p)
            if err is not None and self.has_parameter(p.name):
                self._type_errors[p.name] = err
                p = self.get_parameter(p.name)
            out.append(p)
        return out

    def _on_set_parameters(self, plist: list[Parameter]) -> SetParametersResult:
        errors = [self._type_errors.pop(p.name) for p in plist if p.name in self._type_errors]
        self._type_errors = {}
        if errors:
            return SetParametersResult(successful=False, reason="; ".join(errors))
        model: dict[str, Any] = {}
        node: dict[str, Any] = {}
        try:
            for p in plist:
                if p.name in SPECS:
                    model[p.name] = NP.from_ros(SPECS[p.name].type, p.value)
                elif p.name in NP.NODE_PARAMS:
                    node[p.name] = NP.check_node_value(p.name, p.value)
            new = [from_flat(model, base=self.plant.params(j.name)) for j in self.joints] if model else None
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if new is not None:   # the same sanity warnings as at start-up, for the fields set now
            old_loop = {j.name: current_loop_warning(self.plant.params(j.name)) for j in self.joints}
            warn = {}
            for j, params in zip(self.joints, new):   # the fields set now, and a current-loop warning that is new
                warn[j.name] = [m for m in sanity_warnings(params)
                                if m.split(" ", 1)[0] in model or (m.split(" ", 1)[0] not in SPECS
                                                                   and m != old_loop[j.name])]
            self._log_sanity(warn)
        with self._lock:
            if new is not None:   # a node-level model parameter applies to every joint
                for j, params in zip(self.joints, new):
                    self.scheduler.update_params(j, params)
            for name, value in node.items():
                self.node_values[name] = value
                if name == "node.time_factor":
                    if self._timer is not None:   # re-time the wake-ups (one per period of wall time)
                        self.destroy_timer(self._timer)
                        self._timer = None
                        self.scheduler.set_time_factor(value)
                        self._start_timer()
                    else:
                        self.scheduler.set_time_factor(value)
                elif name == "node.watchdog_timeout":
                    self.scheduler.set_watchdog_timeout(int(round(value * 1e9)))
                elif name == "node.commands_interface":
                    self.scheduler.set_commands_interface(value)
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
        out: dict[str, Any] = flat(self.plant.params(self.joints[0].name))
        out.update(self.node_values)
        out["preset"] = self.preset
        if self.multi:
            out[NP.JOINTS] = [j.name for j in self.joints]
            for j in self.joints:
                out.update({f"{NP.JOINT_PREFIX}{j.name}.{k}": v for k, v in flat(self.plant.params(j.name)).items()})
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
        from . import drive_tuning
        from .recording import McapRecorder
        from .voltage_timing import kernel_declaration

        meta = {"node": self.get_fully_qualified_name(), "joint_name": self.joints[0].name,
                "joints": ",".join(j.name for j in self.joints),
                "time": "log_time = simulation time [ns]", "package": "bldc_actuator"}
        # when the logged q/d voltage acts (the held voltage at each ~/q_axis_state instant) and the motor values the
        # drive's current loop is tuned with (the simulated motor's own, unless drive.controller_* say otherwise):
        # the diagnosis replays the recording with that drive
        decl = {j.name: {**kernel_declaration(self.plant.params(j.name), self.scheduler.config.detail_period_ns * 1e-9),
                         **drive_tuning.declaration(self.plant.params(j.name))} for j in self.joints}
        first = decl[self.joints[0].name]
        meta.update(first)
        for name, d in decl.items():
            if d != first:
                meta.update({f"{k}.{name}": v for k, v in d.items()})
        self.recorder = McapRecorder(path, parameters=self.all_parameters(), metadata=meta)
        topics = [(self.pub_joint, JointState), (self.pub_diag, DiagnosticArray),
                  (self.sub_commands, Float64MultiArray)]
        if self.sub_joint_commands is not None:
            topics.append((self.sub_joint_commands, JointState))
        for j in self.topics:
            topics += [(j.pub_phase, Float64MultiArray), (j.pub_q, Float64MultiArray), (j.pub_tw, Temperature),
                       (j.pub_th, Temperature), (j.sub_current, Float64), (j.sub_torque, Float64),
                       (j.sub_load, Float64), (j.sub_reset, Empty)]
        if self.pub_clock is not None:
            topics.append((self.pub_clock, ClockMsg))
        if self.pub_body is not None:
            topics.append((self.pub_body, Float64MultiArray))
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
       ~/winding_temperature, ~/housing_temperature (per joint, at node.detail_rate, on demand: only while
       subscribed, or recording), /diagnostics (one status per joint; level changes are also logged),
       /clock (node.publish_clock), ~/mujoco/body_state (with mujoco.model: the whole multibody's qpos and
       qvel, labelled, at node.detail_rate, on demand)

With joints given, each per-joint topic is created once a publisher (commands) or subscriber (detail topics)
appears on it, checked every second (node.joint_topics:=always creates them all at start).
Per-joint parameters: joint.<name>.preset, joint.<name>.params_file, joint.<name>.<model parameter>.
A robot: -p mujoco.model:=robot.xml -p joint.knee.preset:=ak80_9 ... drives the MJCF model's joints (MuJoCo
integrates the bodies; the joints are those named in joint.<name>.*, or joints:=[...]).

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
    12 joints at 1 kHz): events needs about a third of the CPU single does, and makes lock-step round trips
    several times faster."""
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
            node = ActuatorNode(parameter_overrides=overrides, start=False)
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
            f"{node.plant.params(node.joints[0].name).drive.current_loop_rate:g} Hz; kernel ready in {node.kernel_warm_up_s:.2f} s "
            f"({'compiled' if COMPILED else 'pure Python'})")
        node.start()   # last: simulation time is tied to the wall clock from here, right before spinning
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
