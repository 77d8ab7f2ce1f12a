"""`bldc-actuator convert`, run in-process through bldc_actuator.cli.main."""

import math
import re

import pytest

from bldc_actuator import cli

S32 = math.sqrt(1.5)
KB_LL_100 = 60 / (2 * math.pi * 100)  # Kv 100 rpm/V, line-to-line peak


def run(capsys, *argv):
    code = cli.main(["convert", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def params(out, winding):
    """motor.* lines of the block for one winding -> dict."""
    block = out.split(f"q-axis model parameters ({winding}):", 1)[1]
    vals = {}
    for key, val in re.findall(r"^\s+motor\.(\w+)\s+=\s+(\S+)", block, re.M):
        if key in vals:
            break
        vals[key] = val
    return vals


def test_delta_example_from_the_brief(capsys):
    code, out, err = run(capsys, "--winding", "delta", "--kv", "100", "--terminal-resistance", "0.186",
                         "--terminal-inductance", "1.2e-4")
    assert code == 0, err
    p = params(out, "delta")
    assert p["winding"] == "delta"
    assert float(p["phase_resistance"]) == pytest.approx(1.5 * 0.186, rel=1e-5)
    assert float(p["q_inductance"]) == pytest.approx(1.5 * 1.2e-4, rel=1e-5)   # physics, not the paper's 1/2
    assert float(p["torque_constant_q"]) == pytest.approx(S32 * KB_LL_100, rel=1e-5)
    # every step explained with its source equation; the paper's inductance factor flagged
    assert "eq. resistance_delta" in out and "Kt_conversion_delta" in out
    assert "inductance_delta" in out and "paper-discrepancies.md" in out
    assert "60 / (2 pi x 100 rpm/V)" in out
    # Kv frame was not given -> assumption warned
    assert "--kv-frame not given" in out


def test_wye(capsys):
    code, out, _ = run(capsys, "--winding", "wye", "--kv", "100", "--terminal-resistance", "0.186",
                       "--terminal-inductance", "1.2e-4", "--kv-frame", "ll_peak")
    assert code == 0
    p = params(out, "wye")
    assert float(p["phase_resistance"]) == pytest.approx(0.093, rel=1e-5)
    assert float(p["q_inductance"]) == pytest.approx(0.6e-4, rel=1e-5)
    assert float(p["torque_constant_q"]) == pytest.approx(KB_LL_100 / math.sqrt(2), rel=1e-5)
    assert "--kv-frame not given" not in out


def test_unknown_winding_prints_both_and_warns(capsys):
    code, out, _ = run(capsys, "--kv", "100", "--terminal-resistance", "0.2")
    assert code == 0
    pw, pd = params(out, "wye"), params(out, "delta")
    assert float(pw["phase_resistance"]) == pytest.approx(0.1, rel=1e-5)
    assert float(pd["phase_resistance"]) == pytest.approx(0.3, rel=1e-5)
    assert float(pd["torque_constant_q"]) / float(pw["torque_constant_q"]) == pytest.approx(math.sqrt(3), rel=1e-5)
    assert "winding unknown" in out and "WARNING" not in out.split("warnings:")[0]


def test_bus_voltage_prints_no_load_speed(capsys):
    code, out, _ = run(capsys, "--winding", "delta", "--kv", "100", "--bus-voltage", "24", "--pole-pairs", "21")
    assert code == 0
    m = re.search(r"omega_max = .* = ([\d.]+) rad/s = ([\d.]+) rpm", out)
    assert m, out
    assert float(m.group(2)) == pytest.approx(2400.0, rel=1e-5)            # V_bus * Kv (ll peak, SVPWM)
    assert float(m.group(1)) == pytest.approx(2400 * 2 * math.pi / 60, rel=1e-5)
    assert "29.3939 V" in out                                              # sqrt(3/2) * 24
    assert params(out, "delta")["pole_pairs"] == "21"


@pytest.mark.parametrize("frame,winding,factor", [
    ("phase_peak", "delta", math.sqrt(2 / 3)), ("line_rms", "delta", 1.0), ("line_peak", "delta", math.sqrt(2)),
    ("q_amplitude_invariant", "wye", math.sqrt(2 / 3)), ("per_phase_amplitude", "wye", S32),
    ("q_power_invariant", "wye", 1.0), ("phase_rms", "wye", 1 / math.sqrt(3)),
])
def test_kt_frames(capsys, frame, winding, factor):
    code, out, _ = run(capsys, "--winding", winding, "--kt", "0.2", "--kt-frame", frame)
    assert code == 0
    assert float(params(out, winding)["torque_constant_q"]) == pytest.approx(0.2 * factor, rel=1e-5)


def test_kt_bus_warns_operating_point(capsys):
    code, out, _ = run(capsys, "--winding", "wye", "--kt", "0.1", "--kt-frame", "bus")
    assert code == 0
    assert float(params(out, "wye")["torque_constant_q"]) == pytest.approx(0.1 / math.sqrt(2), rel=1e-5)
    assert "operating point" in out.split("warnings:")[1]


def test_kt_and_kv_disagree_by_a_named_frame_factor(capsys):
    # delta, Kv 100 -> K_t^q = 0.116955; a "Kt" of 0.0955 read as q-axis is off by sqrt(3/2)
    code, out, _ = run(capsys, "--winding", "delta", "--kv", "100", "--kv-frame", "ll_peak",
                       "--kt", "0.0955", "--kt-frame", "q_power_invariant")
    assert code == 0
    warn = out.split("warnings:")[1]
    assert "sqrt(3/2)" in warn and "--kt-frame were bus" in warn
    assert float(params(out, "delta")["torque_constant_q"]) == pytest.approx(0.0955, rel=1e-5)  # Kt wins


def test_kt_and_kv_agreeing_within_tolerance_is_not_a_warning(capsys):
    code, out, _ = run(capsys, "--winding", "delta", "--kv", "100", "--kv-frame", "ll_peak",
                       "--kt", f"{S32 * KB_LL_100 * 1.05:.6f}", "--kt-frame", "q_power_invariant")
    assert code == 0 and re.search(r"agrees within 4.8 %", out) and "warnings:" not in out


def test_kb_with_unit(capsys):
    # 10 V/krpm line-to-line rms, wye: K_b^q = V_rms per rad/s (factor 1)
    code, out, _ = run(capsys, "--winding", "wye", "--kb", "10", "--kb-unit", "V/krpm", "--kb-frame", "ll_rms")
    assert code == 0
    assert float(params(out, "wye")["torque_constant_q"]) == pytest.approx(10 * 60 / (2 * math.pi * 1000), rel=1e-5)


def test_yaml_snippet(capsys, tmp_path):
    yaml = pytest.importorskip("yaml")
    out_file = tmp_path / "motor.yaml"
    code, out, _ = run(capsys, "--winding", "delta", "--kv", "100", "--terminal-resistance", "0.186",
                       "--terminal-inductance", "1.2e-4", "--pole-pairs", "21", "--yaml", str(out_file))
    assert code == 0 and f"wrote {out_file}" in out
    text = out_file.read_text()
    assert "/**/bldc_actuator:\n  ros__parameters:\n    motor:\n" in text
    data = yaml.safe_load(text)["/**/bldc_actuator"]["ros__parameters"]["motor"]
    assert data["winding"] == "delta" and data["pole_pairs"] == 21
    for key in ("phase_resistance", "q_inductance", "torque_constant_q"):
        assert isinstance(data[key], float), key      # doubles carry '.' or an exponent with a '.' mantissa
        line = re.search(rf"{key}: (\S+)", text).group(1)
        assert "." in line
    assert data["phase_resistance"] == pytest.approx(0.279)
    assert data["q_inductance"] == pytest.approx(1.8e-4)
    assert data["torque_constant_q"] == pytest.approx(S32 * KB_LL_100, rel=1e-10)


def test_yaml_small_values_stay_floats(capsys, tmp_path):
    yaml = pytest.importorskip("yaml")
    out_file = tmp_path / "m.yaml"
    code, _, _ = run(capsys, "--winding", "wye", "--terminal-inductance", "2e-5", "--yaml", str(out_file))
    assert code == 0
    motor = yaml.safe_load(out_file.read_text())["/**/bldc_actuator"]["ros__parameters"]["motor"]
    assert isinstance(motor["q_inductance"], float) and motor["q_inductance"] == pytest.approx(1e-5)


def test_yaml_loads_with_params_module_if_available(capsys, tmp_path):
    params_mod = pytest.importorskip("bldc_actuator.params")
    loader = getattr(params_mod, "load_yaml", None) or getattr(params_mod, "load_params", None)
    if loader is None:
        pytest.skip("params.py has no YAML loader yet")
    out_file = tmp_path / "motor.yaml"
    code, _, _ = run(capsys, "--winding", "delta", "--kv", "100", "--terminal-resistance", "0.186",
                     "--terminal-inductance", "1.2e-4", "--pole-pairs", "21", "--yaml", str(out_file))
    assert code == 0
    try:
        p = loader(out_file)
    except TypeError:
        pytest.skip("params loader has a different signature")
    motor = getattr(p, "motor", None)
    if motor is None:
        pytest.skip("params loader returned no motor block")
    assert motor.phase_resistance == pytest.approx(0.279)
    assert motor.q_inductance == pytest.approx(1.8e-4)
    assert motor.winding == "delta"


@pytest.mark.parametrize("winding", ["wye", "delta"])
def test_verify_reproduces_the_datasheet(capsys, winding):
    code, out, _ = run(capsys, "--winding", winding, "--kv", "270", "--terminal-resistance", "0.039",
                       "--terminal-inductance", "1.57e-5", "--pole-pairs", "7", "--bus-voltage", "48", "--verify")
    assert code == 0, out
    v = out.split(f"verify ({winding})")[1]
    assert "verdict: OK" in v
    errs = [float(e) for e in re.findall(r"\s(\d\.\de[+-]\d\d)\s", v)]
    assert len(errs) >= 5 and max(errs) < 1e-6


def test_verify_with_kt_frames(capsys):
    for frame in ("phase_peak", "line_rms", "q_amplitude_invariant", "per_phase_amplitude", "bus"):
        code, out, _ = run(capsys, "--winding", "delta", "--kt", "0.15", "--kt-frame", frame, "--verify")
        assert code == 0 and "verdict: OK" in out, (frame, out)


def test_verify_marks_the_unused_disagreeing_constant(capsys):
    code, out, _ = run(capsys, "--winding", "delta", "--kv", "100", "--kt", "0.0955",
                       "--kt-frame", "q_power_invariant", "--verify")
    assert code == 0
    assert "(not used: disagrees)" in out and "verdict: OK" in out


def test_verify_unknown_winding_checks_both(capsys):
    code, out, _ = run(capsys, "--kv", "100", "--terminal-resistance", "0.2", "--verify")
    assert code == 0 and "verify (wye)" in out and "verify (delta)" in out


@pytest.mark.parametrize("argv,argument", [
    (["--kv", "-3"], "--kv"),
    (["--kv", "abc"], "--kv"),
    (["--terminal-resistance", "0"], "--terminal-resistance"),
    (["--terminal-inductance", "nan"], "--terminal-inductance"),
    (["--kv", "100", "--pole-pairs", "0"], "--pole-pairs"),
    (["--kv", "100", "--bus-voltage", "-1"], "--bus-voltage"),
    (["--kt", "0.1", "--kt-frame", "amps"], "--kt-frame"),
    (["--winding", "star", "--kv", "100"], "--winding"),
])
def test_bad_values_exit_2_naming_the_argument(capsys, argv, argument):
    with pytest.raises(SystemExit) as exc:
        cli.main(["convert", *argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {argument}" in err


@pytest.mark.parametrize("argv,argument", [
    (["--kt", "0.1"], "--kt-frame"),
    (["--kt-frame", "phase_peak", "--kv", "100"], "--kt-frame"),
    (["--kb-frame", "ll_peak", "--kv", "100"], "--kb-frame"),
    (["--kv-frame", "ll_rms", "--kt", "1", "--kt-frame", "bus"], "--kv-frame"),
    ([], "nothing to convert"),
    (["--kv", "100", "--yaml", "x.yaml"], "--yaml"),
])
def test_inconsistent_arguments_exit_2(capsys, argv, argument):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert argument in err and "error" in err


def test_range_and_unit_in_message(capsys):
    with pytest.raises(SystemExit):
        cli.main(["convert", "--kv", "-3"])
    err = capsys.readouterr().err
    assert "> 0" in err and "rpm/V" in err


def test_delta_drive_frame_is_printed_and_accepted(capsys):
    """Issue #7: on a delta motor an amplitude-invariant drive reports K_t = K_t^q/sqrt(2) (per line-current
    amplitude), sqrt(3) below the per-phase-amplitude value; a drive's K_t entered with that frame gives back
    the same K_t^q."""
    code, out, _ = run(capsys, "--winding", "delta", "--kv", "100", "--terminal-resistance", "0.186",
                       "--terminal-inductance", "1.2e-4", "--bus-voltage", "24")
    assert code == 0
    phase = re.search(r"phase-current amplitude \(Maxon/TQ datasheet style\) = ([0-9.]+)", out)
    drive = re.search(r"drive_amplitude_invariant\) = ([0-9.]+)", out)
    assert float(phase.group(1)) == pytest.approx(0.143239, rel=1e-5)
    assert float(drive.group(1)) == pytest.approx(0.0826993, rel=1e-5)
    assert "= amplitude-invariant drives" not in out          # the old, wrong label
    code, out2, _ = run(capsys, "--winding", "delta", "--kt", "0.0826993", "--kt-frame", "drive_amplitude_invariant")
    assert code == 0 and "motor.torque_constant_q = 0.11695" in out2
