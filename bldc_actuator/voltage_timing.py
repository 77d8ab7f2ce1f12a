"""When a logged q/d voltage acts on the winding, relative to the instant it is logged with (one module for the
writers that declare it and the diagnosis that reads it).

A drive's voltage is a staircase: held for one current-loop period ``T`` from each switch. A log pairs one value
of it with each sample of the current; the voltage equation needs the voltage ACTING at that sample. Conventions
(``diagnose --voltage-timing``, a recording's declared ``voltage_timing``):

- ``applied``: the voltage the inverter applies at the sample instant, i.e. the one held over the loop period the
  sample ends (or, with a computation delay ``0 < d < T``, the period it falls in). This project's kernel logs this
  (``Actuator.outputs()["v_q"]``, ``bldc-actuator simulate``'s CSV, the node's ``~/q_axis_state``, its MCAP):
  with the sample on a tick and ``d = 0`` (or ``d = T``) the logged value was switched on ``T`` before the sample and
  acts centred ``T/2`` BEFORE it; with ``0 < d < T`` centred ``d - T/2`` after it (:func:`applied_offset`; measured
  on the kernel at 1 µs resolution: -50, -30, 0, +30, -50 µs for d = 0, 20, 50, 80, 100 µs at T = 100 µs).
- ``command``: the voltage the drive computed from the current sample it is logged with; it acts the computation
  delay ``d`` + ``T/2`` after the sample (:func:`command_offset`; gym-electric-motor's and motulator's drives).
- ``sample``: the voltage acting at its sample (offset 0).

A writer declares its convention and the offset it implies for its own sample instants (:func:`declaration`):
in an MCAP's ``bldc_actuator`` metadata record, in a CSV's leading ``# key: value`` comment lines
(:func:`csv_comment_lines`). :func:`from_metadata` reads either back into a :class:`VoltageTiming`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: the conventions a recording can declare (``diagnose --voltage-timing`` adds ``auto``)
CONVENTIONS = ("applied", "command", "sample")
#: metadata keys (MCAP metadata record / CSV comment lines)
CONVENTION_KEY = "voltage_timing"
OFFSET_KEY = "voltage_acts_after_sample_s"


@dataclass(frozen=True)
class VoltageTiming:
    """A declared (or chosen) timing of a recording's logged voltage."""

    convention: str                     #: one of :data:`CONVENTIONS`
    acts_after_sample_s: float | None   #: [s] centre of its action after its sample (negative: before); None: unknown
    source: str = ""                    #: where it was declared, for the report

    def __post_init__(self):
        if self.convention not in CONVENTIONS:
            raise ValueError(f"{CONVENTION_KEY}: expected one of {', '.join(CONVENTIONS)}, got {self.convention!r}")
        off = self.acts_after_sample_s
        if off is not None and not (math.isfinite(off) and abs(off) < 0.1):
            raise ValueError(f"{OFFSET_KEY}: expected a finite offset within ±0.1 s, got {off!r}")


def applied_offset(sample_period_ns: int, loop_period_ns: int, delay_ns: int) -> float:
    """[s] mean centre, after its sample instant, of the voltage the kernel holds at samples taken every
    ``sample_period_ns`` from a tick (``t = 0``), for a loop of ``loop_period_ns`` with computation delay ``delay_ns``.

    The kernel switches the held voltage at ``m T + (d mod T)`` (``d = T`` switches on the tick, with the previous
    tick's voltage) and a sample taken at a switch instant logs the voltage held UP TO it (the switch is made when
    the kernel next steps). The held interval then starts at the last switch strictly before the sample and lasts
    ``T``: its centre is ``T/2 - (time since that switch)``. Averaged over the sample phases the samples take (one
    value when the sample period is a whole number of loop periods)."""
    T = int(loop_period_ns)
    P = int(sample_period_ns)
    if T <= 0 or P <= 0:
        raise ValueError(f"applied_offset: expected positive periods, got sample {P} ns, loop {T} ns")
    phase0 = int(delay_ns) % T
    n = T // math.gcd(P, T)          # sample phases repeat after n samples
    total = 0
    for k in range(n):
        since = (k * P - phase0) % T or T        # since the last switch strictly before the sample
        total += T - 2 * since                   # 2 x (centre - sample) [ns]
    return 0.5 * total / n * 1e-9


def command_offset(loop_period_s: float, delay_s: float) -> float:
    """[s] when a voltage computed from a sample acts after it: the computation delay + half the held period."""
    return float(delay_s) + 0.5 * float(loop_period_s)


def kernel_applied_offset(params, sample_period_s: float) -> float:
    """[s] :func:`applied_offset` of this project's kernel for samples every ``sample_period_s`` [s] from a tick, for
    the drive of ``params`` (:class:`~bldc_actuator.params.ActuatorParams`: its loop rate and computation delay, the
    delay clamped to one period as the kernel clamps it)."""
    d = params.drive
    loop_ns = int(round(1e9 / d.current_loop_rate))
    delay_ns = min(int(round(d.current_loop_delay * 1e9)), loop_ns)
    return applied_offset(int(round(sample_period_s * 1e9)), loop_ns, delay_ns)


def kernel_declaration(params, sample_period_s: float) -> dict[str, str]:
    """The metadata a writer of this project's kernel outputs (``applied``) declares for samples every
    ``sample_period_s`` [s] from a tick, for the drive of ``params`` (:func:`kernel_applied_offset`)."""
    return declaration(VoltageTiming("applied", kernel_applied_offset(params, sample_period_s)))


def declaration(timing: VoltageTiming) -> dict[str, str]:
    """``str -> str`` metadata pairs for ``timing``."""
    out = {CONVENTION_KEY: timing.convention}
    if timing.acts_after_sample_s is not None:
        out[OFFSET_KEY] = repr(float(timing.acts_after_sample_s))
    return out


def csv_comment_lines(meta: dict[str, str]) -> list[str]:
    """Leading CSV comment lines (``# key: value``) for metadata pairs; CSV readers told ``#`` starts a comment
    (this project's loader, ``pandas.read_csv(comment="#")``) skip them."""
    return [f"# {k}: {v}" for k, v in meta.items()]


def parse_csv_comments(lines) -> dict[str, str]:
    """``key: value`` pairs of the ``#`` comment lines BEFORE a CSV's header (other comments are kept as they are)."""
    out: dict[str, str] = {}
    for line in lines:
        s = line.strip()
        if not s:
            continue
        if not s.startswith("#"):
            break
        key, sep, value = s[1:].partition(":")
        if sep and key.strip():
            out[key.strip()] = value.strip()
    return out


def from_metadata(meta: dict, source: str) -> VoltageTiming | None:
    """The timing a recording's metadata declares (None when it declares none); a malformed declaration is an error
    naming the key."""
    conv = meta.get(CONVENTION_KEY)
    if conv is None:
        return None
    off = meta.get(OFFSET_KEY)
    if off is not None and off != "":
        try:
            off = float(off)
        except (TypeError, ValueError):
            raise ValueError(f"{source}: {OFFSET_KEY}: expected a number of seconds, got {off!r}") from None
    else:
        off = None
    try:
        return VoltageTiming(str(conv).strip(), off, source)
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}") from None
