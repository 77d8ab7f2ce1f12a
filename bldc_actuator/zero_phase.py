"""Zero-phase filtering of second-order sections with each filter's steady initial state made once (a signal
tool below the diagnosis: its frame and its effect modules use it).

The algorithm is :func:`scipy.signal.sosfiltfilt`'s with its defaults (odd extension over three times the
filter's taps, the sections started in the steady state of the first sample, forward then backward), so the
numbers are scipy's. scipy solves for that initial state (:func:`scipy.signal.sosfilt_zi`) on every call; the
diagnosis filters the same few filters thousands of times per recording (the compliance search: ~1800 calls, a
third of whose cost was that solve)."""

from __future__ import annotations

import numpy as np
import scipy.signal as sps

_ZI: dict[bytes, np.ndarray] = {}
_ZI_MAX = 256


def _zi(sos: np.ndarray) -> np.ndarray:
    key = sos.tobytes()
    zi = _ZI.get(key)
    if zi is None:
        if len(_ZI) >= _ZI_MAX:
            _ZI.clear()
        zi = _ZI[key] = sps.sosfilt_zi(sos)
    return zi


def sosfiltfilt(sos, x, axis: int = 0) -> np.ndarray:
    """:func:`scipy.signal.sosfiltfilt` ``(sos, x, axis)`` with its default padding."""
    sos = np.asarray(sos, float)
    x = np.asarray(x, float)
    n = sos.shape[0]
    ntaps = 2 * n + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    edge = 3 * ntaps
    if x.ndim == 0 or x.shape[axis] <= edge:
        return sps.sosfiltfilt(sos, x, axis=axis)        # scipy's own message for a record too short
    xm = np.moveaxis(x, axis, 0)
    ext = np.concatenate([2.0 * xm[0] - xm[edge:0:-1], xm, 2.0 * xm[-1] - xm[-2:-edge - 2:-1]])
    zi = _zi(sos).reshape((n, 2) + (1,) * (xm.ndim - 1))
    y, _ = sps.sosfilt(sos, ext, axis=0, zi=zi * ext[0])
    y, _ = sps.sosfilt(sos, y[::-1], axis=0, zi=zi * y[-1])
    return np.moveaxis(y[::-1][edge:-edge], 0, axis)
