"""Issue #25, symptom 5 (the node details), in the ROS-free scheduler against a controlled clock: duplicate
joint names in one JointState command, the reset_fault log, the time-factor warning that must not flap. The
ROS-side details (run-time parameters) are in test/test_node_parameters.py."""

from __future__ import annotations

from bldc_actuator.params import load_preset
from bldc_actuator.plant import ActuatorPlant
from bldc_actuator import scheduler as S
from bldc_actuator.scheduler import OK, WARN, Scheduler, SchedulerConfig
from test_node_scheduler import FakeClock, ListLog

PACE_HOLD_NS = S.PACE_HOLD_NS


def make(joints=("hip", "knee"), **cfg):
    plant = ActuatorPlant({name: load_preset("ak80_9") for name in joints})
    log = ListLog()
    clock = FakeClock()
    sched = Scheduler(plant, SchedulerConfig(name_joints=len(joints) > 1, **cfg), log=log, clock=clock)
    return sched, plant, log, clock


def test_duplicate_joint_names_in_one_command_are_refused_naming_the_joint_and_throttled():
    sched, plant, log, clock = make(lock_step=True, watchdog_ns=0)
    sched.joint_commands(["hip", "knee"], [], [], [0.5, -0.5], "/robot_joint_command")
    assert sched.by_name["hip"].value == 0.5 and sched.by_name["knee"].value == -0.5
    received, rejected = sched.commands_received, sched.commands_rejected
    for _ in range(200):   # a controller repeating the ambiguous message at its rate
        sched.joint_commands(["hip", "knee", "hip"], [], [], [1.0, 1.0, 2.0], "/robot_joint_command")
    # nothing applied: neither last-wins (2.0) nor first-wins (1.0) for hip, and knee untouched too
    assert sched.by_name["hip"].value == 0.5 and sched.by_name["knee"].value == -0.5
    assert sched.commands_received == received and sched.commands_rejected == rejected + 200
    assert sched.by_name["hip"].commands_rejected == 200 and "'hip'" in sched.by_name["hip"].last_rejection
    lines = log.having("named more than once")
    assert len(lines) == 1 and "'hip'" in lines[0] and "'knee'" not in lines[0], lines
    clock.t += 1_000_000_000   # a second later: one more line, counting the ones held back
    sched.joint_commands(["hip", "hip"], [], [], [1.0, 2.0], "/robot_joint_command")
    lines = log.having("named more than once")
    assert len(lines) == 2 and "199 more like it" in lines[1]
    h = {x.joint: x for x in sched.health()}
    assert h["hip"].level == WARN and "named more than once" in h["hip"].message and h["knee"].level == OK


def test_reset_fault_is_logged_throttled_not_once_per_message():
    sched, plant, log, clock = make(joints=("j",), lock_step=True, watchdog_ns=0)
    j = sched.joints[0]
    for _ in range(1000):   # std_msgs/Empty on ~/reset_fault at 1 kHz for a second
        sched.reset_fault(j)
        clock.t += 1_000_000
    lines = log.having("fault reset")
    assert 1 <= len(lines) <= 2, len(lines)
    clock.t += 1_000_000_000
    sched.reset_fault(j)
    assert "more like it" in log.having("fault reset")[-1]


def test_a_tripped_drive_reset_is_still_reported():
    hot = load_preset("ak80_9").replace(**{"thermal.initial_winding_temperature": 130.0,
                                           "thermal.initial_housing_temperature": 100.0})
    plant = ActuatorPlant({"j": hot})
    log = ListLog()
    sched = Scheduler(plant, SchedulerConfig(lock_step=True, watchdog_ns=0), log=log, clock=FakeClock())
    sched.advance(2)
    assert plant.outputs("j")["tripped"]
    assert sched.reset_fault(sched.joints[0]) is True
    assert log.having("fault reset") == ["fault reset"]   # the trip cleared: said, without "(no trip ...)"


def test_the_time_factor_warning_does_not_flap_and_reports_the_measured_factor():
    """A factor missed now and then (a slip about once a second, as on a loaded machine) is one WARN line
    with the measured factor, not a WARN/OK pair every second; it clears once the factor has been kept for
    PACE_HOLD_NS."""
    sched, plant, log, clock = make(joints=("j",), period_ns=1_000_000, time_factor=1.0, watchdog_ns=0,
                                    diag_period_ns=100_000_000)

    def on_period(t, outs, detail, diag):
        if diag:
            sched.health(outs)

    sched.on_period = on_period
    sched.start()

    def run(seconds, stall_every_ms=None):
        for k in range(int(seconds * 1000)):
            clock.t += 1_000_000
            if stall_every_ms and k % stall_every_ms == stall_every_ms - 1:
                clock.t += 30_000_000   # the process was not scheduled for 30 ms: a slip
            sched.tick()

    run(48.0, stall_every_ms=1000)
    assert sched.slips >= 40
    changes = [m for _, m in log.lines if "diagnostics" in m and "->" in m]
    assert len(changes) == 1, changes   # before: ~34 WARN/OK lines in 48 s
    assert "OK -> WARN" in changes[0] and "cannot keep time_factor 1" in changes[0]
    achieved = float(changes[0].split("achieved ")[1].split()[0])
    assert 0.5 < achieved < 1.0
    run(PACE_HOLD_NS * 1e-9 + 1.0)      # the factor kept again: cleared once, said once
    changes = [m for _, m in log.lines if "diagnostics" in m and "->" in m]
    assert len(changes) == 2 and "WARN -> OK" in changes[1]
    assert sched.health()[0].level == OK
