"""Typed records the diagnosis hands between its last stages and its outputs: the :class:`Verdict` (one of three
kinds, rendered once and shown alike on stdout, in report.md and in the JSON) and the reasons a recording cannot
decide (:class:`Undecidable`).

The three verdicts:

* ``found`` — missing physics was found (each finding's evidence and held-out before/after in the report); a
  finding the simulated actuator cannot check is marked ``not checkable in simulation`` in the verdict itself;
* ``nothing missing`` — every candidate was tested, none passed the gates, the base model reproduces the data and
  no large structured residual is left;
* ``not decidable`` — the data cannot tell, with the reason (the base model's replay error N x the signal, a
  held-out set too short, a channel clipped, a structured residual no catalogued effect explains, ...) and what
  to do about it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

FOUND = "found"
NOTHING_MISSING = "nothing missing"
NOT_DECIDABLE = "not decidable"
KINDS = (FOUND, NOTHING_MISSING, NOT_DECIDABLE)


@dataclass
class Undecidable:
    """One reason the recording cannot decide whether physics is missing."""

    code: str          #: short key: base_replay_error | holdout_too_short | clipped | outside_catalogue | ...
    reason: str        #: plain words with numbers
    remedy: str = ""   #: what the user can do
    blocking: bool = False   #: True: not decidable even when something was found (the findings are suspected)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class Verdict:
    """The diagnosis' conclusion; :meth:`text` is the one line every output shows."""

    kind: str
    found: list[str] = field(default_factory=list)                    #: effects found
    not_checkable_in_simulation: list[str] = field(default_factory=list)   #: of those, not checkable in simulation
    undecidable: list[Undecidable] = field(default_factory=list)       #: why not decidable (or caveats of "found")
    prefix: str = ""                                                   #: e.g. "base model far off: ..."
    suffix: str = ""                                                   #: e.g. "not shown in simulation: ..."
    #: limits of the model the findings were judged with (the drive's current loop not reproduced by any form the
    #: simulator has): stated, never a finding, and no reason for "not decidable" on their own
    limits: list[str] = field(default_factory=list)

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"Verdict.kind: {self.kind!r} is not one of {', '.join(KINDS)}")

    def text(self) -> str:
        if self.kind == NOT_DECIDABLE and self.found:
            body = ("not decidable: " + "; ".join(u.reason for u in self.undecidable)
                    + "; suspected (not trusted while the above holds): " + ", ".join(self.found))
        elif self.kind == FOUND:
            names = [f"{e} (not checkable in simulation)" if e in self.not_checkable_in_simulation else e
                     for e in self.found]
            body = "found: missing physics: " + ", ".join(names)
            if self.undecidable:
                body += "; caveat: " + "; ".join(u.reason for u in self.undecidable)
        elif self.kind == NOTHING_MISSING:
            body = "nothing missing: no candidate effect passed both the ΔBIC and the held-out gate"
        else:
            body = "not decidable: " + "; ".join(u.reason for u in self.undecidable)
        if self.suffix:
            body += f"; {self.suffix}"
        if self.limits:
            body += "; model limit: " + "; ".join(self.limits)
        return f"{self.prefix}; {body}" if self.prefix else body

    @property
    def nothing_missing(self) -> bool:
        """True only for the kind "nothing missing" (not for a "not decidable" verdict without findings)."""
        return self.kind == NOTHING_MISSING

    def remedies(self) -> list[str]:
        return [u.remedy for u in self.undecidable if u.remedy]

    def to_dict(self) -> dict:
        return {"kind": self.kind, "text": self.text(), "nothing_missing": self.nothing_missing,
                "found": list(self.found),
                "not_checkable_in_simulation": list(self.not_checkable_in_simulation),
                "reasons": [u.to_dict() for u in self.undecidable], "limits": list(self.limits)}


def decide(found: list[str], undecidable: list[Undecidable], *, not_checkable_in_simulation=(),
           prefix: str = "", suffix: str = "", limits=()) -> Verdict:
    """``not decidable`` when a blocking reason holds (the findings are then only suspected), else ``found`` when
    something was found (the other reasons become caveats), else ``not decidable`` when there is a reason, else
    ``nothing missing``."""
    nc = [e for e in found if e in set(not_checkable_in_simulation)]
    if any(u.blocking for u in undecidable):
        kind = NOT_DECIDABLE
    else:
        kind = FOUND if found else (NOT_DECIDABLE if undecidable else NOTHING_MISSING)
    return Verdict(kind, list(found), nc, list(undecidable), prefix, suffix, list(limits))
