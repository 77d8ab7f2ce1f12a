"""The node's scheduler, without ROS: stepping a plant in simulation time, lock-step, the command watchdog,
command checks and the diagnostics levels. :mod:`bldc_actuator.node` is the ROS wiring around it (topics,
parameters, messages, recording); benchmarks and tests drive a :class:`Scheduler` directly.

Time
    :meth:`Scheduler.tick` (called by the node's steady-clock timer every :attr:`Scheduler.wake_period_ns`)
    advances the plant by whole periods (``period_ns``, one publication each) until simulation time has
    caught up with ``time_factor`` x the wall time since the anchor. Simulation time is anchored a tenth of a
    period ahead of the wake-ups, so each wake-up normally advances exactly one period, just after it fell due. A wake-up that finds
    more than ``max_batch_wall_ns`` of wall time due drops the debt (a *slip*: counted, reported WARN, never a
    burst). ``time_factor`` 0 or inf: as fast as possible, batches of periods of at most ``max_batch_wall_ns``
    wall time per wake-up. Lock-step: no timer; :meth:`lock_step_period` after each command message.
Commands
    :meth:`command` (one joint), :meth:`commands` (one value per joint, the ros2_control forward-controller
    array), :meth:`joint_commands` (names + position/velocity/effort, ros2_control's topic-based interface),
    :meth:`load_torque`. Rejected: non-finite values, more than :data:`ABSURD_FACTOR` x the drive's current
    limit (in current or the equivalent output torque), an array of the wrong length (every joint), a joint
    command carrying position or velocity (the whole message, for the joints it names), an unknown joint name
    (that name only). Each rejection is counted for the joints it concerns and logged, throttled per reason
    (:data:`LOG_THROTTLE_NS`), so different reasons never hide each other.
Watchdog
    once a joint has had a command, ``watchdog_ns`` of simulation time without one sets its current command
    to zero (logged once; cleared, and logged, by the next command).
Diagnostics
    :meth:`health` returns one :class:`Health` per joint (level OK/WARN/ERROR, reasons, key values) over the
    window since the last call; every change of a joint's level is logged once on the console.
"""

from __future__ import annotations

import array
import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Protocol, Sequence

from .params import ActuatorParams
from .plant import Plant

OK, WARN, ERROR = 0, 1, 2
LEVEL_NAMES = ("OK", "WARN", "ERROR")
#: simulation time is anchored 1/ANCHOR_LEAD of a wake-up period ahead of the wake-ups
ANCHOR_LEAD = 10
#: a command beyond this multiple of the drive's current limit (in current) is rejected as absurd;
#: commands between 1x and this are accepted and limited by the drive like a real one would
ABSURD_FACTOR = 10.0
#: diagnostics level ERROR once thermal derating has cut the current limit by more than this fraction
DERATE_ERROR_FRACTION = 0.5
#: longest wall time one wake-up may spend stepping before yielding to the executor [ns]
MAX_BATCH_WALL_NS = 20_000_000
#: one console line per rejection reason per this wall time [ns]; the ones held back are counted
LOG_THROTTLE_NS = 1_000_000_000
#: at most one console line per joint about its diagnostics level per this wall time [ns]: a level that
#: flaps is logged as it stands once this has passed (with the number of changes), never left stale
LEVEL_LOG_MIN_NS = 1_000_000_000
#: the time-factor warning (slips: the wall clock outran the physics) is raised by a slip and cleared only
#: after this much wall time without one [ns]: a factor missed now and then is one WARN, not a flapping level
PACE_HOLD_NS = 5_000_000_000
#: commands interfaces of ``~/commands``: what one element means
COMMANDS_INTERFACES = {"effort": "torque", "current": "current"}


class Log(Protocol):
    """What the scheduler logs through: rclpy's node logger or a :class:`logging.Logger`."""

    def info(self, message: str) -> object: ...

    def warning(self, message: str) -> object: ...

    def error(self, message: str) -> object: ...


@dataclass
class SchedulerConfig:
    period_ns: int = 1_000_000          # simulation time per published period [ns]
    time_factor: float = 1.0            # simulated seconds per wall second; 0 or inf = as fast as possible
    lock_step: bool = False             # one period per command message instead of the wall clock
    watchdog_ns: int = 500_000_000      # simulation time without a command before zero current; 0 = off
    max_sim_ns: int = 0                 # stop at this simulation time; 0 = never
    diag_period_ns: int = 100_000_000   # simulation time between diagnostics
    detail_period_ns: int = 1_000_000   # simulation time between per-joint detail publications
    commands_interface: str = "effort"  # meaning of :meth:`Scheduler.commands` elements
    name_joints: bool = False           # reasons name the joint (several joints)
    max_batch_wall_ns: int = MAX_BATCH_WALL_NS


