"""The upload gate: a parameter table reaches the device only with a `Clearance`.

A closed-loop table that the testbed's model says is unstable, saturating or badly
discretised must not be sent because a caller forgot to validate it.  So the check is
not the caller's job: `ParameterLoader.upload` refuses any table that does not come with
a Clearance for exactly its bytes (its CRC-32), and a Clearance is made only here:

* `clear_design(design, values, dictionary)` runs `validate` on the very table that
  will be sent and clears it when the validation passes;
* with `accept_risk="why"`, a table the validation refuses is cleared as an *override*:
  the reason and the validation's problems travel with the upload into the parameter
  history and the recording's journal, so the log says who sent what against advice;
* `override_table(values, dictionary, reason)` clears a table that has no design to be
  checked against (a gain edited by hand in the GUI); it is an override too, recorded
  the same way.

Range and shape problems of the table itself (ptable.problems) are never overridable:
the loader checks them again whatever the clearance says.  Rolling back to a table
that was active before is not an upload of a new table and needs no clearance.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..core.dictionary import Dictionary
from ..core.errors import GroundStationError
from . import table as ptable

#: only this module makes Clearances: each carries a seal over what it clears, keyed
#: with a secret of this program run, so neither a hand-made one nor a copy with another
#: table's CRC (dataclasses.replace) passes Clearance.__post_init__
_KEY = secrets.token_bytes(32)


def _seal(table_crc: int, design: str, override_reason: str, problems: tuple[str, ...]) -> str:
    text = "\x1f".join([f"{table_crc:08x}", design, override_reason, *problems])
    return hmac.new(_KEY, text.encode("utf-8"), hashlib.sha256).hexdigest()

#: the validation problem recorded for a table cleared without a design
NO_DESIGN = "no design given: the closed loop was not checked"


class ValidationRefused(GroundStationError):
    """Validation refused the table and no reason to send it anyway was given."""

    def __init__(self, message: str, report=None):
        super().__init__(message)
        self.report = report


@dataclass(frozen=True)
class Clearance:
    """Permission to upload one table (by CRC): validated, or overridden with a reason."""

    table_crc: int
    design: str                                   # design name and file, or "" for none
    override_reason: str = ""                     # why it is sent although not validated
    problems: tuple[str, ...] = ()                # what the validation said (override only)
    seal: str = field(default="", repr=False, compare=False)

    def __post_init__(self) -> None:
        expected = _seal(self.table_crc, self.design, self.override_reason, tuple(self.problems))
        if not hmac.compare_digest(self.seal, expected):
            raise TypeError("a Clearance is issued by clear_design() or override_table() "
                            "(groundstation.params.clearance), never constructed by hand")

    @property
    def overridden(self) -> bool:
        return bool(self.override_reason)

    def covers(self, dictionary: Dictionary, values: Mapping[str, Any]) -> bool:
        return ptable.table_crc(ptable.pack(dictionary, values)) == self.table_crc

    def record(self) -> dict[str, Any]:
        """What the history and the log keep about the gate."""
        return {"validated": not self.overridden, "override_reason": self.override_reason,
                "accepted_risk": self.risk, "validation_problems": list(self.problems),
                "design": self.design}

    @property
    def risk(self) -> str:
        """What was accepted: "" (validated), "marginal" (a stable loop with margins below
        the limits), or "refused" (validation refused it: unstable, or no design)."""
        if not self.overridden:
            return ""
        return "marginal" if all(p.startswith(MARGINAL) for p in self.problems) else "refused"

    def text(self) -> str:
        if not self.overridden:
            return f"validated ({self.design})" if self.design else "validated"
        if self.risk == "marginal":
            return (f"stable, margins accepted ({'; '.join(p[len(MARGINAL):] for p in self.problems)}): "
                    f"{self.override_reason}")
        return (f"NOT validated ({'; '.join(self.problems)}); sent on the override: "
                f"{self.override_reason}")


#: how an accepted margin shortfall is written among a Clearance's problems
MARGINAL = "stable but marginal: "


def _issue(table_crc: int, design: str, override_reason: str = "",
           problems: tuple[str, ...] = ()) -> Clearance:
    return Clearance(table_crc, design, override_reason, problems,
                     seal=_seal(table_crc, design, override_reason, problems))


def _crc(dictionary: Dictionary, values: Mapping[str, Any]) -> int:
    problems = ptable.problems(dictionary, values)
    if problems:            # never overridable: the table cannot even be packed faithfully
        raise ptable.ParameterError("table refused before sending: " + "; ".join(problems))
    return ptable.table_crc(ptable.pack(dictionary, values))


def clear_design(design, values: Mapping[str, Any], dictionary: Dictionary,
                 accept_risk: str | None = None):
    """(Clearance, ValidationReport) for the table `values` built from `design`.

    Raises ValidationRefused (carrying the report) when the validation refuses the table
    and `accept_risk` gives no reason to send it anyway."""
    from .loop import validate

    report = validate(design, values, dictionary)
    name = f"{design.name} ({design.path})" if getattr(design, "path", None) else design.name
    crc = _crc(dictionary, values)
    if report.ok:
        return _issue(crc, name), report
    risks = tuple(report.problems) + tuple(f"{MARGINAL}{m}" for m in report.marginal)
    reason = (accept_risk or "").strip()
    if not reason:
        if report.problems:
            raise ValidationRefused("refused by validation, nothing sent: " + "; ".join(report.problems),
                                    report)
        raise ValidationRefused("refused by validation, nothing sent: the closed loop is stable but "
                                "marginal (" + "; ".join(report.marginal) + "); to send it, accept "
                                "these margins with a reason (accept_risk), which is recorded",
                                report)
    return _issue(crc, name, reason, risks), report


def override_table(values: Mapping[str, Any], dictionary: Dictionary, reason: str,
                   problems: tuple[str, ...] = (NO_DESIGN,), design: str = "") -> Clearance:
    """Clear a table that was not (or could not be) validated, for a stated reason."""
    why = (reason or "").strip()
    if not why:
        raise ValidationRefused("a table sent without validation needs a reason (the override "
                                "is recorded in the parameter history and the log)")
    return _issue(_crc(dictionary, values), design, why, tuple(problems))
