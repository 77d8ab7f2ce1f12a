"""Issue #24, the input forms a voltage-mode log needs: ``--map`` expressions that combine columns (duty x
supply, an unsigned PWM made signed, a sign from a direction bit) over a whitelisted grammar, and JSON logs (a
list of records, JSON Lines) through the loaders and input profiles recognised by their keys."""

from __future__ import annotations

import json
import textwrap

import numpy as np
import pytest

from bldc_actuator.diagnosis.io import input_profiles as ip
from bldc_actuator.diagnosis.io import loaders
from bldc_actuator.diagnosis.io.mapping import Expression, LoadError, Mapping, compile_expression

N = 300
T = np.arange(N) / 190.0
DUTY = 0.5 + 0.4 * np.sin(2 * np.pi * 1.3 * T)          # unsigned PWM in [0.1, 0.9]
DIR = (np.sin(2 * np.pi * 0.7 * T) < 0).astype(float)   # direction bit
VBUS = 12.0 - 0.3 * np.cos(2 * np.pi * 0.2 * T)
SPEED_OUT = 0.4 * np.sin(2 * np.pi * 0.9 * T)


def _csv(tmp_path):
    p = tmp_path / "servo.csv"
    cols = {"t": T, "duty": DUTY, "dir": DIR, "v_bus": VBUS, "speed": SPEED_OUT, "pwm-raw": DUTY}
    p.write_text(",".join(cols) + "\n" + "\n".join(",".join(f"{v:.12g}" for v in r)
                                                    for r in np.column_stack(list(cols.values()))) + "\n")
    return p


def _records():
    return [{"t": float(t), "servo": {"angle": float(a), "speed": float(s)}, "duty": float(d), "v_bus": float(v),
             "dir": bool(b), "mode": "pwm"}
            for t, a, s, d, v, b in zip(T, np.cumsum(SPEED_OUT) / 190.0, SPEED_OUT, DUTY, VBUS, DIR)]


def test_affine_expressions_stay_a_scale_and_offset():
    assert compile_expression("-adc*2+0.5") == ("adc", -2.0, 0.5)
    assert compile_expression("2*(x+1)") == ("x", 2.0, 2.0)
    assert compile_expression("(x-0.5)/0.25") == ("x", 4.0, -2.0)
    assert compile_expression('"a-b"*2') == ("a-b", 2.0, 0.0)
    assert compile_expression("#3/1000") == ("#3", 1e-3, 0.0)
    assert compile_expression("/joint_states.velocity[0]") == ("/joint_states.velocity[0]", 1.0, 0.0)
    e = compile_expression("duty*v_bus*(1-2*dir)")
    assert isinstance(e, Expression) and e.columns == ("duty", "v_bus", "dir")


