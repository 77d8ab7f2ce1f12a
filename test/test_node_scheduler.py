"""The node's ROS-free scheduler (bldc_actuator.scheduler) over the default plant: time keeping against a
controlled clock, lock-step equal to an offline actuator, the watchdog's exact timing, the command contract,
per-reason log throttling and console lines for every diagnostics level change. No ROS needed."""

from __future__ import annotations

import math

import pytest

from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams, load_preset
from bldc_actuator.plant import ActuatorPlant, Plant
from bldc_actuator.scheduler import ERROR, OK, WARN, Scheduler, SchedulerConfig


class ListLog:
    def __init__(self):
        self.lines: list[tuple[str, str]] = []

    def info(self, m):
        self.lines.append(("info", m))

    def warning(self, m):
        self.lines.append(("warning", m))

    def error(self, m):
        self.lines.append(("error", m))

    def having(self, text):
        return [m for _, m in self.lines if text in m]


class FakeClock:
    def __init__(self, t=1_000_000_000):
        self.t = t

    def __call__(self):
        return self.t


def make(joints=("hip", "knee"), clock=None, **cfg):
    plant = ActuatorPlant({name: load_preset("ak80_9") for name in joints})
    log = ListLog()
    config = SchedulerConfig(name_joints=len(joints) > 1, **cfg)
    return Scheduler(plant, config, log=log, clock=clock or FakeClock()), plant, log


def test_default_plant_satisfies_the_protocol():
    plant = ActuatorPlant({"a": ActuatorParams()})
    assert isinstance(plant, Plant)
    assert plant.joints == ["a"] and plant.t_ns == 0


def test_lock_step_periods_equal_an_offline_actuator_bit_for_bit():
    sched, plant, _ = make(joints=("j",), lock_step=True, period_ns=2_000_000, watchdog_ns=0)
    ref = Actuator(load_preset("ak80_9"))
    for k in range(50):
        tau = 0.2 * math.sin(0.3 * k)
        sched.commands([tau], "~/commands")
        sched.lock_step_period()
        ref.set_torque_command(tau)
        ref.step_ns(2_000_000)
        o = ref.outputs()
        assert (sched.position[0], sched.velocity[0], sched.effort[0]) == \
            (o["position_out"], o["velocity_out"], o["effort_out"])
    assert sched.t_ns == 100_000_000 and sched.periods == 50


def test_each_wake_up_advances_the_periods_that_are_due_and_a_stall_is_a_slip():
    clock = FakeClock()
    sched, _, log = make(clock=clock, period_ns=1_000_000, time_factor=1.0)
    sched.start()
    assert sched.wake_period_ns == 1_000_000
    for k in range(1, 101):                     # wake-ups exactly one period apart: one period each
        clock.t += 1_000_000
        assert sched.tick() == 1
    assert sched.t_ns == 100_000_000 and sched.slips == 0
    clock.t += 3 * 1_000_000 + 200_000          # a late wake-up catches up (3 periods due)
    assert sched.tick() == 3
    clock.t += 1_000_000_000                    # a stall of one second: the debt is dropped, not burst
    n = sched.tick()
    assert n == 20 and sched.slips == 1         # max_batch_wall 20 ms at 1 ms periods
    clock.t += 1_000_000
    assert sched.tick() == 1                    # and back to one period per wake-up
    h = sched.health()
    assert all(x.level == WARN and "cannot keep time_factor 1" in x.message for x in h)
    # the change of both joints is one console line
    lines = log.having("OK -> WARN")
    assert len(lines) == 1 and "hip, knee" in lines[0] and "cannot keep" in lines[0]


