"""Data layer of ``bldc-actuator diagnose``: loading (CSV, MCAP, mappings), cleaning (every glitch found,
counted, timed and reported; nothing dropped silently) and the real-data adapters (../shared/data)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bldc_actuator.diagnosis.io.cleaning import clean
from bldc_actuator.diagnosis.io.loaders import LoadError, Mapping, load, load_csv, load_mcap, parse_expression
from bldc_actuator.diagnosis.signals import CANONICAL, DataIssue, Signals
from bldc_actuator.params import ActuatorParams

SEC = 1_000_000_000


def _issues(sig: Signals, kind: str, channel: str | None = None) -> list[DataIssue]:
    return [i for i in sig.issues if i.kind == kind and (channel is None or i.channel == channel)]


# --------------------------------------------------------------------------------- synthetic dirty CSV

T_SPIKE, T_NAN, T_DUP, T_SWAP, T_GAP = 0.5, 0.7, 0.3, 1.7, 0.999


def _dirty_csv(path, rng=np.random.default_rng(7)):
    """2000 samples at 1 kHz with: a -504 A spike, a NaN, a duplicated row, two swapped rows, a 0.5 s gap,
    winding temperature in kelvin and torque in N*mm. Returns the number of data rows written."""
    n, dt = 2000, 0.001
    t = np.arange(n) * dt
    t[1000:] += 0.5
    cmd = np.where((t % 0.4) < 0.2, 5.0, -5.0)
    cur = cmd + rng.normal(0, 0.05, n)
    vel = np.cumsum(cur) * 0.01 + rng.normal(0, 0.01, n)
    pos = np.cumsum(vel) * dt
    temp_k = 25 + 273.15 + 0.001 * np.arange(n)
    torque_nmm = cur * 0.091 * 1000 + rng.normal(0, 1, n)
    cur[int(round(T_SPIKE / dt))] = -504.0
    rows = [[float(t[i]), cmd[i], cur[i], vel[i], pos[i], temp_k[i], torque_nmm[i]] for i in range(n)]
    text = [",".join(repr(float(v)) for v in r) for r in rows]
    k = int(round(T_NAN / dt))
    parts = text[k].split(",")
    parts[2] = "nan"
    text[k] = ",".join(parts)
    k = int(round(T_SWAP / dt)) - 500          # after the gap: index shifted by the 0.5 s
    text[k], text[k + 1] = text[k + 1], text[k]
    text.insert(int(round(T_DUP / dt)) + 1, text[int(round(T_DUP / dt))])
    path.write_text("time,current_command,current,velocity,position,winding_temperature,torque\n"
                    + "\n".join(text) + "\n")
    return len(text)


def test_dirty_csv_every_glitch_found_counted_and_timed(tmp_path):
    f = tmp_path / "dirty.csv"
    rows = _dirty_csv(f)
    raw = load_csv(f)
    assert len(raw.time) == rows
    s = clean(raw, params=ActuatorParams())

    spike = _issues(s, "outlier", "current")
    assert len(spike) == 1 and spike[0].count == 1
    assert spike[0].first_time == pytest.approx(T_SPIKE)
    assert "-504" in spike[0].detail and "masked" in spike[0].action
    assert list(s.meta["masked"]["current"]["value"]) == [-504.0]
    assert not np.isfinite(s.channels["current"][np.argmin(abs(s.time - T_SPIKE))])

    nan = _issues(s, "nan", "current")
    assert len(nan) == 1 and nan[0].count == 1 and nan[0].first_time == pytest.approx(T_NAN)

    dup = _issues(s, "duplicate_time")
    assert len(dup) == 1 and dup[0].count == 1 and dup[0].first_time == pytest.approx(T_DUP)
    assert dup[0].action == "dropped later duplicate" and "0 of them with different values" in dup[0].detail

    nm = _issues(s, "non_monotonic_time")
    assert len(nm) == 1 and nm[0].count == 1 and "re-ordered" in nm[0].action

    gap = _issues(s, "gap")
    assert len(gap) == 1 and gap[0].count == 1 and gap[0].first_time == pytest.approx(T_GAP)
    assert "0.501 s" in gap[0].detail and gap[0].action == "segment split"
    assert s.segments == [(0, 1000), (1000, 2000)]

    kelvin = _issues(s, "unit_suspect", "winding_temperature")
    assert len(kelvin) == 1 and "kelvin" in kelvin[0].detail and "-273.15" in kelvin[0].action
    nmm = _issues(s, "unit_suspect", "torque")
    assert len(nmm) == 1 and "N*mm" in nmm[0].detail and "*0.001" in nmm[0].action
    # unit suspects are reported, not "fixed" and not masked away by the physical limits
    assert np.nanmedian(s.channels["winding_temperature"]) > 273 and np.isfinite(s.channels["torque"]).all()

    # nothing dropped silently: every input row is either kept or counted as dropped
    acc = s.meta["accounting"]
    assert acc["rows_in"] == rows == acc["rows_out"] + sum(acc["dropped"].values())
    assert acc["dropped"] == {"nan_time": 0, "non_monotonic_time": 0, "duplicate_time": 1}
    assert acc["masked"] == {"current": 1}
    assert np.all(np.diff(s.time) > 0)
    # every issue carries numbers
    assert all(any(ch.isdigit() for ch in i.detail) for i in s.issues)
    js = s.to_json_issues()
    assert {"kind", "channel", "count", "first_time", "detail", "action"} <= set(js[0])


def test_spike_found_by_robust_statistics_without_parameters(tmp_path):
    f = tmp_path / "dirty.csv"
    _dirty_csv(f)
    s = clean(load_csv(f))                      # no params: only generic bounds (1000 A) apply
    spike = _issues(s, "outlier", "current")
    assert len(spike) == 1 and spike[0].count == 1 and "spike" in spike[0].detail
    assert spike[0].first_time == pytest.approx(T_SPIKE)
    # a step edge of the command (5 -> -5 A every 0.2 s) is not a spike
    assert s.meta["accounting"]["masked"] == {"current": 1}


AMBIENT_C, T_ON = 25.0, 0.05


def _heating_run(winding=None, housing=None, n=4000, rate=1000.0) -> Signals:
    """Motion both ways, a current switched on at T_ON and the first-order heating it causes (analytic step
    response, time constant 0.8 s / 2 s): both temperatures sit exactly at ambient until T_ON (50 samples, 1.25 %
    of the record), as the demo's recording does. ``winding``/``housing`` replace a temperature channel."""
    t = np.arange(n) / rate
    w = 5 * np.sin(2 * np.pi * 0.7 * t) + 2 * np.sin(2 * np.pi * 2.1 * t)
    th = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) / rate)])
    on = t >= T_ON
    rise = lambda tau: np.where(on, -np.expm1(-(t - T_ON) / tau), 0.0)  # noqa: E731
    ch = {"position": th, "velocity": w, "current": np.where(on, 0.5 * w + 1.0, 0.0),
          "winding_temperature": AMBIENT_C + 3.0 * rise(0.8) if winding is None else winding,
          "housing_temperature": AMBIENT_C + 0.5 * rise(2.0) if housing is None else housing}
    return Signals(t, ch, "heating")


