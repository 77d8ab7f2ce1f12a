"""Issue #24, symptom 7 and the fresh set's drive extras: a voltage-side effect is judged on the voltage, and a
drive the emulation cannot reproduce is a stated model limit, not a drive-form finding.

(a) A winding resistance under a speed loop moves the drive's q voltage; it reaches the speed only through the
drive's current loop. Where the emulated drive does not reproduce that loop, the simulated speed is no judge of it:
the finding is judged on its own channel (``Effect.channel``, ``Effect.through_drive``).
(b) A drive-form change is a finding only when the form REPRODUCES the recorded drive (its simulated current error
within 1.5 x the in-band current noise, or at most half the file's form's excess over it); else the least bad form is
a model limit (``model_limits`` in the JSON, a "Model limits" line in report.md, "model limit: ..." in the verdict).
A base-model headline needs every value it names (leave one out, like a finding).
Generated data: test/drive_emulation_generators.py (a kernel drive whose current loop is tuned otherwise than the
file says, behind a speed loop).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import drive_emulation_generators as D  # noqa: E402

from bldc_actuator.diagnosis import drive_feedforward as dff  # noqa: E402
from bldc_actuator.diagnosis.effects import registry  # noqa: E402
from bldc_actuator.diagnosis.judge import simulated  # noqa: E402


def test_the_channel_a_finding_is_judged_on_comes_from_its_equations():
    r = registry.get("resistance_error")
    assert r.channel == "voltage" and r.through_drive
    v = registry.get("viscous_friction")
    assert v.channel == "velocity" and not v.through_drive


def test_a_form_that_is_only_the_least_bad_does_not_reproduce_the_drive():
    # the fresh set's fr_null_geared_steps figures: 0.262 -> 0.206 A, the in-band floor taken as 0.027 A: most of
    # the mismatch is left, so the better form is not the drive, and no form comes within 1.5 x the floor
    assert not dff.explains_drive(0.206, 0.262, 0.027)
    assert not dff.within_floor(0.206, 0.027)
    # a form that is the drive removes most of the file's form's excess (tp_drive_ff-like figures)
    assert dff.explains_drive(0.013, 0.0198, 0.0138)
    assert dff.explains_drive(0.02, 0.05, 0.0138)
    assert not dff.explains_drive(0.05, 0.05, 0.0138)       # the file's form is not another form
    assert dff.explains_drive(0.236, 0.312, 0.200)          # within the floor (a kernel drive under current steps)
    # the simulated current low-passed as recorded, the floor's noise scale robust (steps are signal): the kernel
    # replaying its own drive 0.98-1.04 x (builtin null_clamp_at_limit, steps: 0.0501 A on 0.0503), motulator's
    # drive with its own form 0.95 x; fr_saturation's least bad form 2.0 x, a drive without anti-windup 3.1 x
    assert dff.within_floor(0.0501, 0.0503) and dff.within_floor(0.0116, 0.0133)
    assert not dff.within_floor(0.0408, 0.0205) and not dff.within_floor(0.157, 0.051)
    assert dff.within_floor(1.0, float("nan"))              # no floor: nothing claimed


def _windows(rng, n, level, spread):
    return np.abs(level + spread * rng.standard_normal(n))


def test_a_channel_reached_only_through_an_unreproduced_loop_does_not_refuse():
    """The leave-one-out verdict of a voltage-side finding: the voltage error falls 7x; the speed gets worse by
    20 % of its error (beyond its window floor and the old 5 % tolerance). Judged with the speed: refused; with the
    speed not a judge (the loop not reproduced): confirmed, the speed's change still reported."""
    rng = np.random.default_rng(0)
    n = 40
    without = {"voltage": _windows(rng, n, 0.059, 0.004), "velocity": _windows(rng, n, 0.50, 0.01)}
    with_ = {"voltage": _windows(rng, n, 0.008, 0.001), "velocity": without["velocity"] * 1.2}
    signal = {"voltage": 2.0, "velocity": 20.0}
    old = simulated._verdict(without, with_, "voltage", "velocity", 2.0, 0.05, n, 0.1, signal)
    assert old["verdict"] == "worsens the simulated velocity"
    new = simulated._verdict(without, with_, "voltage", "velocity", 2.0, 0.05, n, 0.1, signal, other_judged=False)
    assert new["verdict"] == "confirmed" and new["other_channel_change"] > 0 and not new["other_channel_judged"]
    # a channel the simulation does not reproduce at all (error above half its recorded RMS) refuses nothing either
    lost = {"voltage": with_["voltage"], "velocity": without["velocity"] * 0 + 15.0}
    far = simulated._verdict(dict(without, velocity=without["velocity"] * 0 + 12.0), lost, "voltage", "velocity",
                             2.0, 0.05, n, 0.1, signal)
    assert far["verdict"] == "confirmed"


