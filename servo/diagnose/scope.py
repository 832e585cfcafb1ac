"""Recordings outside the diagnosis's domain: a verdict with its reason, not a refusal.

A recording that loads (numbers, a regular time base, the columns named) but that the
force balance cannot be fitted to gets the verdict ``out_of_scope`` in a full report
(``report.json``, ``report.html``), with what was measured as the reason: an output that
does not move (constant, or within its noise on most samples: a process in other units
than metres, or an arm that sticks), an input that does not change, too few usable rows
(too short a recording, reversals too frequent for any decimation the rows allow).  A
refusal (one error line, non-zero exit) is kept for what cannot be read or asked: a
file that does not load, an option out of range, a model file that is not one, a
baseline term the rows cannot determine, a recording too large for the memory.

The stages that measure these raise :class:`OutOfDomain` (an
:class:`~servo.identify.regressors.IdentificationError`, so a caller that only refuses
still refuses in one line); :func:`servo.diagnose.job.diagnose` turns it into an
:class:`Unscoped` diagnosis.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from servo.identify.regressors import IdentificationError
from servo.io.recording import Recording

#: the verdict of a recording outside the domain (:mod:`servo.diagnose.verdict`'s word)
VERDICT = "out_of_scope"


class OutOfDomain(IdentificationError):
    """Readable data the diagnosis's force balance cannot be fitted to; the message is
    the measured reason (module doc)."""


@dataclass
class Unscoped:
    """The diagnosis of a recording outside the domain: no rows, no model, the verdict
    ``out_of_scope`` and why (``reason``).  Holds the attributes a caller of
    :func:`~servo.diagnose.job.diagnose` reads of a :class:`~servo.diagnose.job.Diagnosis`
    that have a meaning without rows (no findings, nothing dropped)."""

    rec: Recording
    opt: object
    reason: str
    findings: list = field(default_factory=list)
    unconfirmed: list = field(default_factory=list)
    implausible: dict = field(default_factory=dict)
    not_testable: dict = field(default_factory=dict)
    sig: None = None
    frf: None = None

    @property
    def verdict(self) -> dict:
        return {"verdict": VERDICT, "text": self.reason, "baseline_checks": {}, "final_checks": {}}

    def _lines(self) -> list[str]:
        return [f"{self.rec.source}: {self.rec.n} samples; no model fitted", f"verdict: {VERDICT}: {self.reason}"]

    def __repr__(self) -> str:
        return "<Diagnosis " + "; ".join(self._lines()) + ">"

    def _repr_html_(self) -> str:
        """The summary lines as a report page's content (:mod:`servo.io.page`)."""
        from servo.io.page import Page

        return Page("Diagnosis", self._lines(), "bad").fragment()


__all__ = ["OutOfDomain", "Unscoped", "VERDICT"]