def test_watchdog_fires_at_its_timeout_and_clears_and_each_level_change_is_logged_once():
    sched, plant, log = make(joints=("j",), lock_step=True, period_ns=1_000_000, watchdog_ns=20_000_000)
    sched.command(sched.joints[0], "current", 3.0, "~/current_command")
    t_cmd = sched.t_ns
    fired_at = None
    for _ in range(40):
        sched.advance(1)
        if fired_at is None and sched.joints[0].watchdog_active:
            fired_at = sched.t_ns
    # the check runs before the step that starts at t_cmd + timeout: zero current from that period on
    assert fired_at == t_cmd + 20_000_000 + 1_000_000
    assert plant.outputs("j")["i_q_ref"] == 0.0
    assert len(log.having("command watchdog: no command for 0.02 s")) == 1
    h1 = sched.health()
    assert h1[0].level == WARN and "watchdog" in h1[0].message
    h2 = sched.health()                           # still WARN: no second line
    assert h2[0].level == WARN
    assert len(log.having("OK -> WARN")) == 1
    sched.clock.t += 1_000_000_000               # console lines about one joint's level: at most one per second
    sched.command(sched.joints[0], "current", 1.0, "~/current_command")
    assert log.having("command watchdog cleared")
    sched.advance(1)
    assert plant.outputs("j")["i_q_ref"] == 1.0
    assert sched.health()[0].level == OK
    assert len(log.having("WARN -> OK")) == 1


def test_trip_is_error_and_logged_as_error():
    hot = load_preset("ak80_9").replace(**{"thermal.initial_winding_temperature": 130.0,
                                           "thermal.initial_housing_temperature": 100.0})
    plant = ActuatorPlant({"j": hot})
    log = ListLog()
    sched = Scheduler(plant, SchedulerConfig(lock_step=True, watchdog_ns=0), log=log, clock=FakeClock())
    sched.command(sched.joints[0], "current", 5.0, "~/current_command")
    sched.advance(2)
    assert plant.outputs("j")["tripped"]
    h = sched.health()[0]
    assert h.level == ERROR and "TRIP" in h.message
    assert [lvl for lvl, m in log.lines if "OK -> ERROR" in m] == ["error"]


def test_command_contract_and_per_reason_log_throttling():
    sched, plant, log = make(joints=("hip", "knee", "ankle"), lock_step=True)
    hip, knee, ankle = sched.joints
    # position + effort: the whole message rejected, with the reason, for the joints it names
    sched.joint_commands(["hip", "knee"], [1.0, 0.0], [], [0.3, 0.1], "/cmd")
    assert hip.value == 0.0 and knee.value == 0.0 and plant.outputs("hip")["i_q_ref"] == 0.0
    assert "position/velocity commands are not supported" in sched.last_rejection
    assert (hip.commands_rejected, knee.commands_rejected, ankle.commands_rejected) == (1, 1, 0)
    # an unknown name: rejected for that name only, the others applied
    sched.joint_commands(["ankle", "elbow"], [], [], [0.2, 1.0], "/cmd")
    assert ankle.value == 0.2 and ankle.commands_rejected == 0
    assert "unknown joint 'elbow'" in sched.last_rejection
    # effort = output torque: i_q_ref = tau / (K_t_q N) (the drive takes it at its next tick)
    sched.lock_step_period()
    p = plant.params("ankle")
    assert plant.outputs("ankle")["i_q_ref"] == pytest.approx(0.2 / (p.motor.torque_constant_q * p.gear.gear_ratio),
                                                              rel=1e-12)
    # three different reasons in the same second: each logged; a repeat of one is held back and counted
    sched.commands([math.nan, 0.0, 0.0], "/c")          # not finite (hip)
    sched.commands([0.0, 1e6, 0.0], "/c")               # absurd (knee)
    sched.commands([0.0], "/c")                         # wrong length (every joint)
    sched.commands([math.nan, 0.0, 0.0], "/c")          # not finite again: held back
    rejected = [m for lvl, m in log.lines if lvl == "warning" and m.startswith("rejected command on /c:")]
    assert len(rejected) == 3
    assert any("finite" in m for m in rejected) and any("absurd" in m for m in rejected) \
        and any("expected 3 element(s)" in m for m in rejected)
    assert sched.commands_rejected == 6   # every rejection counted, logged or not
    h = {x.joint: x for x in sched.health()}
    assert all(x.level == WARN for x in h.values())     # the wrong-length array concerns every joint


