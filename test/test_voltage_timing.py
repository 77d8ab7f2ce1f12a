"""When this project's own logged voltage acts, declared by its writers and read by the diagnosis (issue #14).

The kernel holds each computed d/q voltage for one current-loop period ``T`` and reports the voltage it HOLDS at a
sample instant (``Actuator.outputs()["v_q"]``): with the sample on a tick and no computation delay that is the voltage
held over the period ending at the sample, acting centred ``T/2`` BEFORE it. Read at its sample, a free rotor's
voltage equation misses ``-K (T/2) dω/dt = -K² (T/2) / J i_q``: the resistance comes out ``K² T / (2 J)`` LOW
(default motor, K 0.091 N·m/A, J 6e-5 kg·m², T 100 µs: -0.0069 Ω of 0.17). The writers (``simulate``'s CSV, the
node's MCAP) now declare ``voltage_timing: applied`` and the offset; ``diagnose --voltage-timing auto`` uses it.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from bldc_actuator import profiles
from bldc_actuator import voltage_timing as vt
from bldc_actuator.diagnosis.frame import candidates as cands
from bldc_actuator.diagnosis.frame import equation_error as ee
from bldc_actuator.diagnosis.io.csvio import load_csv
from bldc_actuator.diagnosis.io.loaders import load_many
from bldc_actuator.diagnosis.io.mapping import LoadError, Mapping
from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams
from bldc_actuator.simulate import simulate_profile, write_csv

sys.path.insert(0, str(Path(__file__).parent))
from test_issue14_judge_helpers import closed_loop_recording, triangle_then_sines  # noqa: E402

P = ActuatorParams()
#: the simulate CSV's columns as canonical channels
SIM_MAP = Mapping.parse(["time=t [s]", "current=i_q [A]", "current_d=i_d [A]", "voltage_q=v_q [V]",
                         "voltage_d=v_d [V]", "position=theta [rad]", "velocity=omega [rad/s]",
                         "current_command=i_q_ref [A]"])


def held_interval_centres(params: ActuatorParams, log_ns: int, n_log: int = 12, fine_ns: int = 1000) -> np.ndarray:
    """[s] for each logged sample (a sine current command, the kernel stepped in ``fine_ns`` steps): the centre of
    the interval over which the kernel held the q voltage logged at that sample, minus the sample instant."""
    act = Actuator(params)
    t_end, v_end, log = [], [], []
    steps = log_ns // fine_ns
    for k in range(n_log * steps):
        if k % steps == 0:
            log.append((act.t_ns, act.state.v_q))
            act.set_current_command(1.0 + 3.0 * math.sin(2 * math.pi * 37 * act.t_ns * 1e-9))
        act.step_ns(fine_ns)
        t_end.append(act.t_ns)
        v_end.append(act.state.v_q)              # held over (t - fine_ns, t]
    t_end, v_end = np.array(t_end), np.array(v_end)
    out = []
    for t_k, v_k in log[3:]:
        hold = np.flatnonzero(v_end == v_k)
        assert len(hold), "the logged voltage is one the kernel held"
        run = np.split(hold, np.flatnonzero(np.diff(hold) > 1) + 1)
        near = min(run, key=lambda r: min(abs(t_end[r[0]] - fine_ns - t_k), abs(t_end[r[-1]] - t_k)))
        start, end = t_end[near[0]] - fine_ns, t_end[near[-1]]
        assert start < t_k <= end, "the sample falls in the hold of the value it logs"
        out.append(((start + end) / 2 - t_k) * 1e-9)
    return np.array(out)


@pytest.mark.parametrize("delay_us, expected_us", [(0, -50), (20, -30), (80, 30), (100, -50)])
def test_the_kernel_logs_the_voltage_it_holds_at_the_sample(delay_us, expected_us):
    """Measured on the kernel at 1 µs resolution (1 kHz log, 10 kHz loop): the logged q voltage is held for one loop
    period from the last switch before the sample (switches at m T + d; a delay of a whole period switches on the
    tick); its centre is where :func:`applied_offset` says, for every sample."""
    p = P.replace(**{"drive.current_loop_delay": delay_us * 1e-6})
    centres = held_interval_centres(p, 1_000_000)
    assert np.allclose(centres, expected_us * 1e-6, atol=1e-9)
    assert vt.applied_offset(1_000_000, 100_000, delay_us * 1000) == pytest.approx(expected_us * 1e-6, abs=1e-12)


def test_a_log_between_ticks_holds_the_voltage_at_every_phase():
    """A log period of 2.5 loop periods samples on a tick and half-way between (centres -50 and 0 µs): the declared
    offset is their mean."""
    centres = held_interval_centres(P, 250_000, n_log=21)     # 18 samples kept: 9 of each phase
    assert sorted(set(np.round(centres * 1e6, 6))) == [-50.0, 0.0]
    assert vt.applied_offset(250_000, 100_000, 0) == pytest.approx(float(np.mean(centres)), abs=1e-12)


def _resistance(sig, params=P, timing="auto") -> tuple[float, float, ee.Context]:
    """R [ohm] and its sd by the search's resistance column (nuisance columns included)."""
    ctx = ee.prepare([(sig, False)], params, holdout=0.3, voltage_timing=timing)
    cols = {k: ctx.column(k, b) for k, b in ctx.nuisance.items()}
    cols["r_err"] = ctx.column("r_err", cands.col_r_err)
    fit = ee.fit_columns(ctx, cols, list(cols), {"electrical": 1.0}, blocks=["electrical"])
    return params.motor.phase_resistance + float(fit.beta[-1]), float(math.sqrt(fit.cov[-1, -1])), ctx