def test_temperature_at_ambient_before_the_heating_is_not_clipped():
    """The run a channel starts in is its initial state, not a limit: nothing is flagged "clipped" (it was, with
    the demo's 51 samples at 25 degC), yet a sensor ceiling or a floor the signal comes back to still is, with
    exactly the clipped samples counted."""
    s = clean(_heating_run(), params=ActuatorParams())
    assert _issues(s, "clipped") == [] and s.meta["clipped"] == {}
    # a winding sensor that tops out at ambient + 2.9 K: the samples above are counted, from the first one
    t = np.arange(4000) / 1000.0
    true_w = AMBIENT_C + 3.0 * np.where(t >= T_ON, -np.expm1(-(t - T_ON) / 0.8), 0.0)
    ceiling = AMBIENT_C + 2.9
    s = clean(_heating_run(winding=np.minimum(true_w, ceiling)), params=ActuatorParams())
    (hit,) = _issues(s, "clipped", "winding_temperature")
    assert hit.count == int((true_w >= ceiling).sum()) > 1000 and "max" in hit.detail
    assert hit.first_time == pytest.approx(t[np.argmax(true_w >= ceiling)])
    assert s.meta["clipped"]["winding_temperature"]["levels"] == [ceiling]
    # a housing sensor whose floor is the start value, the signal swinging 3 K about ambient + 1 K after T_ON:
    # only the samples that come back to the floor count, not the 50 it starts with
    swing = AMBIENT_C + np.where(t >= T_ON, 1.0 + 3.0 * np.sin(2 * np.pi * 0.5 * (t - T_ON)), 0.0)
    s = clean(_heating_run(housing=np.maximum(swing, AMBIENT_C)), params=ActuatorParams())
    (hit,) = _issues(s, "clipped", "housing_temperature")
    assert hit.count == int(((swing <= AMBIENT_C) & (t >= T_ON)).sum()) > 1000 and "min" in hit.detail
    first = t[np.argmax((swing <= AMBIENT_C) & (t >= T_ON))]
    assert first > 1.0 and hit.first_time == pytest.approx(first)


