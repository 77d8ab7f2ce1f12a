"""The drive's form (drive_feedforward) and its voltage-limit mode (judge/drive_modes) are decided only by a
closed-loop replay of the drive from its recorded commands: a recording without a current or torque command says
so, in the one record both build (``drive_modes.drive_replay_unavailable``), and neither proposes anything."""

from __future__ import annotations

import numpy as np

from bldc_actuator.diagnosis import drive_feedforward
from bldc_actuator.diagnosis.frame import equation_error as ee
from bldc_actuator.diagnosis.judge import drive_modes
from bldc_actuator.params import ActuatorParams

from test_issue14_judge_helpers import closed_loop_recording


def _ctx(channels):
    nominal = ActuatorParams()
    rec = closed_loop_recording(nominal, nominal, lambda t: 2.0 * np.sin(2 * np.pi * 0.5 * t), duration=3.0,
                                channels=channels)
    return ee.prepare([(rec, False)], nominal, fc=None, holdout=0.3), nominal


def test_without_a_command_neither_drive_check_runs_and_both_say_what_is_missing():
    ctx, nominal = _ctx(("current", "current_d", "position", "velocity", "voltage_q", "voltage_d"))
    starts = list(range(100, 2900, 100))
    ff = drive_feedforward.identify(ctx, nominal, starts, starts, 0.1)
    vm = drive_modes.identify(ctx, nominal, 0.1)
    for r, effect in ((ff, drive_feedforward.EFFECT), (vm, "voltage_limit_mode")):
        assert r["findings"] == [] and r["simulation"] is None
        assert r["not_checkable"] == [{"effect": effect, "reason": "needs current, speed and the current or torque "
                                       "command", "needs": ["current", "velocity|position",
                                                            "current_command|torque_command"]}]
    # with the command logged the same recording is replayed (not refused for want of channels)
    ctx, nominal = _ctx(("current_command", "current", "current_d", "position", "velocity", "voltage_q", "voltage_d"))
    assert drive_modes.drive_replay_unavailable(ctx, "x") is None
    vm = drive_modes.identify(ctx, nominal, 0.1)
    assert not any(nc["reason"].startswith("needs current") for nc in vm["not_checkable"])
