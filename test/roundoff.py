"""Comparing a trajectory with a stored one made on another machine, or by the other kernel path.

Exact equality holds only between two runs of the same code path on the same machine (same CPU, same libm, the
same numpy SIMD dispatch). A fixture written elsewhere differs in the last bits: libm's and numpy's sin/exp/sqrt
round differently per CPU, and numba (LLVM, libm) and the pure-Python path (math/numpy) differ too. Issue #25: a
fixture of the same numba/numpy versions on another x86_64 differed in 407 of 558 elements, by up to 3.9e-12 of
the value. Through the stable closed loops of these runs (1500 steps) such differences stay near 1e-12 of a
channel's range (the compiled and the pure-Python path agree to 1e-12 over 3 s: test_kernel_paths.py).

A change of the physics moves them far more: a 1 ppm change of the phase resistance moves the rigid reference
runs (test_transmission.py) by 1.5e-7 .. 1.5e-5 of each channel's range. ``ROUNDOFF_REL = 1e-9`` of the channel's
range lies between the two, ~250x above the observed rounding and >100x below a 1 ppm physics change.
"""

from __future__ import annotations

import numpy as np

#: tolerance as a fraction of each channel's range (max |value| over its samples); see the module docstring
ROUNDOFF_REL = 1e-9


def roundoff_deviation(now, then, axis: int | None = 0) -> tuple[float, tuple]:
    """The largest |now - then| as a fraction of its channel's scale, and where it sits.

    ``axis``: the sample axis; the scale of a channel is its max |then| along that axis (a channel crossing zero
    keeps a tolerance). ``axis=None``: each element is its own channel (e.g. energies of different size).
    """
    now, then = np.asarray(now, dtype=float), np.asarray(then, dtype=float)
    if now.shape != then.shape:
        raise AssertionError(f"shape {now.shape} != stored {then.shape}")
    if axis is None:
        scale = np.abs(then)
    else:
        scale = np.max(np.abs(then), axis=axis, keepdims=True)
    scale = np.where(scale > 0.0, scale, np.finfo(float).tiny)
    dev = np.abs(now - then) / scale
    dev = np.where(np.isnan(now) & np.isnan(then), 0.0, dev)     # NaN where both are NaN is equal
    dev = np.where(np.isnan(dev), np.inf, dev)                   # NaN on one side only is not
    if dev.size == 0:
        return 0.0, ()
    where = np.unravel_index(int(np.argmax(dev)), dev.shape)
    return float(dev[where]), tuple(int(i) for i in where)


def assert_matches_up_to_roundoff(now, then, *, axis: int | None = 0, rel: float = ROUNDOFF_REL,
                                  err_msg: str = "") -> None:
    """``now`` equals the stored ``then`` up to floating-point rounding: every element within ``rel`` of its
    channel's scale (see :func:`roundoff_deviation`)."""
    dev, where = roundoff_deviation(now, then, axis)
    if not dev <= rel:
        now_v = np.asarray(now, dtype=float)[where] if where else now
        then_v = np.asarray(then, dtype=float)[where] if where else then
        raise AssertionError(
            f"{err_msg}: differs by {dev:.3g} of its channel's scale at index {where} (now {now_v!r}, stored "
            f"{then_v!r}); rounding on another machine or kernel path stays below {rel:g}")