def test_clock_jump_back_is_dropped_reported_and_split(tmp_path):
    t = np.concatenate([np.arange(100) * 0.01, 0.505 + np.arange(100) * 0.01])   # clock jumps back 0.485 s
    f = tmp_path / "reset.csv"
    f.write_text("time,current\n" + "\n".join(f"{float(x)!r},{math.sin(x)}" for x in t) + "\n")
    s = clean(load_csv(f))
    nm = _issues(s, "non_monotonic_time")
    assert len(nm) == 1 and nm[0].count == 49 and "dropped" in nm[0].action   # 0.505 .. 0.985 s
    assert nm[0].first_time == pytest.approx(0.99)
    assert s.meta["accounting"]["rows_in"] == 200 == s.meta["accounting"]["rows_out"] + 49
    assert len(s.segments) == 2 and np.all(np.diff(s.time) > 0)


def test_parse_error_names_line_and_column(tmp_path):
    f = tmp_path / "bad.csv"
    f.write_text("time,current\n0.0,1\n0.1,2\n0.2,abc\n0.3,4\n")
    with pytest.raises(LoadError, match=r"line 4, column 'current'.*'abc'"):
        load_csv(f)
    f.write_text("0.0,1\n0.1,2\n")
    with pytest.raises(LoadError, match="header"):
        load_csv(f)
    f.write_text("t,current\n0.0,1\n")
    with pytest.raises(LoadError, match="no 'time' column"):
        load_csv(f)
    f.write_text("time,current\n0.0,1\n0.1\n")           # short last row: NaN, reported
    s = load_csv(f)
    assert np.isnan(s.channels["current"][1]) and _issues(s, "nan")[0].count == 1


def test_mapping_expressions_and_scaling(tmp_path):
    assert parse_expression("speed*9") == ("speed", 9.0, 0.0)
    assert parse_expression("-adc_torque") == ("adc_torque", -1.0, 0.0)
    assert parse_expression("temp_K-273.15") == ("temp_K", 1.0, -273.15)
    assert parse_expression("t_ms/1000") == ("t_ms", 0.001, 0.0)
    assert parse_expression("2*x+1") == ("x", 2.0, 1.0)
    assert parse_expression('"velocity (Rad/S)"*9') == ("velocity (Rad/S)", 9.0, 0.0)
    assert parse_expression("/ns/motor.velocity[0]*9") == ("/ns/motor.velocity[0]", 9.0, 0.0)
    with pytest.raises(ValueError, match="not a canonical name"):
        Mapping.parse(["speed=foo"])
    with pytest.raises(ValueError, match="expected CANONICAL=EXPRESSION"):
        Mapping.parse(["velocity"])

    f = tmp_path / "foreign.csv"
    f.write_text("t_ms,iq_measured,speed,adc_torque\n0,1.0,2.0,3.0\n10,1.5,-1.0,-2.0\n")
    m = Mapping.parse(["time=t_ms*0.001", "current=iq_measured", "velocity=speed*9", "torque=-adc_torque"])
    s = load(f, mapping=m)
    assert np.allclose(s.time, [0.0, 0.01])
    assert np.allclose(s.channels["velocity"], [18.0, -9.0])
    assert np.allclose(s.channels["torque"], [-3.0, 2.0])
    assert s.meta["mapping"]["velocity"] == "9*speed"
    with pytest.raises(LoadError, match="no column 'nope'"):
        load_csv(f, Mapping.parse(["time=t_ms", "current=nope"]))

    y = tmp_path / "map.yaml"
    y.write_text("time: t_ms*0.001\nvelocity: speed\n")
    assert Mapping.from_yaml(y).scale == {"time": 0.001, "velocity": 1.0}
    y.write_text("columns: {time: t_ms, velocity: speed}\nscale: {velocity: 9}\noffset: {time: 1.0}\n")
    m = Mapping.from_yaml(y)
    assert m.scale["velocity"] == 9.0 and m.offset["time"] == 1.0

    h = tmp_path / "headerless.csv"                       # headerless: columns by index
    h.write_text("0.0,5.0\n0.1,6.0\n")
    s = load_csv(h, Mapping.parse(["time=#0", "current=#1*2"]))
    assert np.allclose(s.channels["current"], [10.0, 12.0])


