"""Torque ripple locked to the electrical angle (current sensors, flux harmonics).

The catalogue record; its regressor columns, excitation test and parameter mapping are attached
in :mod:`..frame.candidates`."""

from __future__ import annotations

from .record import Effect, Story, WriteBack

EFFECT = Effect(
    name="electrical_angle_ripple", rank=60,
    description="torque ripple locked to the ELECTRICAL angle (current-sensor offset at order p, gain mismatch at "
                "2p, flux harmonics / dead time at 6p)",
    equations=("mechanical", "electrical"), needs=("current", "position"), simulated=False,
    confusable={"cogging_torque": "repeat at a different current: cogging does not scale with current"},
    # parameters named by form and order: <form>_order_<k>_amplitude / _phase (form: sensor_offset,
    # sensor_gain_ripple, flux_harmonic, torque_ripple)
    story=Story.ANGLE_SPECTRUM, angle_locked=True, sensor_side=True, writeback=WriteBack.CURRENT_SENSORS,
)
