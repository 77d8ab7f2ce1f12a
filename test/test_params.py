"""Parameter schema: YAML layout, validation messages, datasheet block, flat names."""

import math

import pytest

from bldc_actuator import frames
from bldc_actuator.params import (SPECS, ActuatorParams, ParameterError, dump_yaml, from_flat, load_yaml,
                                  params_from_dict, to_flat)


def test_yaml_round_trip_in_ros_layout(tmp_path):
    p = ActuatorParams().replace(**{"effects.cogging_order": 84, "effects.cogging_cos": (0.01, 0.002),
                                    "effects.cogging_sin": (0.0, 1e-5), "motor.winding": "delta"})
    path = tmp_path / "p.yaml"
    text = dump_yaml(p, path)
    assert text.splitlines()[0] == "/**/bldc_actuator:" and text.splitlines()[1] == "  ros__parameters:"
    # ROS needs doubles written as doubles: 24.0, never 24
    assert "bus_voltage: 24.0" in text and "q_inductance: 5.7e-05" in text
    assert load_yaml(path) == p


def test_every_field_has_unit_range_description():
    for name, spec in SPECS.items():
        assert spec.description, name
        if spec.type is float:
            assert spec.unit or name.endswith(("gear_ratio",)), name
        default = spec.default
        if spec.type in (int, float):
            lo, hi = spec.range
            assert lo <= default <= hi, name


@pytest.mark.parametrize("field,value,match", [
    ("motor.phase_resistance", -0.1, r"motor.phase_resistance: -0.1 is outside \(0, inf\) ohm \(physical limit; "
                                     r"usual range \(0, 100\]\)"),
    ("drive.modulation_limit", 1.2, r"drive.modulation_limit: 1.2 is outside \(0, 1\]"),
    ("effects.coulomb_friction", -1.0, r"effects.coulomb_friction: -1.0 is outside \[0, inf\) N\*m"),
    ("drive.bus_voltage", "lots", r"drive.bus_voltage: expected a number \[V\]"),
    ("motor.pole_pairs", 7.5, r"motor.pole_pairs: expected an integer"),
    ("motor.winding", "star", r"motor.winding: expected one of wye, delta"),
    ("thermal.ambient_temperature", math.nan, r"thermal.ambient_temperature"),
])
def test_bad_values_name_field_range_and_unit(field, value, match):
    with pytest.raises(ParameterError, match=match) as info:
        ActuatorParams().replace(**{field: value})
    assert info.value.field == field


def test_cross_field_checks():
    with pytest.raises(ParameterError, match="drive.trip_temperature: must be above"):
        ActuatorParams().replace(**{"drive.trip_temperature": 90.0})
    with pytest.raises(ParameterError, match="cogging_sin"):
        ActuatorParams().replace(**{"effects.cogging_cos": (1.0,)})
    with pytest.raises(ParameterError, match="current_loop_bandwidth"):
        ActuatorParams().replace(**{"drive.current_loop_bandwidth": 5000.0})


def test_unknown_keys_are_errors(tmp_path):
    with pytest.raises(ParameterError, match="motor.phase_resistence"):
        from_flat({"motor.phase_resistence": 0.1})
    path = tmp_path / "typo.yaml"
    path.write_text("/**/bldc_actuator:\n  ros__parameters:\n    motr:\n      winding: wye\n")
    with pytest.raises(ParameterError, match="motr.winding"):
        load_yaml(path)


def test_yaml_parse_error_names_the_line(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("/**/bldc_actuator:\n  ros__parameters:\n    motor:\n      winding: [wye\n")
    with pytest.raises(ParameterError, match="line"):
        load_yaml(path)


def test_datasheet_block_converts_with_frames():
    tree = {"/**/bldc_actuator": {"ros__parameters": {
        "datasheet": {"winding": "delta", "terminal_resistance": 0.186, "terminal_inductance": 1.2e-4, "kv": 100.0},
        "drive": {"bus_voltage": 48.0}}}}
    p = params_from_dict(tree)
    assert p.motor.winding == "delta"
    assert p.motor.phase_resistance == pytest.approx(1.5 * 0.186)
    assert p.motor.q_inductance == pytest.approx(1.5 * 1.2e-4)     # physics, not the paper's 1/2
    k_b_ll = 60.0 / (2 * math.pi * 100.0)
    assert p.motor.torque_constant_q == pytest.approx(math.sqrt(1.5) * k_b_ll)
    assert p.drive.bus_voltage == 48.0
    # explicit q-axis values override the datasheet block
    tree["/**/bldc_actuator"]["ros__parameters"]["motor"] = {"torque_constant_q": 0.2}
    assert params_from_dict(tree).motor.torque_constant_q == 0.2


def test_datasheet_errors_name_the_key():
    with pytest.raises(ParameterError, match="datasheet.winding"):
        params_from_dict({"datasheet": {"winding": "unknown", "kv": 100}})
    with pytest.raises(ParameterError, match="datasheet.torque_constant_frame"):
        params_from_dict({"datasheet": {"winding": "wye", "torque_constant": 0.1}})
    with pytest.raises(ParameterError, match="datasheet.terminal_resistance"):
        params_from_dict({"datasheet": {"winding": "wye", "terminal_resistance": -1}})


def test_flat_names_cover_dataclasses():
    flat = to_flat(ActuatorParams())
    assert set(flat) == set(SPECS)
    assert from_flat(flat) == ActuatorParams()
    assert frames.voltage_limit_q(24.0, "wye") == pytest.approx(24.0 / math.sqrt(2))


def test_bounds_are_sanity_limits_a_real_value_outside_them_is_accepted_with_a_warning(tmp_path):
    """Issue #14: a 95 kg linear axis has 203.5 N s/m of viscous friction; the usual range [0, 100] is a sanity
    limit, so the value is representable (and simulated), the YAML loader warns and names the field."""
    from bldc_actuator.params import ParameterWarning, sanity_warnings

    p = ActuatorParams().replace(**{"motor.viscous_damping": 203.5, "motor.rotor_inertia": 950.0})
    assert p.motor.viscous_damping == 203.5 and p.motor.rotor_inertia == 950.0
    msgs = sanity_warnings(p)
    assert len(msgs) == 2 and any("motor.viscous_damping = 203.5" in m and "[0, 100]" in m for m in msgs)
    assert sanity_warnings(ActuatorParams()) == []
    path = tmp_path / "axis.yaml"
    dump_yaml(p, path)
    with pytest.warns(ParameterWarning) as caught:
        assert load_yaml(path) == p
    assert sorted(str(w.message).split(": ", 1)[1].split(" =")[0] for w in caught) == \
        ["motor.rotor_inertia", "motor.viscous_damping"]
