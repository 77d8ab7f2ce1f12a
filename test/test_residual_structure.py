"""Issue #24: the structure check's reference is the residual's own noise, not a flat spectrum.

A correct model's residual holds the recording's noise through the derivatives the equation error takes: a
14-bit encoder's error on a 0.8 rad/s triangle is a 2086 Hz sawtooth, sampled at 1 kHz an 86 Hz line in the
acceleration (test_diagnosis_analysis::test_null_case_with_another_noise_seed...: 41 % of the held-out power in
78.7-99.2 Hz, "outside the catalogue" against a flat reference). An unlogged narrow-band load in that same noise
band must still be reported outside the catalogue.
"""

from __future__ import annotations

import math

import numpy as np

from bldc_actuator.diagnosis.io import cleaning
from bldc_actuator.diagnosis.pipeline import DiagnoseOptions, diagnose
from bldc_actuator.diagnosis.frame.quantization_noise import angle_step
from bldc_actuator.diagnosis.report import residual_structure as rs
from issue14_generators import NOMINAL, pd_run


def test_angle_step_reads_the_encoder_grid_and_nothing_from_a_continuous_angle():
    t = np.arange(5000) / 1000.0
    theta = 0.8 * t + 0.3 * np.sin(2 * math.pi * 1.3 * t)
    step = 2 * math.pi / 2 ** 14
    got = angle_step(np.round(theta / step) * step + 0.1 * step)
    assert got is not None
    assert abs(got[0] - step) < 1e-6 * step
    assert angle_step(theta) is None


def test_noise_shapes_rise_with_each_derivative_up_to_the_cut_off():
    """White noise through k central differences and the zero-phase low-pass: flat, ~f^2, ~f^4 below the cut-off."""
    from bldc_actuator.diagnosis.frame.equation_error import Decimator

    dec = Decimator(fs=1000.0, fc=100.0, q=2, segments=[(0, 10000)])
    f = np.array([5.0, 10.0, 20.0, 40.0])
    B = rs.noise_shapes(f, dec)
    assert np.allclose(B[0] / B[0][0], 1.0, rtol=0.01)
    for k in (1, 2):
        ratio = B[k][1:] / B[k][:-1]
        assert np.all(np.abs(ratio / 4.0 ** k - 1.0) < 0.25), (k, ratio)


def test_an_unlogged_narrow_band_load_in_the_noise_band_is_still_outside_the_catalogue():
    """45 Hz, 0.03 N*m at the output: inside the band where the differentiated angle's noise is largest."""
    sig = pd_run(NOMINAL, disturbance=lambda t: 0.03 * math.sin(2 * math.pi * 45.0 * t))
    rep = diagnose(cleaning.clean(sig, params=NOMINAL), NOMINAL, options=DiagnoseOptions(replay=False))
    big = [x for x in rep.residual_structure if x["large"]]
    assert big and big[0]["equation"] == "mechanical", rep.residual_structure
    lo, hi = big[0]["band_hz"]
    assert lo <= 45.0 <= hi
    assert big[0]["band_fraction"] > big[0]["band_noise_share"] + 0.25
    assert "physics outside the catalogue" in rep.verdict
