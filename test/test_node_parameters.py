"""Issue #25, symptom 5, the run-time parameters of actuator_node: an integer for a double is accepted (as in a
parameter file), a value of the wrong type is refused naming the field, its type, range and unit, and an
absurd value set at run time gets the same sanity warning as at start-up."""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy")

from node_helpers import make_node  # noqa: E402

pytestmark = pytest.mark.ros


class ListLog:
    def __init__(self):
        self.lines: list[str] = []

    def info(self, m, *a, **k):
        self.lines.append(m)

    warning = error = debug = info


def test_an_integer_for_a_double_is_accepted_at_run_time(ros_context, ros_executor):
    from rclpy.parameter import Parameter

    node = make_node(ros_context, ros_executor, params={"node.lock_step": True})
    result = node.set_parameters([Parameter("drive.bus_voltage", Parameter.Type.INTEGER, 36),
                                  Parameter("node.time_factor", Parameter.Type.INTEGER, 2)])
    assert all(r.successful for r in result), [r.reason for r in result]
    assert node.plant.params(node.joints[0].name).drive.bus_voltage == 36.0
    p = node.get_parameter("drive.bus_voltage")
    assert p.type_ == Parameter.Type.DOUBLE and p.value == 36.0
    assert node.scheduler.config.time_factor == 2.0


def test_a_value_of_the_wrong_type_is_refused_naming_field_type_range_and_unit(ros_context, ros_executor):
    from rclpy.parameter import Parameter

    node = make_node(ros_context, ros_executor, params={"node.lock_step": True})
    before = node.plant.params(node.joints[0].name).drive.bus_voltage
    (result,) = node.set_parameters([Parameter("drive.bus_voltage", Parameter.Type.STRING, "48V")])
    assert not result.successful
    assert "drive.bus_voltage" in result.reason and "double" in result.reason and "[V]" in result.reason \
        and "'48V'" in result.reason, result.reason
    assert node.plant.params(node.joints[0].name).drive.bus_voltage == before
    assert node.get_parameter("drive.bus_voltage").value == before
    # a value out of the physical limits: the field, the limits and the unit (params.check_value's message)
    (result,) = node.set_parameters([Parameter("drive.current_limit", Parameter.Type.DOUBLE, -5.0)])
    assert not result.successful and "drive.current_limit" in result.reason and " A" in result.reason
    # and the next good value is taken (nothing left over from the refused one)
    (result,) = node.set_parameters([Parameter("drive.bus_voltage", Parameter.Type.DOUBLE, 30.0)])
    assert result.successful and node.plant.params(node.joints[0].name).drive.bus_voltage == 30.0


def test_an_absurd_value_at_run_time_warns_as_at_start_up(ros_context, ros_executor):
    from rclpy.parameter import Parameter

    node = make_node(ros_context, ros_executor, params={"node.lock_step": True}, start=False)
    log = ListLog()
    node.get_logger = lambda: log   # (the lines logged from here on)
    (result,) = node.set_parameters([Parameter("drive.current_limit", Parameter.Type.DOUBLE, 1e9)])
    assert result.successful   # accepted: the usual range is a sanity limit, as at start-up
    lines = [m for m in log.lines if "drive.current_limit" in m]
    assert len(lines) == 1 and "usual range" in lines[0] and "1000" in lines[0] and " A " in lines[0], log.lines
    assert node.plant.params(node.joints[0].name).drive.current_limit == 1e9
    # a usual value: no warning
    log.lines.clear()
    (result,) = node.set_parameters([Parameter("drive.current_limit", Parameter.Type.DOUBLE, 30.0)])
    assert result.successful and not [m for m in log.lines if "usual range" in m]


def test_an_absurd_value_at_start_up_warns(ros_context, ros_executor, capfd):
    node = make_node(ros_context, ros_executor, params={"node.lock_step": True, "drive.current_limit": 1e9},
                     start=False)
    err = capfd.readouterr().err
    assert "drive.current_limit = 1e+09 A is outside its usual range" in err, err[-2000:]
    assert node.plant.params(node.joints[0].name).drive.current_limit == 1e9