@dataclass
class JointCommand:
    """One joint's command state, counters and diagnostics window."""

    name: str
    index: int
    kind: str = "current"               # "current" [A] | "torque" [N*m]
    value: float = 0.0
    last_command_ns: int | None = None  # the watchdog is armed by the first command
    watchdog_active: bool = False
    commands_received: int = 0
    commands_rejected: int = 0
    last_rejection: str = ""
    load_torque_extra: float = 0.0
    win_saturated: int = 0
    win_rejected: int = 0
    level: int = OK                     # level of the last diagnostics
    logged_level: int = OK              # level of the last console line about it
    level_logged_ns: int | None = None  # wall time of that line
    level_changes: int = 0              # level changes since that line
    current_abs_max: float = math.inf   # |command| limits (absurd beyond), A and N*m at the output
    torque_abs_max: float = math.inf


def absurd_limits(p: ActuatorParams) -> tuple[float, float]:
    """``(current [A, q-axis], torque [N*m, output])``: a command beyond either in magnitude is absurd and rejected
    (:data:`ABSURD_FACTOR` x ``drive.current_limit``, and its output torque through ``motor.torque_constant_q`` and
    ``gear.gear_ratio``); the node's rule, which ``bldc-actuator simulate`` applies to its profiles too."""
    current = ABSURD_FACTOR * p.drive.current_limit
    return current, current * p.motor.torque_constant_q * p.gear.gear_ratio


@dataclass(frozen=True)
class Health:
    """One joint's diagnostics: level (:data:`OK`, :data:`WARN`, :data:`ERROR`), message, key values."""

    joint: str
    level: int
    message: str
    values: dict[str, str]


@dataclass
class Throttle:
    """Allows one event per key per ``interval_ns`` of wall time and counts the ones held back."""

    interval_ns: int
    clock: Callable[[], int] = time.monotonic_ns
    _last: dict = field(default_factory=dict)
    _held: dict = field(default_factory=dict)

    def allow(self, key) -> tuple[bool, int]:
        """``(allowed, held back since the last allowed one)``."""
        now = self.clock()
        last = self._last.get(key)
        if last is not None and now - last < self.interval_ns:
            self._held[key] = self._held.get(key, 0) + 1
            return False, 0
        self._last[key] = now
        return True, self._held.pop(key, 0)


def _default_log() -> Log:
    import logging

    return logging.getLogger("bldc_actuator.scheduler")


