"""``bldc-actuator demo``: the node driven by the in-process profile player records, summarises and plots;
its physics numbers agree with the analytic steady state, and the MCAP re-simulates the run."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("rclpy")

from conftest import next_domain_id  # noqa: E402

from bldc_actuator.demo import demo_profile, run_demo, steady_speed_analytic  # noqa: E402
from bldc_actuator.model import Actuator  # noqa: E402
from bldc_actuator.params import ActuatorParams, load_preset  # noqa: E402

pytestmark = pytest.mark.ros


def test_analytic_steady_state_matches_the_model_offline():
    """The demo's reference value is itself checked against the model (no ROS): ak80_9 has friction."""
    for p in (ActuatorParams(), load_preset("ak80_9")):
        prof = demo_profile(p)
        tau_a, load = prof.meta["tau_a"], prof.meta["load"]
        i_ref = tau_a / (p.motor.torque_constant_q * p.gear.gear_ratio)
        for tau_load in (0.0, load):
            act = Actuator(p)
            act.set_torque_command(tau_a)
            act.set_load_torque(tau_load)
            act.step(0.5)
            st = act.state
            w, i_d = steady_speed_analytic(p, st.T_winding, st.T_housing, tau_load, i_ref)
            assert act.outputs()["velocity_out"] == pytest.approx(w, rel=1e-6)
            assert st.i_d == pytest.approx(i_d, rel=1e-4, abs=1e-7)


def test_demo_runs_records_and_agrees_with_physics(tmp_path, capsys):
    s = run_demo(None, tmp_path, domain_id=next_domain_id())
    out = capsys.readouterr().out
    assert "steady speed, no load" in out and "re-simulated from the MCAP alone" in out
    assert s["finalized"] and (tmp_path / "demo.mcap").stat().st_size > 0
    assert (tmp_path / "demo.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    topics = s["topics"]
    assert topics["/joint_states"][1] == 4001 and topics["/bldc_actuator/torque_command"][1] == 4000
    assert topics["/bldc_actuator/load_torque"][1] == 2
    for measured, analytic, _, saturated in (s["steady_no_load"], s["steady_load"]):
        assert saturated == 1.0 and measured == pytest.approx(analytic, rel=1e-5)
    assert s["steady_load"][0] < s["steady_no_load"][0]
    assert s["replay_max_dv"] == 0.0 and s["replay_states"] == 4001
    assert 25.0 < s["peak_T_winding"] < 30.0 and 0.0 < s["saturation_s"] < s["sim_s"]
    assert math.isfinite(s["real_time_factor"])


def test_demo_is_registered_as_a_subcommand():
    from bldc_actuator.cli import build_parser

    args = build_parser().parse_args(["demo", "--preset", "ak80_9", "--out", "x", "--no-plot"])
    assert args.command == "demo" and args.preset == "ak80_9" and args.func.__module__ == "bldc_actuator.demo"


def test_node_recording_diagnosed_closes_the_loop(tmp_path):
    """A node run whose motor has twice the preset's Coulomb friction, diagnosed against the preset: the
    recording alone names coulomb_friction, fits it near the truth, and the updated parameter file loads."""
    from bldc_actuator.diagnosis.io.cleaning import clean
    from bldc_actuator.diagnosis.io.loaders import load
    from bldc_actuator.diagnosis.pipeline import DiagnoseOptions, diagnose
    from bldc_actuator.params import dump_yaml, load_yaml

    nominal = load_preset("ak80_9")
    true_tau_c = 2.0 * nominal.effects.coulomb_friction
    truth = tmp_path / "truth.yaml"
    dump_yaml(nominal.replace(**{"effects.coulomb_friction": true_tau_c}), truth)
    run_demo(str(truth), tmp_path, domain_id=next_domain_id(), plot=False)
    sig = clean(load(tmp_path / "demo.mcap", params=nominal), params=nominal)
    # the node declares when its logged voltage acts (held over the loop period ending at each 1 kHz sample)
    timing = sig.meta["voltage_timing"]
    assert timing.convention == "applied"
    assert timing.acts_after_sample_s == pytest.approx(-0.5 / nominal.drive.current_loop_rate)
    rep = diagnose(sig, nominal, options=DiagnoseOptions(progress=False))
    assert [f["effect"] for f in rep.to_dict()["findings"]] == ["coulomb_friction"]
    fitted = rep.finding("coulomb_friction")["parameters"]["coulomb_friction"]
    assert fitted == pytest.approx(true_tau_c, rel=0.15)
    out = tmp_path / "fitted.yaml"
    rep.write_params(out)
    assert load_yaml(out).effects.coulomb_friction == pytest.approx(fitted)
