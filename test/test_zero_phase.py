"""The zero-phase filter (bldc_actuator/zero_phase.py) is scipy's sosfiltfilt with each filter's
initial state made once: the same numbers on any axis and shape, and scipy's own error for a record too short."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sps

from bldc_actuator.zero_phase import sosfiltfilt


@pytest.mark.parametrize("order,fc", [(4, 0.2), (2, 0.05), (4, 0.9)])
@pytest.mark.parametrize("shape,axis", [((500,), 0), ((300, 3), 0), ((3, 300), 1)])
def test_the_same_numbers_as_scipy(order, fc, shape, axis):
    sos = sps.butter(order, fc, output="sos")
    x = np.random.default_rng(order).standard_normal(shape)
    for _ in range(2):                                   # the second call uses the cached initial state
        np.testing.assert_allclose(sosfiltfilt(sos, x, axis=axis), sps.sosfiltfilt(sos, x, axis=axis),
                                   rtol=1e-12, atol=1e-14)


def test_a_record_too_short_is_scipys_error():
    with pytest.raises(ValueError):
        sosfiltfilt(sps.butter(4, 0.2, output="sos"), np.ones(10))