def _simulated_csv(path: Path, params=P, seed: int = 0) -> Path:
    """``bldc-actuator simulate``'s CSV of a free rotor under a multisine current command (8 s, 1 kHz)."""
    rng = np.random.default_rng(seed)
    t = np.arange(8000) / 1000.0
    f = np.array([0.7, 1.9, 3.1, 5.3, 8.9])
    cmd = (0.8 * np.sin(2 * np.pi * f[None] * t[:, None] + rng.uniform(0, 2 * np.pi, len(f)))).sum(axis=1)
    write_csv(simulate_profile(params, profiles.Profile(t, cmd, "current"), rate=1000.0), path)
    return path


def _noisy(sig, seed: int):
    rng = np.random.default_rng(seed)
    n = len(sig.time)
    for ch, sd in (("current", 0.03), ("current_d", 0.03), ("voltage_q", 0.02), ("voltage_d", 0.02)):
        sig.channels[ch] = sig.channels[ch] + sd * rng.standard_normal(n)
    return sig


def test_the_simulate_csv_declares_its_timing_and_round_trips(tmp_path):
    """The CSV writer's comment lines come back from the loader as the kernel's convention and offset (-T/2; with a
    20 µs computation delay -30 µs); a second file of another timing is refused when loaded together, and a malformed
    declaration is an error naming the key."""
    a = _simulated_csv(tmp_path / "a.csv")
    assert a.read_text().startswith("# voltage_timing: applied\n# voltage_acts_after_sample_s: -5e-05\n")
    sig = load_csv(a, mapping=SIM_MAP, only_mapped=True)
    assert sig.meta["voltage_timing"] == vt.VoltageTiming("applied", -5e-5, "a.csv comment lines")
    b = _simulated_csv(tmp_path / "b.csv", P.replace(**{"drive.current_loop_delay": 2e-5}))
    assert load_csv(b, mapping=SIM_MAP, only_mapped=True).meta["voltage_timing"].acts_after_sample_s == \
        pytest.approx(-3e-5)
    c = tmp_path / "c.csv"
    c.write_text("# voltage_timing: applied\ntime,current,voltage_q\n0,1,2\n0.001,1,2\n")
    d = tmp_path / "d.csv"
    d.write_text("# voltage_timing: sample\ntime,current,voltage_q\n0,1,2\n0.001,1,2\n")
    assert load_many([c, c]).meta["voltage_timing"].convention == "applied"
    with pytest.raises(LoadError, match="different voltage timings"):
        load_many([c, d])
    c.write_text("# voltage_timing: late\ntime,current,voltage_q\n0,1,2\n0.001,1,2\n")
    with pytest.raises(LoadError, match="voltage_timing"):
        load_csv(c)


