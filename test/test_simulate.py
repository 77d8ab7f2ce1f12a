"""`bldc-actuator simulate` end to end, and command profiles from CSV."""

import csv

import numpy as np
import pytest

from bldc_actuator import profiles
from bldc_actuator.cli import main


def test_simulate_csv_profile_writes_all_signals(tmp_path, capsys):
    src = tmp_path / "cmd.csv"
    src.write_text("time,torque_command,load_torque\n0,0,0\n0.01,0.5,0\n0.2,0.5,0.2\n0.3,0,0\n")
    rc = main(["simulate", "--profile", "csv", "--input", str(src), "--out", str(tmp_path / "run"),
               "--no-plot", "--preset", "ak80_9"])
    assert rc == 0
    with (tmp_path / "run.csv").open() as fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    header = rows[0]
    assert header[0] == "t [s]" and "i_phase_a [A]" in header and "T_winding [degC]" in header
    data = np.array(rows[1:], dtype=float)
    t = data[:, 0]
    assert t[-1] == pytest.approx(0.3)
    # torque command 0.5 N*m at the output of a 9:1 gear: i_q_ref = 0.5 / (9 K_t_q)
    from bldc_actuator.params import load_preset
    p = load_preset("ak80_9")
    iref = data[:, header.index("i_q_ref [A]")]
    assert np.max(iref) == pytest.approx(0.5 / (9 * p.motor.torque_constant_q), rel=1e-9)
    out = capsys.readouterr().out
    assert "residual" in out


