"""An angle-locked ripple in a measured torque (cogging or torque ripple), from the torque alone.

Found by :mod:`..torque_balance` on logs with a torque sensor and motion but no motor current: the order per motor
revolution that stands out of its neighbouring orders in the torque's spectrum against the angle, its amplitude
and their uncertainties. Without the motor current the motor's own share is not separated, so nothing is written
back to the parameter file."""

from __future__ import annotations

from .record import Effect, Param, Route, WriteBack

EFFECT = Effect(
    name="angle_locked_ripple", rank=240,
    description="a torque ripple locked to the rotor angle in the measured torque (cogging or torque ripple; "
                "the motor's own share is not separated without its current)",
    equations=("torque_balance",), needs=("torque", "position"), simulated=False, route=Route.TORQUE_BALANCE,
    params=(Param("order", "per motor revolution"), Param("amplitude", "N*m"), Param("cos", "N*m"),
            Param("sin", "N*m")),
    writeback=WriteBack.NONE,
)