def test_signals_api():
    t = np.arange(10) * 0.1
    s = Signals(t, {"current": np.where(t < 0.5, 1.0, np.nan), "velocity": np.full(10, np.nan)}, "x")
    assert s.has("current") and not s.has("velocity") and not s.has("torque")
    assert s.missing_for(["current", "velocity", "torque_command|current_command"]) == \
        ["velocity", "torque_command|current_command"]
    assert s.rate() == pytest.approx(10.0)
    sub = s.slice(0.2, 0.5)
    assert len(sub) == 3 and sub.time[0] == pytest.approx(0.2) and sub.segments == [(0, 3)]
    with pytest.raises(ValueError, match="not a canonical channel"):
        Signals(t, {"iq": t})
    with pytest.raises(ValueError, match="not one of"):
        DataIssue("weird", "time", 1, None, "x", "none")
    assert set(CANONICAL) >= {"current", "torque", "position", "voltage_q", "bus_current"}


def test_position_units_and_wrapping(tmp_path):
    t = np.arange(0, 4, 0.001)
    w = 3.0 + np.sin(t)                                   # rad/s
    theta = np.cumsum(w) * 0.001
    deg = np.degrees(theta)
    f = tmp_path / "deg.csv"
    f.write_text("time,position,velocity\n" + "\n".join(f"{float(a)!r},{float(b)!r},{float(c)!r}" for a, b, c in zip(t, deg, w)))
    s = clean(load_csv(f))
    u = _issues(s, "unit_suspect", "position")
    assert len(u) == 1 and "degrees" in u[0].detail and "0.0174533" in u[0].action
    wrapped = np.mod(theta, 2 * np.pi)                    # wraps twice in 4 s at ~3.3 rad/s
    f.write_text("time,position,velocity\n" + "\n".join(f"{float(a)!r},{float(b)!r},{float(c)!r}" for a, b, c in zip(t, wrapped, w)))
    s = clean(load_csv(f))
    wr = _issues(s, "wrapped", "position")
    assert len(wr) == 1 and wr[0].count == int(theta[-1] // (2 * np.pi))
    assert np.allclose(s.channels["position"], theta, atol=1e-6)
    assert not _issues(s, "unit_suspect")


# ------------------------------------------------------------------------------------------------ MCAP

@pytest.fixture
def recorder():
    pytest.importorskip("rclpy", reason="rclpy not importable: cannot serialise ROS messages")
    rec = pytest.importorskip("bldc_actuator.recording", reason="recording module absent")
    return rec


def _write_node_like(recording, path, n=1500, gear=9.0, names=None, **params):
    """A recording with the node's topic layout (written with McapRecorder, values known)."""
    from sensor_msgs.msg import JointState, Temperature
    from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension

    q_fields = ("i_q", "i_d", "i_q_ref", "v_q", "v_d", "v_limit_q", "bus_voltage", "v_magnitude_q", "omega",
                "torque_em", "current_limit_effective", "joule_power", "resistance_phase", "voltage_saturated",
                "tripped")
    p = ActuatorParams().replace(**{"gear.gear_ratio": gear, **params})
    with recording.McapRecorder(path, parameters=p.to_flat(), metadata={"node": "/bldc_actuator"}) as rec:
        q = Float64MultiArray()
        q.layout.dim = [MultiArrayDimension(label=",".join(q_fields), size=len(q_fields), stride=len(q_fields))]
        for k in range(n):
            t_ns = k * 1_000_000
            x = k * 1e-3
            j = JointState(name=names[k % len(names)] if names else ["joint"])
            j.header.stamp.sec, j.header.stamp.nanosec = divmod(t_ns, SEC)
            j.position = [math.cos(x) + 0.0 * i for i in range(len(j.name))]
            j.velocity = [-math.sin(x)] * len(j.name)
            j.effort = [0.1] * len(j.name)
            q.data = [2.0 + math.sin(x), 0.01, 2.0, 1.5, -0.1, 16.9, 24.0, 1.5, -gear * math.sin(x), 0.2, 20.0,
                      0.5, 0.17, 0.0, 0.0]
            tw = Temperature(temperature=30.0 + x)
            tw.header.stamp = j.header.stamp
            rec.write("/joint_states", j, t_ns)
            rec.write("/bldc_actuator/q_axis_state", q, t_ns)
            rec.write("/bldc_actuator/winding_temperature", tw, t_ns)
            if k == 500:
                rec.write("/bldc_actuator/torque_command", Float64(data=1.5), t_ns)
        rec.add_topic("/bldc_actuator/load_torque", "std_msgs/msg/Float64")
    return p


def test_own_mcap_recording_round_trip(recorder, tmp_path):
    f = tmp_path / "run.mcap"
    _write_node_like(recorder, f)
    s = load(f)
    x = np.arange(1500) * 1e-3
    assert s.meta["own_recording"] and s.meta["gear_ratio"] == 9.0
    assert s.meta["params_from_recording"].gear.gear_ratio == 9.0
    assert np.allclose(s.time, x)
    assert np.allclose(s.channels["current"], 2.0 + np.sin(x))
    assert np.allclose(s.channels["velocity"], -9.0 * np.sin(x))
    assert np.allclose(s.channels["position"], 9.0 * np.cos(x))      # output side x gear ratio
    assert np.allclose(s.channels["winding_temperature"], 30.0 + x)
    assert np.allclose(s.channels["bus_voltage"], 24.0)
    tc = s.channels["torque_command"]                                # held; 0 before the first message
    assert np.all(tc[:500] == 0.0) and np.all(tc[500:] == 1.5)
    assert np.all(s.channels["load_torque"] == 0.0)
    assert set(s.meta["extraction"].values()) == {"cdr-vectorised, time=header.stamp", "cdr-vectorised"}
    c = clean(s, params=s.meta["params_from_recording"])
    assert not _issues(c, "unit_suspect") and not _issues(c, "outlier")   # position/velocity consistent


def test_own_mcap_load_side_encoder_is_load_position(recorder, tmp_path):
    """gear.encoder_side: load -> the node's joint_states position is the load's angle (output side, no gear
    factor), read as load_position; the rotor's angle is absent (never the load's angle x gear)."""
    f = tmp_path / "run.mcap"
    _write_node_like(recorder, f, **{"gear.transmission_stiffness": 120.0, "gear.load_inertia": 0.01,
                                     "gear.encoder_side": "load"})
    s = load(f)
    x = np.arange(1500) * 1e-3
    assert np.allclose(s.channels["load_position"], np.cos(x))       # output side, as recorded
    assert "position" not in s.channels
    assert np.allclose(s.channels["velocity"], -9.0 * np.sin(x))     # the rotor's, from q_axis_state
    assert any("encoder_side: load" in n for n in s.meta["notes"])   # said, not silent


def test_foreign_mcap_with_mapping_and_variable_layout(recorder, tmp_path):
    f = tmp_path / "foreign.mcap"
    # joint names vary in number: message length varies -> per-message path, lookup by joint name
    _write_node_like(recorder, f, n=400, names=[["wrist"], ["elbow", "wrist"]])
    m = Mapping.parse(["velocity=/joint_states.velocity[wrist]*9", "current=q_axis_state.data[0]",
                       "bus_voltage=/bldc_actuator/q_axis_state.bus_voltage"])
    s = load_mcap(f, mapping=m)
    x = np.arange(400) * 1e-3
    assert s.meta["extraction"]["/joint_states"].startswith("cdr-per-message")
    assert np.allclose(s.channels["velocity"], -9.0 * np.sin(x))
    assert np.allclose(s.channels["current"], 2.0 + np.sin(x))
    assert np.allclose(s.channels["bus_voltage"], 24.0)
    with pytest.raises(LoadError, match="no such topic"):
        load_mcap(f, mapping=Mapping.parse(["current=/nope.data"]))
    with pytest.raises(LoadError, match="no numeric field 'i_x'"):
        load_mcap(f, mapping=Mapping.parse(["current=q_axis_state.i_x"]))


# ------------------------------------------------------------------------------------------- real data

def test_ak80_9_glitch_files(shared_data_dir):
    import realdata_files as realdata

    s2 = realdata.load_dataset("ak80-9/sysid_final/trial2", shared_data_dir)
    out = [i for i in _issues(s2, "outlier", "current") if "physical limit" in i.detail]
    assert len(out) == 1 and out[0].count == 338 and "504.3" in out[0].detail
    assert out[0].first_time == pytest.approx(7.24, abs=0.005)
    assert np.nanmax(np.abs(s2.channels["current"])) < 25                 # what is left is physical
    assert 504.3 == pytest.approx(np.max(np.abs(s2.meta["masked"]["current"]["value"])), abs=0.05)
    # the telemetry sign was opposite to the command in this trial: detected and reported
    assert _issues(s2, "sign_convention", "current")
    assert np.corrcoef(s2.channels["torque_command"][np.isfinite(s2.channels["current"])],
                       s2.channels["current"][np.isfinite(s2.channels["current"])])[0, 1] > 0.9

    s1 = realdata.load_dataset("ak80-9/sysid_final/trial1", shared_data_dir)
    out = [i for i in _issues(s1, "outlier", "current") if "physical limit" in i.detail]
    assert len(out) == 1 and out[0].count == 457 and "153.5" in out[0].detail
    assert any("drive stopped" in i.detail for i in _issues(s1, "outlier", "torque"))

    s5 = realdata.load_dataset("ak80-9/sysid_final/trial5", shared_data_dir)
    assert s5.rate() == pytest.approx(100.0, rel=1e-3) and s5.meta["gear_ratio"] == 9.0
    assert not [i for i in _issues(s5, "outlier", "current")]
    tq, cmd = s5.channels["torque"], s5.channels["torque_command"]        # Futek aligned with the command
    ok = np.isfinite(tq)
    assert np.corrcoef(tq[ok], cmd[ok])[0, 1] > 0.95


def test_ak80_9_torque_vs_angle_and_servo_efficiency(shared_data_dir):
    import realdata_files as realdata

    s = realdata.load_dataset("ak80-9/torque_vs_angle/synchronized_trial_4", shared_data_dir)
    pos = s.channels["position"]
    assert np.nanmax(pos) - np.nanmin(pos) == pytest.approx(2 * np.pi * 9, rel=0.02)   # one output turn
    assert not _issues(s, "unit_suspect", "position")                     # consistent with the speed
    eff = realdata.load_dataset("ak80-9/servo_efficiency/1666992430.653646", shared_data_dir)
    assert any("velocity (ERPM)" not in i.detail and "2.222 x too small" in i.detail
               for i in _issues(eff, "unit_suspect", "velocity"))
    vq = [i for i in _issues(eff, "outlier", "voltage_q") if "physical limit" in i.detail]
    assert vq and vq[0].count == 1 and "6.711e+04" in vq[0].detail
    assert {"current", "voltage_q", "bus_voltage", "velocity", "torque"} <= set(eff.channels)


def test_odrive_map_steady_state_points(shared_data_dir):
    import realdata_files as realdata

    s = realdata.load_dataset("odrive-d5065/odrive_data", shared_data_dir)
    assert len(s.time) == 344 and s.meta["steady_state_points"] is True
    tq = s.channels["torque"]
    assert 0.5 < np.nanmax(np.abs(tq)) < 2.0                              # N*m, not N*mm
    ok = np.isfinite(tq) & np.isfinite(s.channels["current"])
    assert ok.sum() == 342                                                # 2 rows never reached their speed
    kt = np.sum(tq[ok] * s.channels["current"][ok]) / np.sum(s.channels["current"][ok] ** 2)
    assert 0.02 < kt < 0.035                                              # N*m/A, near 8.27/270
    assert any("did not reach" in i.detail for i in _issues(s, "outlier", "velocity"))


def test_benkatz_logs_plausible(shared_data_dir):
    import realdata_files as realdata

    s = realdata.load_dataset("benkatz-dyno/u8_pro_emap", shared_data_dir)
    assert s.rate() == pytest.approx(200, rel=0.05) and s.meta["sampling"]["irregular"]
    assert 15 < np.nanmin(s.channels["bus_voltage"]) and np.nanmax(s.channels["bus_voltage"]) < 30
    assert np.nanmax(np.abs(s.channels["torque"])) < 5 and np.nanmax(np.abs(s.channels["velocity"])) < 250
    assert len(s.segments) == 1                                           # logger jitter is not a gap
    v = realdata.load_dataset("benkatz-dyno/vs_thermal_4a", shared_data_dir)
    assert 30 < np.nanmin(v.channels["housing_temperature"]) < np.nanmax(v.channels["housing_temperature"]) < 50
    assert np.nanmedian(v.channels["current"]) == pytest.approx(4.0, abs=0.1)   # mA -> A


def test_dataset_registry_and_profile_detection(shared_data_dir, tmp_path):
    import realdata_files as realdata

    infos = {i.name: i for i in realdata.list_datasets(shared_data_dir)}
    assert {"ak80-9/sysid_final/trial2", "odrive-d5065/odrive_data", "benkatz-dyno/friction_test",
            "ak80-9/torque_vs_angle/synchronized_trial_4", "ak80-9/servo_efficiency"} <= set(infos)
    assert infos["ak80-9/sysid_final/trial2"].licence == "GPL-3.0"
    assert infos["benkatz-dyno/friction_test"].licence == "MIT"
    assert infos["odrive-d5065/odrive_data"].kind == "steady_state_points"
    # load() recognises every file by its header alone (its input profile), never by its folder: a copy
    # elsewhere under another name reads the same (output -> motor side etc.)
    import shutil

    copy = tmp_path / "anything.csv"
    shutil.copy(shared_data_dir / "ak80-9" / "sysid_final" / "trial5.csv", copy)
    raw = load(copy)
    assert raw.meta["profile"] == "tmotorcan_mit_log" and raw.meta["profile_how"].startswith("auto")
    assert raw.meta["gear_ratio"] == 9.0 and "clean_limits" in raw.meta
    for info in realdata.list_datasets(shared_data_dir):
        if info.path.endswith(".csv"):
            assert load(info.path).meta.get("profile"), info.name
    with pytest.raises(KeyError, match="no dataset named"):
        realdata.load_dataset("ak80-9/nope", shared_data_dir)


def _rest_then_motion(freeze: tuple[float, float] | None = None, held_speed: float | None = None) -> Signals:
    """3 s at rest (velocity exactly 0, the angle standing still, current noise), then motion; ``freeze``: the
    velocity sensor repeats one value over that span while the angle moves; ``held_speed``: the motion is a
    constant speed whose sensor reads exactly that value."""
    rate = 1000.0
    t = np.arange(8000) / rate
    mov = t >= 3.0
    w = np.where(mov, 5 * np.sin(2 * np.pi * 0.7 * (t - 3)) if held_speed is None else held_speed, 0.0)
    th = 1.0 + np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) / rate)])
    cur = 0.02 * np.random.default_rng(1).standard_normal(len(t)) + np.where(mov, 0.5 * w, 0.0)
    w_meas = w.copy()
    if freeze is not None:
        k = (t > freeze[0]) & (t < freeze[1])
        w_meas[k] = w_meas[np.argmax(k)]
    return Signals(t, {"position": th, "velocity": w_meas, "current": cur}, "rest")


def test_rest_and_held_speed_are_not_a_stuck_sensor_but_a_frozen_speed_is():
    """A velocity of exactly 0 for 3 s while the angle stands still is an actuator at rest (it was flagged "stuck"),
    a speed read exactly constant while the angle advances at that speed is a held speed; a velocity sensor that
    repeats one value for 2.5 s while the angle does something else is stuck — and is found although the rest
    samples make its median step 0 (it was not)."""
    assert _issues(clean(_rest_then_motion(), params=ActuatorParams()), "constant") == []
    assert _issues(clean(_rest_then_motion(held_speed=3.0), params=ActuatorParams()), "constant") == []
    (hit,) = _issues(clean(_rest_then_motion(freeze=(4.0, 6.5)), params=ActuatorParams()), "constant", "velocity")
    assert "stuck" in hit.detail and hit.count == 2499 and hit.first_time == pytest.approx(4.001)