class Scheduler:
    """Steps ``plant`` in periods of ``config.period_ns``; see the module docstring.

    ``on_period(t_ns, outputs, detail_due, diagnostics_due)`` is called after every period (the node
    publishes there; ``outputs`` is ``plant.all_outputs()``, or None on a period where neither diagnostics
    nor wanted details are due and the plant has the cheaper ``joint_states()``); :attr:`position`, :attr:`velocity`, :attr:`effort` (``array('d')``, ``plant.joints``
    order, output side) hold that period's joint state, updated in place (a message may share them).
    ``on_finished(t_ns)`` is called once when ``config.max_sim_ns`` is reached. ``clock`` is the wall clock
    [ns] (steady)."""

    def __init__(self, plant: Plant, config: SchedulerConfig | None = None, *, log: Log | None = None,
                 on_period: Callable[[int, list, bool, bool], None] | None = None,
                 on_finished: Callable[[int], None] | None = None, clock: Callable[[], int] = time.monotonic_ns):
        self.plant = plant
        self.config = cfg = config or SchedulerConfig()
        if cfg.period_ns <= 0:
            raise ValueError(f"period_ns: expected > 0 ns, got {cfg.period_ns}")
        if cfg.commands_interface not in COMMANDS_INTERFACES:
            raise ValueError(f"commands_interface: expected one of {', '.join(COMMANDS_INTERFACES)}, got "
                             f"{cfg.commands_interface!r}")
        self.log = log or _default_log()
        self.on_period = on_period
        self.on_finished = on_finished
        self.clock = clock
        self.joints = [JointCommand(name, k) for k, name in enumerate(plant.joints)]
        self.by_name = {j.name: j for j in self.joints}
        for j in self.joints:
            self._limits(j, plant.params(j.name))
        n = len(self.joints)
        self.position = array.array("d", bytes(8 * n))
        self.velocity = array.array("d", bytes(8 * n))
        self.effort = array.array("d", bytes(8 * n))
        self.outputs: list[dict] = plant.all_outputs()
        self._fill(self.outputs)
        self.t_ns = plant.t_ns
        self.periods = 0
        self.slips = 0
        self.finished = False
        self.commands_received = 0
        self.commands_rejected = 0
        self.last_rejection = ""
        self.rejections: deque[str] = deque(maxlen=100)   # recent rejection reasons, newest last
        self.real_time_factor = float("nan")
        #: when a list: (ideal wall time, wall time after publication) [ns] of every period the clock advanced
        self.timing: list[tuple[int, int]] | None = None
        self._throttle = Throttle(LOG_THROTTLE_NS, clock)
        # the time-factor warning with a hold (PACE_HOLD_NS): raised at a slip, its measurement window since then
        self._pace_warn = False
        self._pace_last_slip = 0
        self._pace_wall0 = self._pace_sim0 = self._pace_slips = 0
        self._pace_text = ""
        self._next_diag_ns = self.t_ns
        self._next_detail_ns = self.t_ns
        self._watchdog_check_ns: int | None = None   # earliest simulation time a watchdog can fire
        self._win_periods = self._win_slips = 0
        self._win_wall0, self._win_sim0 = clock(), self.t_ns
        self._anchor_wall = self._anchor_sim = 0
        self._started = False
        #: whether the per-joint detail topics want the full outputs on detail periods (the node clears it
        #: while nothing subscribes to them)
        self.detail_wanted = True
        self._joint_states = getattr(plant, "joint_states", None)   # optional cheap read, see plant.py
        #: the last ~/commands array if every element was accepted and nothing was commanded since (see
        #: :meth:`commands`)
        self._held: Sequence[float] | None = None

    def share_joint_state(self, position: array.array, velocity: array.array, effort: array.array) -> None:
        """Write every period's joint state into these ``array('d')`` (one element per joint) from now on,
        e.g. the arrays of a reusable message: then a period changes no message field."""
        n = len(self.joints)
        for name, a in (("position", position), ("velocity", velocity), ("effort", effort)):
            if not isinstance(a, array.array) or a.typecode != "d" or len(a) != n:
                raise ValueError(f"{name}: expected array('d') of {n} element(s), got {a!r}")
        position[:], velocity[:], effort[:] = self.position, self.velocity, self.effort
        self.position, self.velocity, self.effort = position, velocity, effort

    # ------------------------------------------------------------------------------------ time

    @property
    def as_fast_as_possible(self) -> bool:
        f = self.config.time_factor
        return f == 0.0 or math.isinf(f)

    @property
    def wake_period_ns(self) -> int:
        """Wall time between wake-ups (:meth:`tick`): one period of wall time, at least 1 ms (faster than real
        time: several periods per wake-up), 1 ms as fast as possible."""
        if self.as_fast_as_possible:
            return 1_000_000
        return max(int(self.config.period_ns / self.config.time_factor), 1_000_000)

    def start(self) -> None:
        """Anchor simulation time to the wall clock now (call when the wake-ups start)."""
        self._anchor()
        self._started = True

    def _anchor(self) -> None:
        """Tie simulation time to the wall clock now, a tenth of a wake-up ahead: a timer started right after
        this fires a tenth of a period after each period fell due (timers never fire early), so every
        wake-up finds exactly one period due and publishes it with little delay."""
        self._anchor_sim = self.t_ns
        self._anchor_wall = self.clock() - (0 if self.as_fast_as_possible else self.wake_period_ns // ANCHOR_LEAD)

    def set_time_factor(self, time_factor: float) -> None:
        """Change ``time_factor`` at run time (re-anchors; the caller re-times its wake-ups to
        :attr:`wake_period_ns`)."""
        if not (time_factor >= 0.0):
            raise ValueError(f"time_factor: expected >= 0 (0 or inf = as fast as possible), got {time_factor!r}")
        self.config.time_factor = time_factor
        self._pace_warn = False   # a new target: judged afresh
        if self._started:
            self._anchor()

    def set_watchdog_timeout(self, watchdog_ns: int) -> None:
        self.config.watchdog_ns = int(watchdog_ns)
        self._watchdog_check_ns = None

    def set_commands_interface(self, interface: str) -> None:
        if interface not in COMMANDS_INTERFACES:
            raise ValueError(f"commands_interface: expected one of {', '.join(COMMANDS_INTERFACES)}, "
                             f"got {interface!r}")
        self.config.commands_interface = interface
        self._held = None

    def tick(self) -> int:
        """One wake-up: advance every period that is due by the wall clock; returns how many."""
        if self.finished:
            return 0
        cfg = self.config
        if self.as_fast_as_possible:
            deadline = time.perf_counter_ns() + cfg.max_batch_wall_ns
            n = 0
            while not self.finished:
                self._advance_period()
                n += 1
                if time.perf_counter_ns() >= deadline:
                    break
            return n
        now = self.clock()
        f = cfg.time_factor
        target = self._anchor_sim + int((now - self._anchor_wall) * f)
        n = (target - self.t_ns) // cfg.period_ns
        limit = max(1, int(cfg.max_batch_wall_ns * f) // cfg.period_ns)
        if n > limit:   # cannot keep up: drop the debt instead of bursting later
            self.slips += 1
            self._win_slips += 1
            n = limit
            self._anchor_sim = self.t_ns + limit * cfg.period_ns
            self._anchor_wall = now - self.wake_period_ns // ANCHOR_LEAD
        timing = self.timing
        for _ in range(n):
            self._advance_period()
            if timing is not None:
                timing.append((self._anchor_wall + int((self.t_ns - self._anchor_sim) / f), self.clock()))
            if self.finished:
                break
        return max(n, 0)

    def advance(self, periods: int = 1) -> None:
        """Advance ``periods`` periods now, whatever the clock (tests, embedding, lock-step)."""
        for _ in range(periods):
            if self.finished:
                break
            self._advance_period()

    def lock_step_period(self) -> None:
        """In lock-step mode a command message (also a rejected one, so a controller waiting for the next
        state never stalls) advances one period."""
        if self.config.lock_step and not self.finished:
            self._advance_period()

    def _fill(self, outs: list[dict]) -> None:
        pos, vel, eff = self.position, self.velocity, self.effort
        for k, o in enumerate(outs):
            pos[k] = o["position_out"]
            vel[k] = o["velocity_out"]
            eff[k] = o["effort_out"]

    def _advance_period(self) -> None:
        cfg = self.config
        t = self.t_ns
        step = cfg.period_ns
        if cfg.max_sim_ns:
            step = min(step, cfg.max_sim_ns - t)
        if cfg.watchdog_ns and (self._watchdog_check_ns is None or t >= self._watchdog_check_ns):
            self._watchdog(t)
        plant = self.plant
        if step > 0:
            plant.step_ns(step)
        self.t_ns = t = plant.t_ns
        detail = t >= self._next_detail_ns
        if detail:
            self._next_detail_ns = t - t % cfg.detail_period_ns + cfg.detail_period_ns
        diag = t >= self._next_diag_ns
        if diag:
            self._next_diag_ns = t - t % cfg.diag_period_ns + cfg.diag_period_ns
        pos, vel, eff = self.position, self.velocity, self.effort
        joints = self.joints
        if self._joint_states is not None and not diag and not (detail and self.detail_wanted):
            # a period nobody needs more than the joint state of: the plant's cheap read
            outs = None
            for k, (p, v, e, saturated) in enumerate(self._joint_states()):
                pos[k], vel[k], eff[k] = p, v, e
                if saturated:
                    joints[k].win_saturated += 1
        else:
            outs = self.outputs = plant.all_outputs()
            for k, o in enumerate(outs):
                pos[k] = o["position_out"]
                vel[k] = o["velocity_out"]
                eff[k] = o["effort_out"]
                if o["voltage_saturated"]:
                    joints[k].win_saturated += 1
        self.periods += 1
        self._win_periods += 1
        if self.on_period is not None:
            self.on_period(t, outs, detail, diag)
        if cfg.max_sim_ns and t >= cfg.max_sim_ns and not self.finished:
            self.finished = True
            self.log.info(f"node.max_sim_time reached ({t * 1e-9:g} s)")
            if self.on_finished is not None:
                self.on_finished(t)

    def first_period(self) -> tuple[int, list, bool, bool]:
        """``(t_ns, outputs, detail, diagnostics)`` of the initial state (published before any step)."""
        t = self.t_ns
        self._next_detail_ns = t - t % self.config.detail_period_ns + self.config.detail_period_ns
        self._next_diag_ns = t - t % self.config.diag_period_ns + self.config.diag_period_ns
        return t, self.outputs, True, True

    def _watchdog(self, t: int) -> None:
        wd = self.config.watchdog_ns
        earliest = None
        for j in self.joints:
            if j.last_command_ns is None or j.watchdog_active:
                continue
            due = j.last_command_ns + wd
            if t >= due:
                j.watchdog_active = True
                self._held = None
                self.plant.set_current_command(j.name, 0.0)
                self.log.warning(f"command watchdog{self._for(j)}: no command for {wd * 1e-9:g} s of simulation "
                                 "time; current command set to zero until the next command")
            elif earliest is None or due < earliest:
                earliest = due
        # nothing can fire before the earliest deadline (a new command only moves deadlines later)
        self._watchdog_check_ns = earliest if earliest is not None else t + wd

    # ------------------------------------------------------------------------------------ commands

    def _limits(self, j: JointCommand, p: ActuatorParams) -> None:
        j.current_abs_max, j.torque_abs_max = absurd_limits(p)

    def _for(self, j: JointCommand) -> str:
        return f" for joint {j.name}" if self.config.name_joints else ""

    def reject(self, joints: Sequence[JointCommand], topic: str, key: str, reason: str) -> None:
        """Count a rejected message for ``joints`` (none: a node-level rejection that leaves every joint's
        diagnostics alone) and log it, throttled per ``(topic, key)``."""
        self.commands_rejected += 1
        self.last_rejection = f"{topic}: {reason}"
        self.rejections.append(self.last_rejection)
        for j in joints:
            j.commands_rejected += 1
            j.win_rejected += 1
            j.last_rejection = self.last_rejection
        allowed, held = self._throttle.allow((topic, key))
        if allowed:
            more = f" ({held} more like it in the last {LOG_THROTTLE_NS * 1e-9:g} s)" if held else ""
            self.log.warning(f"rejected command on {topic}: {reason}{more}")

    def command(self, j: JointCommand, kind: str, value, topic: str) -> bool:
        """Check and apply one joint's command (``kind`` "current" [A] or "torque" [N*m] at the output);
        False when rejected."""
        self._held = None
        unit = "A" if kind == "current" else "N*m"
        try:
            v = float(value)
        except (TypeError, ValueError):
            v = math.nan
        if not math.isfinite(v):
            self.reject((j,), topic, "not_finite", f"{kind} command{self._for(j)} must be a finite number "
                        f"[{unit}], got {value!r}")
            return False
        limit = j.current_abs_max if kind == "current" else j.torque_abs_max
        if abs(v) > limit:
            self.reject((j,), topic, "absurd", f"{kind} command{self._for(j)} {v:g} {unit} is absurd (more than "
                        f"{ABSURD_FACTOR:g} x drive.current_limit: |value| <= {limit:g} {unit})")
            return False
        if v != j.value or kind != j.kind or j.watchdog_active:   # (the same command again: the plant holds it)
            try:
                if kind == "current":
                    self.plant.set_current_command(j.name, v)
                else:
                    self.plant.set_torque_command(j.name, v)
            except Exception as exc:  # noqa: BLE001 - the node never dies on a message
                self.reject((j,), topic, "plant", f"{type(exc).__name__}: {exc}")
                return False
        j.kind, j.value = kind, v
        j.commands_received += 1
        self.commands_received += 1
        j.last_command_ns = self.t_ns
        if j.watchdog_active:
            j.watchdog_active = False
            self.log.info(f"command watchdog cleared{self._for(j)}: commands are back")
        return True

    def commands(self, values: Sequence[float], topic: str) -> None:
        """One value per joint in ``plant.joints`` order (ros2_control's forward command controller); the
        meaning is ``config.commands_interface``. A wrong length is rejected for every joint."""
        interface = self.config.commands_interface
        if len(values) != len(self.joints):
            names = ", ".join(j.name for j in self.joints)
            self.reject(self.joints, topic, "length", f"expected {len(self.joints)} element(s) ({interface} for "
                        f"{names}), got {len(values)}")
            return
        t = self.t_ns
        held = self._held
        if type(values) is type(held) and values == held:
            # the very array accepted last time, nothing commanded since (a controller holding its output):
            # only the counters and the watchdog's clock change
            for j in self.joints:
                j.commands_received += 1
                j.last_command_ns = t
            self.commands_received += len(self.joints)
            return
        kind = COMMANDS_INTERFACES[interface]
        current = kind == "current"
        n = 0
        accepted = True
        for j, value in zip(self.joints, values):
            # the same accepted command again (a controller holding its output): only the counters and the
            # watchdog's clock change; anything else (a new value, a rejection, the watchdog) takes command()
            if value == j.value and kind == j.kind and not j.watchdog_active and \
                    abs(value) <= (j.current_abs_max if current else j.torque_abs_max) < math.inf:
                j.commands_received += 1
                j.last_command_ns = t
                n += 1
            else:
                accepted = self.command(j, kind, value, topic) and accepted
        self.commands_received += n
        self._held = values[:] if accepted and isinstance(values, (array.array, list, tuple)) else None

    def joint_commands(self, names: Sequence[str], position: Sequence[float], velocity: Sequence[float],
                       effort: Sequence[float], topic: str) -> None:
        """``sensor_msgs/JointState`` commands as ros2_control's topic-based hardware interface sends them:
        joints by name, ``effort`` = output torque [N*m] in ``names`` order. A message carrying position or
        velocity is rejected as a whole (this is a torque-controlled actuator), so is one whose efforts do not
        match its names; an unknown name is rejected for that name only (the other joints are applied)."""
        names = list(names)
        known = [self.by_name[n] for n in names if n in self.by_name]
        if len(position) or len(velocity):
            given = " and ".join(f for f, v in (("position", position), ("velocity", velocity)) if len(v))
            self.reject(known, topic, "position_velocity",
                        f"position/velocity commands are not supported (this message carries {given}): nothing "
                        "applied; give each joint only <command_interface name=\"effort\"/> (output torque "
                        "[N*m]) in <ros2_control>")
            return
        if len(effort) != len(names):
            self.reject(known, topic, "effort_count", f"expected one effort per name ({len(names)} names, "
                        f"{len(effort)} efforts): nothing applied")
            return
        if len(set(names)) != len(names):
            twice = sorted({n for n in names if names.count(n) > 1})
            self.reject([j for j in self.joints if j.name in twice], topic, "duplicate:" + ",".join(twice),
                        f"joint(s) {', '.join(repr(n) for n in twice)} named more than once in one message: "
                        "nothing applied (which effort is meant is ambiguous)")
            return
        for name, value in zip(names, effort):
            j = self.by_name.get(name)
            if j is None:
                self.reject((), topic, f"unknown_joint:{name}", f"unknown joint {name!r} ignored (this node has "
                            f"{', '.join(self.by_name)})")
            else:
                self.command(j, "torque", value, topic)

    def load_torque(self, j: JointCommand, value: float, topic: str, bound: float) -> bool:
        """Extra external load at the output [N*m], finite and within +-``bound``."""
        v = float(value)
        if not math.isfinite(v) or abs(v) > bound:
            self.reject((j,), topic, "load", f"load torque must be finite and within +-{bound:g} N*m, got {value!r}")
            return False
        self.plant.set_load_torque(j.name, v)
        j.load_torque_extra = v
        return True

    def reset_fault(self, j: JointCommand) -> bool:
        """Clear a latched trip of joint ``j``; True if one was latched. Logged throttled per joint and outcome
        (a controller that publishes resets at its own rate gets one line per :data:`LOG_THROTTLE_NS`, the
        ones held back counted)."""
        was = bool(self.plant.reset_fault(j.name))
        allowed, held = self._throttle.allow(("reset_fault", j.name, was))
        if allowed:
            more = f" ({held} more like it in the last {LOG_THROTTLE_NS * 1e-9:g} s)" if held else ""
            self.log.info(f"fault reset{self._for(j)}" + ("" if was else " (no trip was latched)") + more)
        return was

    def update_params(self, j: JointCommand, params: ActuatorParams) -> None:
        self.plant.update_params(j.name, params)
        self._limits(j, params)
        self._held = None   # (the limits changed: check the next array again)

    # ------------------------------------------------------------------------------------ diagnostics

    def health(self, outs: list[dict] | None = None, *, error: str = "",
               values: dict[str, str] | None = None) -> list[Health]:
        """Every joint's diagnostics over the window since the last call (which this resets). ``error``: a
        node-level fault (e.g. the recording stopped) that makes every joint ERROR; ``values``: extra key
        values for every joint. Each change of a joint's level is logged once."""
        outs = outs if outs is not None else self.plant.all_outputs()
        wall = self.clock()
        if wall > self._win_wall0 and self.t_ns > self._win_sim0:
            self.real_time_factor = (self.t_ns - self._win_sim0) / (wall - self._win_wall0)
        self._pace(wall)
        result = [self._joint_health(j, o, error, values or {}) for j, o in zip(self.joints, outs)]
        lines: dict[tuple, list[JointCommand]] = {}   # the same change of several joints: one line
        for j, h in zip(self.joints, result):
            if h.level != j.level:
                j.level = h.level
                j.level_changes += 1
            if j.level != j.logged_level and (j.level_logged_ns is None
                                              or wall - j.level_logged_ns >= LEVEL_LOG_MIN_NS):
                lines.setdefault((j.logged_level, h.level, h.message), []).append(j)
        for (old, new, message), joints in lines.items():
            self._log_level(joints, old, new, message, max(j.level_changes for j in joints))
            for j in joints:
                j.logged_level, j.level_logged_ns, j.level_changes = new, wall, 0
        self._win_periods = self._win_slips = 0
        for j in self.joints:
            j.win_saturated = j.win_rejected = 0
        self._win_wall0, self._win_sim0 = wall, self.t_ns
        return result

    def _pace(self, wall: int) -> None:
        """The time-factor warning: raised by a slip in this window, held until :data:`PACE_HOLD_NS` of wall
        time pass without one; measured (achieved factor, slips) from the window it was raised in."""
        if self._win_slips:
            if not self._pace_warn:
                self._pace_warn = True
                self._pace_wall0, self._pace_sim0, self._pace_slips = self._win_wall0, self._win_sim0, 0
            self._pace_slips += self._win_slips
            self._pace_last_slip = wall
        elif self._pace_warn and wall - self._pace_last_slip >= PACE_HOLD_NS:
            self._pace_warn = False
        if self._pace_warn:
            span = wall - self._pace_wall0
            achieved = (self.t_ns - self._pace_sim0) / span if span > 0 else float("nan")
            self._pace_text = (f"cannot keep time_factor {self.config.time_factor:g} (achieved {achieved:.2f} over "
                               f"the last {span * 1e-9:.1f} s; {self._pace_slips} slip(s))")

    def _log_level(self, joints: list[JointCommand], old: int, new: int, message: str, changes: int) -> None:
        more = f" ({changes} level changes since the last line)" if changes > 1 else ""
        who = ", ".join(j.name for j in joints) if self.config.name_joints else "actuator"
        text = f"diagnostics {who}: {LEVEL_NAMES[old]} -> {LEVEL_NAMES[new]}: {message}{more}"
        # one call site per severity (rclpy's logger keys its state by call site)
        if new == ERROR:
            self.log.error(text)
        elif new == WARN:
            self.log.warning(text)
        else:
            self.log.info(text)

    def _mode(self) -> str:
        if self.config.lock_step:
            return "lock_step"
        return "as_fast_as_possible" if self.as_fast_as_possible else f"time_factor {self.config.time_factor:g}"

    def _joint_health(self, j: JointCommand, o: dict, error: str, extra: dict[str, str]) -> Health:
        p = self.plant.params(j.name)
        cfg = self.config
        sat = j.win_saturated / self._win_periods if self._win_periods else 0.0
        level, why = OK, []
        lim_eff, lim = float(o["current_limit_effective"]), p.drive.current_limit
        T_w = float(o["T_winding"])
        reset_topic = f"~/{j.name}/reset_fault" if cfg.name_joints else "~/reset_fault"
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
            why.append(f"command watchdog: no command for {cfg.watchdog_ns * 1e-9:g} s, holding zero current")
        if j.win_rejected:
            level = max(level, WARN)
            why.append(f"{j.win_rejected} command(s) rejected: {j.last_rejection}")
        if error:
            level = ERROR
            why.append(error)
        if self._pace_warn:
            level = max(level, WARN)
            why.append(self._pace_text)
        values = {
            "sim_time [s]": f"{self.t_ns * 1e-9:.6f}",
            "real_time_factor": f"{self.real_time_factor:.3f}",
            "mode": self._mode(),
            "command": f"{j.kind} {j.value:g}",
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
            **extra,
        }
        return Health(j.name, level, "; ".join(why) if why else "OK", values)