def test_the_kernels_own_csv_gives_the_true_resistance_with_its_declared_timing(tmp_path):
    """The simulate CSV (noise added after loading), loaded and fitted as the search fits R: with the file's
    declaration R is within 3 sd of the true 0.17 Ω; without it (the same data, nothing declared) it comes out
    K² T / (2 J) = 0.0069 Ω low within 20 %: the bias the declaration removes (before it: 0.1632 for 0.17)."""
    path = _simulated_csv(tmp_path / "run.csv")
    R, sd, ctx = _resistance(_noisy(load_csv(path, mapping=SIM_MAP, only_mapped=True), 1))
    assert float(ctx.sig["voltage_alignment"]) == pytest.approx(-5e-5)
    assert abs(R - 0.17) < 3 * sd and sd < 0.002, (R, sd)
    bare = _noisy(load_csv(path, mapping=SIM_MAP, only_mapped=True), 1)
    bare.meta["voltage_timing"] = None
    R0, sd0, ctx0 = _resistance(bare)
    m = P.motor
    bias = -m.torque_constant_q ** 2 * 0.5e-4 / m.rotor_inertia
    assert "voltage_alignment" not in ctx0.sig
    assert R0 - 0.17 == pytest.approx(bias, rel=0.2) and abs(R0 - 0.17) > 8 * sd0, (R0, sd0)
    # told on the command line instead, the same value (the offset from the nominal loop rate and delay)
    R1, _, _ = _resistance(bare, timing="applied")
    assert R1 == pytest.approx(R, abs=0.05 * sd)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_kernels_closed_loop_recording_gives_the_true_resistance_when_declared(seed):
    """The tests' closed-loop joint (PD at 1 kHz around the kernel, 0.03 A / 0.02 V log noise), declaring the
    kernel's timing as the project's writers do: R within 2 sd of 0.17 Ω (sd 0.001); undeclared 0.1624 / 0.1641."""
    sig = closed_loop_recording(P, P, triangle_then_sines, duration=16.0, seed=seed)
    assert sig.meta["voltage_timing"] == vt.VoltageTiming("applied", -5e-5, "closed_loop_recording")
    R, sd, ctx = _resistance(sig)
    sig.meta["voltage_timing"] = None
    R0, sd0, _ = _resistance(sig)
    assert ctx.voltage_convention == "applied"
    assert any("declared by the recording" in n for n in ctx.notes)
    assert abs(R - 0.17) < 2 * sd, (R, sd)
    assert 0.17 - R0 > 4 * sd0, (R0, sd0)


def test_a_given_timing_overrides_the_declared_one_and_says_so():
    sig = closed_loop_recording(P, P, triangle_then_sines, duration=4.0, seed=2)
    sig.meta["voltage_timing"] = vt.VoltageTiming("applied", -5e-5, "test")
    ctx = ee.prepare([(sig, False)], P, voltage_timing="sample")
    assert "voltage_alignment" not in ctx.sig
    assert any("overrides it" in n for n in ctx.notes)
    with pytest.raises(ValueError, match="voltage_timing"):
        vt.VoltageTiming("later", None)


def test_the_node_recorder_metadata_round_trips(tmp_path):
    """An MCAP with the node's layout and the node's declaration (per joint where joints differ) loads with it."""
    pytest.importorskip("rclpy", reason="rclpy not importable: cannot serialise ROS messages")
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension
    from sensor_msgs.msg import JointState

    from bldc_actuator.diagnosis.io.mcapio import load_mcap
    from bldc_actuator.recording import McapRecorder

    meta = {"node": "/a", **vt.kernel_declaration(P, 1e-3)}
    meta.update({f"{k}.knee": v for k, v in vt.kernel_declaration(
        P.replace(**{"drive.current_loop_delay": 2e-5}), 1e-3).items()})
    path = tmp_path / "run.mcap"
    with McapRecorder(path, parameters=P.to_flat(), metadata=meta) as rec:
        q = Float64MultiArray()
        fields = ("i_q", "i_d", "i_q_ref", "v_q", "v_d", "v_limit_q", "bus_voltage", "v_magnitude_q", "omega")
        q.layout.dim = [MultiArrayDimension(label=",".join(fields), size=len(fields), stride=len(fields))]
        for k in range(50):
            j = JointState(name=["joint"], position=[0.001 * k], velocity=[1.0], effort=[0.0])
            q.data = [1.0, 0.0, 1.0, 2.0, 0.0, 16.0, 24.0, 2.0, 1.0]
            rec.write("/joint_states", j, k * 1_000_000)
            rec.write("/bldc_actuator/q_axis_state", q, k * 1_000_000)
    sig = load_mcap(path)
    assert sig.meta["voltage_timing"].convention == "applied"
    assert sig.meta["voltage_timing"].acts_after_sample_s == pytest.approx(-5e-5)
    assert any("declares its voltage timing" in n for n in sig.meta["notes"])
    from bldc_actuator.diagnosis.io.mcapio import declared_voltage_timing
    rec_meta = [("bldc_actuator", meta)]
    assert declared_voltage_timing(rec_meta, "knee", path).acts_after_sample_s == pytest.approx(-3e-5)


def test_the_command_line_offers_every_timing_the_equation_knows():
    from bldc_actuator.cli import build_parser

    parser = build_parser()
    for timing in ee.VOLTAGE_TIMINGS:
        args = parser.parse_args(["diagnose", "run.csv", "--params", "defaults", "--voltage-timing", timing])
        assert args.voltage_timing == timing
    assert set(ee.VOLTAGE_TIMINGS) == {"auto", "applied", "command", "sample"}
