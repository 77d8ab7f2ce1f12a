"""The typed record of one effect the diagnosis knows (issue #24): every facet the stages ask about, in one place.

Each effect is one module of this package holding ``EFFECT = Effect(...)``; :mod:`.registry` finds them. The
rest of the diagnosis knows an effect only through these facets (``effect.route is Route.THERMAL``,
``effect.angle_locked``...), never by comparing its name (``test/test_effect_literals.py``).

This package sits below the diagnosis's frame and stages: it imports nothing of the diagnosis, so every layer
may import it (``test/test_import_graph.py``).
"""

from __future__ import annotations

import enum
import functools
import math
import numbers
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping


class Route(enum.Enum):
    """Which search finds the effect."""

    LINEAR = "linear"                #: equation-error columns, forward selection (frame.selection)
    THERMAL = "thermal"              #: the thermal network's output error (frame.thermal)
    VOLTAGE_LIMIT = "voltage_limit"  #: the drive's fitted voltage limit (frame.voltage_limit, judged by replay)
    DRIVE_MODE = "drive_mode"        #: the drive's voltage-limit mode, by simulation only (judge.drive_modes)
    #: the drive's current-controller form and feed-forward, by the closed-loop replay before anything is judged
    #: (diagnosis.drive_feedforward); found by the pipeline itself, never a candidate a run is asked to test
    DRIVE_FORM = "drive_form"
    #: found by the torque-balance route (a measured torque and motion, no motor current: diagnosis.torque_balance)
    #: from the torque alone, never a candidate of the full route
    TORQUE_BALANCE = "torque_balance"
    #: a parameter of the robot's multibody model (a link or payload mass), found by the robot route
    #: (diagnosis.body) jointly over every joint from the MJCF's inverse dynamics, never a per-joint candidate
    BODY = "body"


class Story(enum.Enum):
    """The report's plain-word pointer from the located residual to the effect (frame.candidates.evidence)."""

    NONE = "none"
    VELOCITY = "velocity"                      #: the mechanical residual by speed (direction, low vs high speed)
    ANGLE_SPECTRUM = "angle_spectrum"          #: the mechanical residual's angle-order spectrum at the form's order
    CURRENT_TREND = "current_trend"            #: both equations' residuals by |current|
    TEMPERATURE_TREND = "temperature_trend"    #: both equations' residuals by temperature
    HEADROOM = "headroom"                      #: the electrical residual by voltage headroom |v|/v_max
    ELECTRICAL_CURRENT_TREND = "electrical_current_trend"  #: the electrical residual by |current|


class WriteBack(enum.Enum):
    """How an accepted finding enters the updated parameter file (frame.writeback, frame.thermal)."""

    FIELDS = "fields"                  #: each fitted parameter into its own field
    COGGING_SERIES = "cogging_series"  #: angle harmonics added onto the nominal series of the same order
    CURRENT_SENSORS = "current_sensors"  #: the current sensors' offsets/gains (or a cogging-like torque form)
    SETTING = "setting"                #: a categorical drive setting, written as found (``updated_fields``)
    NONE = "none"                      #: no simulator term


#: the simulated channel each model equation's effects show in first, the one a finding is judged on (voltage-side
#: effects: the drive's q voltage, since the current loop hides them in the current)
EQUATION_CHANNEL = {"mechanical": "velocity", "electrical": "voltage", "tracking": "current"}


@dataclass(frozen=True)
class Bounds:
    """The physically plausible range of a fitted parameter: a fit outside it explains noise, not physics, and is
    refused (:func:`..frame.candidates.implausible`). ``[lo, hi]`` in the parameter's unit, or in multiples of a
    nominal value (``nominal``: its dotted path in ActuatorParams, e.g. ``"motor.rotor_inertia"``)."""

    lo: float = -math.inf
    hi: float = math.inf
    nominal: str | None = None
    #: standard deviations the value may lie below ``lo`` (negative: it must clear ``lo`` by that many)
    lo_sd: float = 0.0
    #: the reason's words for the parameter (default: its name)
    label: str | None = None

    def violation(self, param: "Param", value, sd, params) -> str | None:
        """Why ``value`` (± ``sd``) is implausible under ``params`` (the nominal ActuatorParams), or None; a
        non-numeric value (a frame factor's name) is not bounded."""
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            return None
        v, s = float(value), float(sd or 0.0)
        slack = self.lo_sd * s if self.lo_sd else 0.0     # an unknown sd (NaN) fails a bound that counts it
        what = self.label or param.name
        unit = f" {param.unit}" if param.unit else ""
        if self.nominal is not None:
            nom = float(functools.reduce(getattr, self.nominal.split("."), params))
            lo, hi = self.lo * nom, self.hi * nom
            if lo - slack <= v <= hi:
                return None
            if math.isinf(self.lo) and v > hi:
                return f"{what} {v:.3g}{unit} above {self.hi:g} x nominal {nom:.3g} ({self.nominal})"
            return f"{what} {v:.3g} outside [{self.lo:g}, {self.hi:g}] x nominal {nom:.3g} ({self.nominal})"
        if self.lo - slack <= v <= self.hi:
            return None
        if self.lo_sd < 0 and not v >= self.lo - slack:
            return f"{what} {v:.3g} ± {s:.2g}{unit} not above {self.lo:g}"
        if math.isinf(self.hi):
            return f"{what} {v:.3g}{unit} < {self.lo:g}"
        return f"{what} {v:.3g}{unit} outside [{self.lo:g}, {self.hi:g}]"