def _resistance_behind(rep, truth):
    assert "far off" not in rep.verdict
    assert dff.EFFECT not in rep.effects
    assert "resistance_error" in rep.effects, rep.verdict
    f = rep.finding("resistance_error")
    value, sd = f["parameters"]["phase_resistance"], f["uncertainty"]["phase_resistance"]
    assert abs(value - truth.motor.phase_resistance) < max(3 * sd, 0.05 * truth.motor.phase_resistance)
    lim = rep.to_dict()["model_limits"]
    assert all(x["effect"] == dff.EFFECT and "not reproduced" in x["message"] for x in lim)


@pytest.mark.slow
def test_resistance_behind_a_delay_compensated_drive_under_a_speed_loop():
    """R x1.3 behind the hand-written drive as motulator's runs (a d/q PI with feed-forward, its voltage applied one
    period after its sample and held in stator coordinates, the inverse Park advanced by 1.5 periods to compensate;
    the file says no computation delay), a speed loop around it: the resistance is named near its value, no
    drive-form finding is invented and the verdict has no "base model far off" headline."""
    from bldc_actuator.diagnosis.pipeline import diagnose

    sig, nominal, truth = D.resistance_case(1.3, delay_periods=1)
    _resistance_behind(diagnose(sig, nominal), truth)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="NOT DONE: the 1.5-period advance of a voltage applied at once turns the "
                   "logged voltage by p*omega*T against the winding's; the voltage equation has no form for it and "
                   "refuses R at the training gate (negative ΔBIC), before any simulation judges it")
def test_resistance_behind_an_over_compensated_drive_under_a_speed_loop():
    """The same drive with its voltage applied at once (no computation delay) but still advanced by 1.5 periods: a
    rotation of the applied voltage the kernel has no form for."""
    from bldc_actuator.diagnosis.pipeline import diagnose

    sig, nominal, truth = D.resistance_case(1.3)
    _resistance_behind(diagnose(sig, nominal), truth)


def test_a_model_limit_is_one_record_in_the_verdict_the_json_and_report_md(tmp_path):
    """The limit a drive-form identification states reaches every output from one record: the verdict's
    "model limit: ..." (kind unchanged: a limit is neither a finding nor a reason for "not decidable"), the JSON's
    ``model_limits`` and report.md's "Model limits" line."""
    from bldc_actuator.diagnosis.report.document import DiagnosisReport
    from bldc_actuator.diagnosis.results import decide

    lim = dff.EmulationLimit("current loop", "complex_vector without feed-forward", 0.206, 0.027, 59, "held-out")
    assert "leaves 0.206 A" in lim.message and "delay compensation" in lim.message
    rec = decide([], [], limits=[lim.short])
    assert rec.nothing_missing and rec.text().endswith("model limit: " + lim.short)
    rep = DiagnosisReport(channels=["current"], findings=[], rejected=[], windows=[], data_issues=[],
                          not_checkable=[], aliases=[], verdict_record=rec, model_limits=[lim.to_dict()])
    d = rep.to_dict()
    assert d["model_limits"][0]["message"] == lim.message and d["verdict_record"]["limits"] == [lim.short]
    md = rep.write_markdown(tmp_path, plots=False).read_text()
    assert "## Model limits" in md and lim.message in md


def test_the_floor_counts_the_sensor_not_the_steps():
    """The drive-form floor's noise scale: 0.03 A of white sensor noise on a current stepping 2-8 A every 0.25 s at
    1 kHz. The standard deviation above the low-pass counts the steps' above-band content (several times the noise),
    the robust scale the sensor within 15 % (0.0333 A here; 0.0296 A on the noise alone, where the standard
    deviation gives 0.0293 A)."""
    from types import SimpleNamespace

    from bldc_actuator.diagnosis.frame.equation_error import Decimator

    fs, n = 1000.0, 10000
    rng = np.random.default_rng(4)
    levels = rng.choice([-8.0, -6.0, -4.0, -2.0, 2.0, 4.0, 6.0, 8.0], n // 250)
    i = np.repeat(levels, 250) + 0.03 * rng.standard_normal(n)
    ctx = SimpleNamespace(sig={"i_q": i}, fs=fs, dec=Decimator(fs=fs, fc=100.0, q=2, segments=[(0, n)]))
    frac = 1.0 - 100.0 / 500.0
    assert simulated.current_noise_rms(ctx) * np.sqrt(frac) > 3 * 0.03 * np.sqrt(frac)
    assert abs(simulated.current_noise_rms_robust(ctx) - 0.03) < 0.15 * 0.03