@pytest.mark.parametrize("expr, value", [
    ("duty*v_bus", DUTY * VBUS),
    ("(duty-0.5)*2*v_bus", (DUTY - 0.5) * 2 * VBUS),
    ("duty*v_bus*(1-2*dir)", DUTY * VBUS * (1 - 2 * DIR)),
    ("where(dir > 0.5, -duty, duty) * v_bus", np.where(DIR > 0.5, -DUTY, DUTY) * VBUS),
    ("-abs(speed) + sign(speed)**2", -np.abs(SPEED_OUT) + np.sign(SPEED_OUT) ** 2),
    ('"pwm-raw" * v_bus / 2', DUTY * VBUS / 2),
])
def test_combined_expressions_evaluate_over_csv_columns(tmp_path, expr, value):
    sig = loaders.load(_csv(tmp_path), mapping=Mapping.parse(["time=t", "velocity=speed*288", f"voltage_q={expr}"]))
    np.testing.assert_allclose(sig.channels["voltage_q"], value, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(sig.channels["velocity"], 288 * SPEED_OUT, rtol=1e-9)
    assert sig.meta["mapping"]["voltage_q"] == expr.strip()


@pytest.mark.parametrize("bad, words", [
    ("__import__('os')", ["unknown function", "__import__"]),
    ("__import__('os').system('true')", ["not allowed"]),
    ("duty if dir else 0", ["not allowed"]),
    ("lambda: 1", ["not allowed"]),
    ("duty**v_bus", ["exponent"]),
    ("where(duty)", ["where() takes 3"]),
    ("duty*(v_bus", ["cannot parse"]),
])
def test_unsafe_or_malformed_expressions_are_refused_with_the_reason(bad, words):
    with pytest.raises(ValueError) as exc:
        Mapping.parse([f"voltage_q={bad}"])
    assert "voltage_q=" in str(exc.value) and all(w in str(exc.value) for w in words), str(exc.value)


def test_an_unknown_column_names_the_expression_the_column_and_the_columns(tmp_path):
    with pytest.raises(LoadError) as exc:
        loaders.load(_csv(tmp_path), mapping=Mapping.parse(["time=t", "velocity=speed", "voltage_q=duty*supply"]))
    msg = str(exc.value)
    assert "duty*supply" in msg and "'supply'" in msg and "v_bus" in msg and "servo.csv" in msg


def test_time_cannot_be_a_combination():
    with pytest.raises(ValueError, match="time"):
        Mapping.parse(["time=t0+t1"])


def test_map_over_map_file_keeps_combined_targets(tmp_path):
    f = tmp_path / "map.yaml"
    f.write_text("time: t\nvelocity: speed*288\nvoltage_q: duty*v_bus\n")
    m = Mapping.from_yaml(f)
    m.update(Mapping.parse(["voltage_q=(duty-0.5)*2*v_bus"]))
    sig = loaders.load(_csv(tmp_path), mapping=m)
    np.testing.assert_allclose(sig.channels["voltage_q"], (DUTY - 0.5) * 2 * VBUS, rtol=1e-9)


@pytest.mark.parametrize("form", ["records", "json lines"])
def test_json_logs_load_with_combined_maps(tmp_path, form):
    recs = _records()
    if form == "records":
        p = tmp_path / "servo.json"
        p.write_text(json.dumps(recs))
    else:
        p = tmp_path / "servo.jsonl"
        p.write_text("\n".join(json.dumps(r) for r in recs) + "\n")
    sig = loaders.load(p, mapping=Mapping.parse(["time=t", "velocity=servo.speed*288",
                                                 "voltage_q=duty*v_bus*(1-2*dir)"]))
    np.testing.assert_allclose(sig.time, T, rtol=1e-12)
    np.testing.assert_allclose(sig.channels["velocity"], 288 * SPEED_OUT, rtol=1e-9)
    np.testing.assert_allclose(sig.channels["voltage_q"], DUTY * VBUS * (1 - 2 * DIR), rtol=1e-9)
    assert sig.source == str(p) and sig.meta["format"] == "json" and sig.meta["json_layout"] == form


def test_json_with_canonical_keys_speaks_for_itself(tmp_path):
    p = tmp_path / "own.json"
    p.write_text(json.dumps({"time": T.tolist(), "velocity": SPEED_OUT.tolist(), "voltage_q": DUTY.tolist()}))
    sig = loaders.load(p)
    np.testing.assert_allclose(sig.channels["voltage_q"], DUTY, rtol=1e-12)


def test_a_json_profile_is_recognised_by_its_keys_and_maps_them(tmp_path, monkeypatch):
    prof = tmp_path / "profiles"
    prof.mkdir()
    (prof / "hobby_servo_json.yaml").write_text(textwrap.dedent("""\
        name: hobby_servo_json
        description: "hobby servo JSON log: output angle and speed, PWM duty with a direction bit, supply"
        format: json
        signature:
          header_has: [t, servo.angle, servo.speed, duty, v_bus]
        time: {column: t}
        gear_ratio: 288
        columns:
          position: servo.angle
          velocity: servo.speed
          voltage_q: duty*v_bus*(1-2*dir)
          bus_voltage: v_bus
        side: {position: output, velocity: output}
        """))
    monkeypatch.setattr(ip, "profile_dir", lambda: prof)
    p = tmp_path / "run.json"
    p.write_text(json.dumps(_records()))
    assert ip.detect(p).name == "hobby_servo_json"
    csv_twin = _csv(tmp_path)                       # same keys in a CSV: a JSON profile does not claim it
    assert ip.detect(csv_twin) is None
    sig = loaders.load(p)
    assert sig.meta["profile"] == "hobby_servo_json"
    np.testing.assert_allclose(sig.channels["velocity"], 288 * SPEED_OUT, rtol=1e-9)
    np.testing.assert_allclose(sig.channels["voltage_q"], DUTY * VBUS * (1 - 2 * DIR), rtol=1e-9)
    np.testing.assert_allclose(sig.channels["bus_voltage"], VBUS, rtol=1e-9)
    over = loaders.load(p, mapping=Mapping.parse(["voltage_q=(duty-0.5)*2*v_bus"]), profile="hobby_servo_json")
    np.testing.assert_allclose(over.channels["voltage_q"], (DUTY - 0.5) * 2 * VBUS, rtol=1e-9)


@pytest.mark.parametrize("text, words", [
    ("", ["no data"]),
    ("[1, 2, 3]", ["record 0", "object"]),
    ('{"t": [1, 2], "x": [1]}', ["equal-length"]),
    ('{"t": 1}\n{"t": 2,\n', ["line 2"]),
])
def test_bad_json_names_the_file_and_the_place(tmp_path, text, words):
    p = tmp_path / "bad.json"
    p.write_text(text)
    with pytest.raises(LoadError) as exc:
        loaders.load(p, mapping=Mapping.parse(["time=t", "velocity=x"]))
    assert "bad.json" in str(exc.value) and all(w in str(exc.value) for w in words), str(exc.value)