class CountingPlant(ActuatorPlant):
    """The default plant (with its cheap ``joint_states()`` read), counting full reads."""

    full_reads = 0

    def all_outputs(self):
        self.full_reads += 1
        return super().all_outputs()


class FullReadPlant(ActuatorPlant):
    """The default plant without the optional cheap read: every period reads ``all_outputs()``."""

    joint_states = None


def test_a_plant_with_a_cheap_joint_state_read_is_fully_read_only_when_needed():
    """Same joint states and saturation counts as the full read; all_outputs() only on diagnostics periods
    (and detail periods while details are wanted)."""
    cfg = dict(lock_step=True, watchdog_ns=0, diag_period_ns=10_000_000)
    cheap = Scheduler(CountingPlant({"a": load_preset("ak80_9")}), SchedulerConfig(**cfg), log=ListLog(),
                      clock=FakeClock())
    full = Scheduler(FullReadPlant({"a": load_preset("ak80_9")}), SchedulerConfig(**cfg), log=ListLog(),
                     clock=FakeClock())
    cheap.detail_wanted = False
    reads0 = cheap.plant.full_reads
    for s in (cheap, full):
        s.command(s.joints[0], "current", s.plant.params("a").drive.current_limit, "~/current_command")
    for _ in range(300):                                         # runs into the voltage limit: saturates
        for s in (cheap, full):
            s.advance(1)
        assert (cheap.position[0], cheap.velocity[0], cheap.effort[0]) == (full.position[0], full.velocity[0],
                                                                           full.effort[0])
    assert cheap.plant.full_reads - reads0 == 31                 # t = 1 (first diagnostics), 10, 20, ..., 300 ms
    assert cheap.joints[0].win_saturated == full.joints[0].win_saturated > 0
    cheap.detail_wanted = True
    cheap.advance(10)
    assert cheap.plant.full_reads - reads0 == 41


def test_a_held_commands_array_is_still_counted_watched_and_checked():
    """The same ``~/commands`` array again (the scheduler's shortcut for a controller holding its output)
    behaves exactly like a new one: counted per joint, keeps the watchdog fed, clears a fired watchdog
    (the current comes back), and is checked again after a parameter change makes it absurd."""
    from array import array

    sched, plant, log = make(lock_step=True, watchdog_ns=20_000_000, commands_interface="current")
    held = array("d", [2.0, -1.0])
    for _ in range(30):                           # 30 ms of the same array: the watchdog never fires
        sched.commands(array("d", held), "~/commands")
        sched.lock_step_period()
    hip, knee = sched.joints
    assert hip.commands_received == knee.commands_received == 30 and sched.commands_received == 60
    assert not hip.watchdog_active and hip.last_command_ns == sched.t_ns - 1_000_000
    assert plant.outputs("hip")["i_q_ref"] == 2.0 and plant.outputs("knee")["i_q_ref"] == -1.0
    sched.advance(25)                             # silence: the watchdog zeroes both currents
    assert hip.watchdog_active and plant.outputs("hip")["i_q_ref"] == 0.0
    sched.commands(array("d", held), "~/commands")  # the same array once more: current back, watchdog cleared
    sched.advance(1)
    assert not hip.watchdog_active and plant.outputs("hip")["i_q_ref"] == 2.0
    assert plant.outputs("knee")["i_q_ref"] == -1.0 and log.having("command watchdog cleared")
    # a current limit of 0.1 A makes 2 A absurd (> 10 x the limit): the same array is now rejected for the hip
    sched.update_params(hip, plant.params("hip").replace(**{"drive.current_limit": 0.1}))
    rejected = hip.commands_rejected
    sched.commands(array("d", held), "~/commands")
    assert hip.commands_rejected == rejected + 1 and "absurd" in hip.last_rejection
    assert knee.commands_rejected == 0