@dataclass(frozen=True)
class Param:
    """One fitted parameter of an effect: its name in the report, SI unit, the parameter-file field it is
    written to (None: reported, not written), and its plausible range (a fit outside any is refused)."""

    name: str
    unit: str
    field: str | None = None
    bounds: tuple[Bounds, ...] = ()


@dataclass(frozen=True)
class Effect:
    """Everything the diagnosis knows about one effect apart from its regressor columns' code (which
    :mod:`..frame.candidates` attaches to the same name)."""

    name: str                                   #: identifier (the JSON report's ``effect``)
    rank: int                                   #: catalogue order (the order effects are tried and listed)
    description: str                            #: plain words: what physics this is
    equations: tuple[str, ...]                  #: "mechanical" | "electrical" | "tracking" | "thermal" | "torque_balance" | "body"
    needs: tuple[str, ...]                      #: recorded channels ("a|b" = either)
    simulated: bool                             #: has a simulator term (parameters in the schema)
    route: Route = Route.LINEAR
    #: other effect -> the experiment separating the two
    confusable: Mapping[str, str] = field(default_factory=dict)
    #: never fitted on its own; checked as an alias only behind these accepted effects (None: behind any sharing
    #: an equation)
    hides_behind: tuple[str, ...] | None = None
    params: tuple[Param, ...] = ()              #: the fitted parameters it reports (documentation, lookups)
    #: a parameter-change effect: (reported parameter, dotted path of its nominal value in ActuatorParams); its
    #: practical significance is the largest relative change among them
    nominal: tuple[tuple[str, str], ...] = ()
    #: its output-error fit is bounded to [1/10, 10] x nominal (a parameter at the bound is not identified)
    bounded_log_fit: bool = False
    story: Story = Story.NONE
    #: the report points at the time windows where the residual changes level (slow, temperature-driven effects)
    level_windows: bool = False
    #: locked to the rotor angle: an angle-synchronous held-out metric and order plot at its form's order
    angle_locked: bool = False
    #: the selection's words when no form of it stands out (in place of "no usable form for this data")
    no_form_reason: str | None = None
    #: shows only within a current-loop period: not checkable from a log slower than the loop (sampling artefact)
    within_loop_period: bool = False
    #: torque-side in the equations, drive-side in fact (the current sensors): the closed-loop replay judges it
    sensor_side: bool = False
    #: an external load: a recorded torque sensor supplies it in the replay, which therefore cannot show it
    external_load: bool = False
    writeback: WriteBack = WriteBack.FIELDS
    #: parameter-file flags switched on when it is written back
    enables: tuple[str, ...] = ()
    #: its ratio (``ratio_to_nominal``) scales every torque-side parameter fitted with it (the torque constant);
    #: not checkable where the current clips
    torque_scale: bool = False
    #: a heat source driven by motion: extra heat in the thermal model, its drag a share of the nominal friction
    motion_heat: bool = False
    #: the replay chooses between the simulator's forms of its term (the converter's sign form, drive.dead_time_sign)
    replay_form: bool = False
    #: its parameter that the rotor inertia gives up when written back (the load moved behind a spring)
    takes_from_rotor_inertia: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "confusable", MappingProxyType(dict(self.confusable)))

    @property
    def channel(self) -> str:
        """The simulated channel it is judged on: its first model equation's (:data:`EQUATION_CHANNEL`)."""
        eqs = [q for q in self.equations if q in EQUATION_CHANNEL]
        return EQUATION_CHANNEL[eqs[0]] if eqs else "velocity"

    @property
    def through_drive(self) -> bool:
        """Its term acts on the drive's side of the current loop (the voltage equation, the current's tracking): it
        reaches the speed only through the drive's current loop, so the simulated speed can refuse it only where
        the emulated drive reproduces that loop (a resistance under a speed loop hardly moves the speed)."""
        return self.channel != EQUATION_CHANNEL["mechanical"]

    @property
    def candidate(self) -> bool:
        """One of the candidate effects a run tests (``--effects``, frame.candidates.library); the drive's own form
        is identified by the pipeline in every run instead, a torque-balance finding by that route."""
        return self.route not in (Route.DRIVE_FORM, Route.TORQUE_BALANCE, Route.BODY)

    @property
    def special(self) -> bool:
        """Found by its own route (thermal, voltage limit, drive mode), not by the linear selection."""
        return self.route is not Route.LINEAR