def test_simulate_png(tmp_path):
    rc = main(["simulate", "--profile", "chirp", "--duration", "0.2", "--out", str(tmp_path / "c")])
    assert rc == 0
    png = (tmp_path / "c.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


def test_csv_profile_errors_name_the_line(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,current_command\n0,1\n0.1,abc\n")
    with pytest.raises(ValueError, match=r"bad.csv:3"):
        profiles.from_csv(bad)
    bad.write_text("time,current_command\n0,1\n0.1,2\n0.05,3\n")
    with pytest.raises(ValueError, match="strictly increasing"):
        profiles.from_csv(bad)
    bad.write_text("t,current_command\n0,1\n")
    with pytest.raises(ValueError, match="'time'"):
        profiles.from_csv(bad)


def test_simulate_bad_arguments_exit_2(tmp_path, capsys):
    assert main(["simulate", "--preset", "no_such_motor", "--out", str(tmp_path / "x")]) == 2
    assert "no preset named" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["simulate", "--duration", "-1"])


def _simulate_csv(tmp_path, name, rows, *extra):
    src = tmp_path / f"{name}.csv"
    src.write_text("time,current_command\n" + "".join(f"{t!r},{c!r}\n" for t, c in rows))
    assert main(["simulate", "--profile", "csv", "--input", str(src), "--out", str(tmp_path / name), "--no-plot",
                 "--preset", "ak80_9", *extra]) == 0
    with (tmp_path / f"{name}.csv").open() as fh:
        data = list(csv.reader(line for line in fh if not line.startswith("#")))
    return data[0], np.array(data[1:], dtype=float)


def test_simulate_csv_writes_at_the_output_rate_not_at_the_input_rows(tmp_path, capsys):
    """Issue #16: 4 command rows (a 5 A step held for 0.45 s) and the same steps written as 1001 rows at 1 kHz
    are the same zero-order-hold command, so the run is the same physics: the same trace at --rate, the same
    peak current (the loop reaches the 5 A step), not a summary of four samples."""
    def command(t):
        return 5.0 if 0.05 <= t < 0.5 else 0.0

    short = [(0.0, 0.0), (0.05, 5.0), (0.5, 0.0), (1.0, 0.0)]
    dense = [(k / 1000, command(k / 1000)) for k in range(1001)]
    header, a = _simulate_csv(tmp_path, "short", short)
    out_short = capsys.readouterr().out
    _, b = _simulate_csv(tmp_path, "dense", dense)
    out_dense = capsys.readouterr().out
    assert a.shape == b.shape == (1001, len(header))          # 1 s at the default --rate 1000 Hz
    t, i_q = header.index("t [s]"), header.index("i_q [A]")
    assert np.allclose(a[:, t], np.arange(1001) / 1000.0, atol=1e-12)
    peak_short, peak_dense = np.max(np.abs(a[:, i_q])), np.max(np.abs(b[:, i_q]))
    assert peak_short == pytest.approx(peak_dense, rel=1e-6)
    assert 4.5 < peak_dense < 5.5                              # the PI loop settles on the 5 A command
    assert np.allclose(a[:, i_q], b[:, i_q], rtol=1e-6, atol=1e-9)
    peak_line = [line for line in out_short.splitlines() if line.startswith("peak |i_q|")]
    assert peak_line and peak_line == [line for line in out_dense.splitlines() if line.startswith("peak |i_q|")]
    # --rate sets the output rate of a csv profile too
    _, c = _simulate_csv(tmp_path, "slow", short, "--rate", "200")
    assert len(c) == 201 and np.max(np.abs(c[:, i_q])) == pytest.approx(peak_dense, rel=0.05)


def _summary_lines(out):
    return [line for line in out.splitlines() if line.startswith(("peak |i_q|", "winding temperature"))]


def test_simulate_summary_is_the_simulations_not_the_output_rates(tmp_path, capsys):
    """Issue #25: the printed peak |i_q| was the peak of the trace sampled at --rate (5.00 / 5.87 / 7.57 A at 100 /
    1000 / 10000 Hz for one run: a +5 A run-up to the voltage limit, then -5 A at 228 rad/s, whose overshoot lasts a
    few ticks). The summary covers every current-loop tick: the same figures at every rate, the overshoot's peak."""
    rows = [(0.0, 0.0), (0.05, 5.0), (0.6, -5.0), (0.8, -5.0)]
    lines = {}
    for rate in ("100", "1000", "10000"):
        _simulate_csv(tmp_path, f"rev{rate}", rows, "--rate", rate)
        lines[rate] = _summary_lines(capsys.readouterr().out)
    assert len(lines["100"]) == 2
    assert lines["100"] == lines["1000"] == lines["10000"]
    peak = float(lines["100"][0].split()[2])
    assert peak > 7.0                   # the reversal's overshoot (test_simulate_reversal.py), seen at any rate
    # the Python API says the same (SimResult.summary)
    from bldc_actuator.simulate import simulate_profile

    prof = profiles.Profile([r[0] for r in rows], [r[1] for r in rows])
    a, b = simulate_profile("ak80_9", prof, rate=100.0), simulate_profile("ak80_9", prof, rate=3000.0)
    assert a.summary.peak_abs_i_q == pytest.approx(b.summary.peak_abs_i_q, rel=1e-9) == pytest.approx(peak, abs=1e-3)
    assert a.summary.ticks == b.summary.ticks == 8000
    assert np.max(np.abs(a["i_q"])) < 5.01 < a.summary.peak_abs_i_q      # the 100 Hz trace misses the overshoot


def test_csv_time_in_milliseconds_is_an_error_unless_declared(tmp_path, capsys):
    """Issue #25: a command CSV whose time column is in ms (0..900 in steps of 1) ran silently for 900 s (rc 0).
    Now an error naming the column, the expected unit and the fixes; declared (--time-unit ms or a column t_ms),
    the same file is a 0.9 s run, the same physics as the file written in seconds."""
    ms_rows = "".join(f"{k},{5.0 if 100 <= k < 600 else 0.0}\n" for k in range(901))
    src = tmp_path / "ms.csv"
    src.write_text("time,current_command\n" + ms_rows)
    out = str(tmp_path / "run")
    assert main(["simulate", "--profile", "csv", "--input", str(src), "--out", out, "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "'time'" in err and "milliseconds" in err and "expected seconds" in err
    assert "--time-unit ms" in err and "t_ms" in err and "900 s" in err
    assert not (tmp_path / "run.csv").exists()
    with pytest.raises(ValueError, match="looks like milliseconds"):
        profiles.from_csv(src)
    # declared: the option, or the header's unit (t_ms, "time [ms]")
    a = profiles.from_csv(src, time_unit="ms")
    (tmp_path / "t_ms.csv").write_text("t_ms,current_command\n" + ms_rows)
    (tmp_path / "bracket.csv").write_text("time [ms],current_command\n" + ms_rows)
    b, c = profiles.from_csv(tmp_path / "t_ms.csv"), profiles.from_csv(tmp_path / "bracket.csv")
    assert a.duration == b.duration == c.duration == pytest.approx(0.9)
    assert np.array_equal(a.t, b.t) and np.array_equal(a.values, c.values)
    s_rows = "".join(f"{k / 1000!r},{5.0 if 100 <= k < 600 else 0.0}\n" for k in range(901))
    (tmp_path / "s.csv").write_text("time,current_command\n" + s_rows)
    assert np.allclose(profiles.from_csv(tmp_path / "s.csv").t, a.t, rtol=0, atol=1e-12)
    assert main(["simulate", "--profile", "csv", "--input", str(src), "--time-unit", "ms", "--out", out,
                 "--no-plot", "--preset", "ak80_9"]) == 0
    assert "duration 0.900 s" in capsys.readouterr().out
    # a header unit and a different --time-unit contradict each other; --time-unit s confirms seconds
    with pytest.raises(ValueError, match="says ms"):
        profiles.from_csv(tmp_path / "t_ms.csv", time_unit="s")
    assert profiles.from_csv(src, time_unit="s").duration == 900.0
    # a few sparse rows in seconds (the common hand-written profile) are not suspect
    (tmp_path / "sparse.csv").write_text("time,current_command\n0,0\n0.05,5\n0.5,0\n1.0,0\n")
    assert profiles.from_csv(tmp_path / "sparse.csv").duration == 1.0


def test_absurd_commands_are_refused_by_the_nodes_rule(tmp_path, capsys):
    """Issue #25: a 1.5e12 N*m command was accepted silently. Refused (exit 2) with the field, the limit and unit:
    the node scheduler's rule (scheduler.absurd_limits: 10 x drive.current_limit, in current or output torque),
    not a second one; a command between the limit and that is accepted and limited by the drive."""
    from bldc_actuator.params import load_preset
    from bldc_actuator.scheduler import absurd_limits
    from bldc_actuator.simulate import simulate_profile

    p = load_preset("ak80_9")
    i_max, tau_max = absurd_limits(p)
    assert i_max == pytest.approx(10 * p.drive.current_limit)
    src = tmp_path / "absurd.csv"
    src.write_text("time,torque_command\n0,0\n0.01,1.5e12\n0.02,0\n")
    out = str(tmp_path / "run")
    assert main(["simulate", "--profile", "csv", "--input", str(src), "--out", out, "--no-plot",
                 "--preset", "ak80_9"]) == 2
    err = capsys.readouterr().err
    assert "torque_command" in err and "1.5e+12 N*m" in err and "absurd" in err
    assert f"{tau_max:g} N*m" in err and "drive.current_limit" in err
    assert not (tmp_path / "run.csv").exists()
    assert main(["simulate", "--amplitude", "1e6", "--out", out, "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "--amplitude" in err and "current command 1e+06 A" in err and " A (10 x drive.current_limit" in err
    with pytest.raises(ValueError, match="absurd"):
        simulate_profile(p, profiles.step(1.5e12, 0.1, kind="torque"))
    # just inside the node's bound: accepted, the drive limits the current to drive.current_limit
    r = simulate_profile(p, profiles.step(0.99 * i_max, 0.02, t_step=0.005))
    assert r.summary.peak_abs_i_q <= p.drive.current_limit * 1.1
    assert np.max(r["i_q_ref"]) == pytest.approx(p.drive.current_limit)


def test_tick_trace_records_every_tick_whatever_the_callers_steps():
    """Actuator.tick_trace: stepped in uneven chunks (off the tick grid), it holds the state at every tick instant,
    the same as an actuator stepped tick by tick and read at each (to the splitting's effect: an interval split off
    the tick grid is integrated in two parts, ~1e-4 A here while the rotor breaks away from static friction)."""
    from bldc_actuator.model import Actuator
    from bldc_actuator.params import load_preset

    p = load_preset("ak80_9")
    a, b = Actuator(p, warn=False), Actuator(p, warn=False)
    a.set_current_command(5.0), b.set_current_command(5.0)
    tr = a.tick_trace(4)                      # grows as needed
    tr.record_now()
    for dt in (370_000, 1_300_000, 50_000, 1_280_000):
        tr.step_ns(dt)
    st = tr.states()
    tick = int(round(1e9 / p.drive.current_loop_rate))
    assert st["t_ns"][0] == 0 and np.all(np.diff(st["t_ns"]) == tick) and st["t_ns"][-1] == 3_000_000
    assert a.t_ns == 3_000_000
    ref = []
    for _ in range(len(st)):
        ref.append(b.state.i_q)
        b.step_ns(tick)
    assert np.allclose(st["i"].imag, ref, rtol=0, atol=1e-3)
    sig = a.tick_signals(st)
    assert np.allclose(sig["velocity_out"], st["omega"] / p.gear.gear_ratio)
    assert np.max(sig["i_q"]) > 4.5
