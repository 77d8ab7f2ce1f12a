"""Input profiles (issue #9): log formats as YAML data, recognised by the file's own header, with units, gear
side, per-joint columns, time sources and quirks; errors name the profile field."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

from bldc_actuator.diagnosis.io import input_profiles as ip
from bldc_actuator.diagnosis.io import loaders, quirks
from bldc_actuator.diagnosis.io.cleaning import clean
from bldc_actuator.params import ActuatorParams

GEAR = 9.0


def _params():
    return ActuatorParams().replace(**{"gear.gear_ratio": GEAR})


def _write(path, header, rows):
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.9g}" for v in r) for r in rows) + "\n")
    return path


def _wide(tmp_path, joints=3, n=400):
    t = np.arange(n) / 100.0
    cols = {"time": t}
    for j in range(1, joints + 1):
        q_out = 0.2 * j * np.sin(2 * np.pi * 0.5 * t)
        cols[f"Position{j}"] = q_out
        cols[f"Velocity{j}"] = np.gradient(q_out, t)
        cols[f"Cur{j}"] = j * np.cos(t)
        cols[f"Torque{j}"] = 0.8 * j * np.cos(t)
        cols[f"Temp{j}"] = 30.0 + j + 0 * t
    (tmp_path / "robot").mkdir()
    return _write(tmp_path / "robot" / "2026-03-04_joints.csv", list(cols), np.column_stack(list(cols.values())))


def test_every_shipped_profile_is_valid_and_named_after_its_file():
    profs = ip.available()
    assert len(profs) >= 10
    for p in profs:
        assert p.signature, p.name                  # every shipped profile can be recognised
        assert ip.get(p.name) is not None
    assert len({p.name for p in profs}) == len(profs)


def test_wide_csv_joints_output_side_and_detection(tmp_path):
    f = _wide(tmp_path)
    assert loaders.joints(f) == ["joint1", "joint2", "joint3"]
    with pytest.raises(loaders.LoadError, match="several joints .*--joint"):
        loaders.load(f, params=_params())
    s = loaders.load(f, params=_params(), joint="joint2")
    assert s.meta["profile"] == "wide_joints" and s.meta["profile_how"].startswith("auto")
    raw = np.loadtxt(f, delimiter=",", skiprows=1)
    # output-side angle x gear ratio: the motor-side canonical channel (the 9x / 100x trap)
    assert np.allclose(s.channels["position"], raw[:, 1 + 5] * GEAR)
    assert np.allclose(s.channels["current"], raw[:, 3 + 5])
    assert np.allclose(s.meta["aux"]["torque_estimate_out"], raw[:, 4 + 5])
    assert "housing_temperature" in s.channels
    # the same file with no gear ratio known: an error naming the profile field
    with pytest.raises(loaders.LoadError, match="side.position is output .*gear_ratio"):
        loaders.load(f, joint="joint1")


def test_profile_file_units_time_and_errors(tmp_path):
    n = 300
    t_ms = np.arange(n) * 2.0
    ang_deg = np.linspace(0, 720, n)
    rpm = np.full(n, 720 / (n * 2e-3) / 6.0)       # deg/s -> rpm
    i_ma = 1500 + 0 * t_ms
    temp_k = 300.15 + 0 * t_ms
    f = _write(tmp_path / "log.csv", ["stamp", "angle", "speed", "iq_mA", "tK"],
               np.column_stack([t_ms, ang_deg, rpm, i_ma, temp_k]))
    prof = tmp_path / "mine.yaml"
    prof.write_text(textwrap.dedent("""\
        name: my_logger
        signature: {header_has: [stamp, iq_mA]}
        time: {column: stamp}
        columns: {position: angle, velocity: speed, current: iq_mA, winding_temperature: tK}
        units: {time: ms, position: deg, velocity: rpm, current: mA, winding_temperature: K}
        side: {position: output, velocity: output}
        gear_ratio: 6
        """))
    s = loaders.load(f, profile=str(prof))
    assert s.meta["profile"] == "my_logger" and s.meta["profile_how"].startswith("given")
    assert s.time[1] == pytest.approx(2e-3)
    assert s.channels["position"][-1] == pytest.approx(4 * math.pi * 6)
    assert s.channels["velocity"][0] == pytest.approx(720 / (n * 2e-3) / 6.0 * 2 * math.pi / 60 * 6)
    assert s.channels["current"][0] == pytest.approx(1.5)
    assert s.channels["winding_temperature"][0] == pytest.approx(27.0)
    # a missing column names the profile field; an unknown unit and an unknown field are errors too
    prof.write_text(prof.read_text().replace("current: iq_mA", "current: iq_A"))
    with pytest.raises(loaders.LoadError, match=r"columns.current: none of iq_A"):
        loaders.load(f, profile=str(prof))
    prof.write_text(prof.read_text().replace("current: mA", "current: milliamp"))
    with pytest.raises(ip.ProfileError, match=r"units.current: unknown unit 'milliamp'"):
        loaders.load(f, profile=str(prof))
    prof.write_text(prof.read_text() + "colums: {}\n")
    with pytest.raises(ip.ProfileError, match="unknown field.*colums"):
        loaders.load(f, profile=str(prof))


def test_unknown_file_says_what_to_do(tmp_path):
    f = _write(tmp_path / "x.csv", ["a", "b"], np.ones((5, 2)))
    with pytest.raises(loaders.LoadError, match="--profile FILE .* or map the columns"):
        loaders.load(f)


def test_recognised_by_header_not_by_folder(tmp_path):
    """An output-side CSV anywhere is read by its header; a canonical CSV in the same folder is not touched."""
    t = np.arange(200) / 100.0
    f = _write(tmp_path / "x.csv", ["t", "q_out", "dq_out", "iq"],
               np.column_stack([t, 0.1 * t, 0.1 + 0 * t, np.ones_like(t)]))
    s = loaders.load(f, params=_params())
    assert s.meta["profile"] == "output_side_csv"
    assert np.allclose(s.channels["velocity"], 0.1 * GEAR)
    g = _write(tmp_path / "y.csv", ["time", "current", "velocity"], np.column_stack([t, t, t]))
    assert "profile" not in loaders.load(g).meta


def test_gear_side_mismatch_names_the_profile_field(tmp_path):
    """Position mapped on the output side but velocity on the motor side: cleaning's consistency check says
    which profile field fixes it."""
    t = np.arange(2000) / 200.0
    q_out = 0.5 * np.sin(2 * np.pi * 0.3 * t) + 0.05 * t
    f = _write(tmp_path / "z.csv", ["stamp", "pos", "vel", "cur"],
               np.column_stack([t, q_out, np.gradient(q_out, t) * GEAR, np.sin(t)]))
    prof = tmp_path / "p.yaml"
    prof.write_text("name: half_right\nsignature: {header_has: [stamp, pos]}\ntime: {column: stamp}\n"
                    "columns: {position: pos, velocity: vel, current: cur}\n")
    s = clean(loaders.load(f, profile=str(prof)), params=_params())
    iss = [i for i in s.issues if i.kind == "unit_suspect" and i.channel == "position"]
    assert iss and "output side" in iss[0].detail
    assert "input profile half_right" in iss[0].action and "side.position" in iss[0].action


def test_quirk_operations():
    from bldc_actuator.diagnosis.signals import Signals

    t = np.arange(500) / 100.0
    cmd = np.sin(t)
    s = Signals(t, {"torque_command": cmd, "current": -2 * cmd, "torque": cmd.copy()}, "q",
                meta={"aux": {"a": -cmd}})
    quirks.apply(s, [{"op": "align_sign", "channels": ["current"], "aux": ["a"], "reference": "torque_command"}])
    assert np.allclose(s.channels["current"], 2 * cmd) and np.allclose(s.meta["aux"]["a"], cmd)
    assert [i.kind for i in s.issues] == ["sign_convention"]
    quirks.apply(s, [{"op": "mask_when", "channels": ["torque"], "when": "abs(torque_command) > 0.99",
                      "min_duration_s": 0.0, "kind": "outlier", "detail": "test"}])
    assert np.isnan(s.channels["torque"][np.abs(cmd) > 0.99]).all()
    assert s.meta["premasked"]["torque"] == int(np.sum(np.abs(cmd) > 0.99))
    with pytest.raises(quirks.ExpressionError, match="not allowed"):
        quirks.evaluate("__import__('os')", {})
