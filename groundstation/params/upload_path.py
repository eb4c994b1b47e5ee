"""The one way a parameter table reaches the device: design -> table -> gate -> upload.

    outcome = upload_design(loader, "profiles/controllers/relative_design2.toml")
    outcome.record            # the verified UploadRecord (history, journal)

`upload_design` reads a design (a file, or a ControllerDesign already loaded), builds
its table over the device's active one (so entries the design does not set keep what
runs), passes that very table through the upload gate (clearance.py: validated against
the design, or overridden with a recorded reason) and hands it to the ParameterLoader,
which sends, commits and verifies it.  `upload_table` does the same for a table that
was built or edited elsewhere (the window's parameter panel), with or without its
design.  `prepare` is the first half alone, with no device: the table and what the
validation says about it, for a preview or a refusal before anything is opened.

The Station's upload verbs (and through them the CLI, campaigns and the window's
Session) call these.  No Qt, no threads: a caller with a GUI runs them off its GUI
thread.  A refusal raises clearance.ValidationRefused (carrying the validation report);
a failed transfer raises the loader's UploadError.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Mapping

from ..core.dictionary import Dictionary
from .clearance import Clearance, ValidationRefused, clear_design, override_table
from .design_file import ControllerDesign, load_design, table_values
from .loop import ValidationReport, validate
from .upload import ParameterLoader, UploadRecord

Progress = Callable[[str, float], None]


@dataclass(frozen=True)
class PreparedTable:
    """A design's table and the validation of exactly that table (nothing sent)."""

    design: ControllerDesign
    values: dict[str, Any]
    report: ValidationReport


@dataclass(frozen=True)
class UploadOutcome:
    """A table verified on the device, and how it passed the gate."""

    record: UploadRecord                   # what the loader verified and kept in the history
    values: dict[str, Any]                 # the table that was sent
    clearance: Clearance                   # validated, or the override and its reason
    report: ValidationReport | None        # the validation of `values` (None: no design)
    source: str                            # the record's source, with any override noted


def design_of(design: ControllerDesign | str | Path) -> ControllerDesign:
    """A loaded design as it is, a file read (DesignError names the file and field)."""
    return design if isinstance(design, ControllerDesign) else load_design(design)


def source_of(design: ControllerDesign | str | Path) -> str:
    """How an upload names its design: the file as given, or the loaded design's file."""
    if isinstance(design, ControllerDesign):
        return str(design.path)
    return str(design)


def judged_on(design: ControllerDesign, testbed,
              warn: Callable[[str], None] | None = None) -> ControllerDesign:
    """The design as the gate must judge it: on the plant the session drives.  A design
    names the testbed it was made for; on another file of the same kind (an identified
    rig, the appendix's inertias) it is judged on that one, and `warn` is told; a
    design for another kind of rig is refused (ValidationRefused).  `testbed` None (the
    session was given none): the design's own is all there is."""
    own = design.testbed
    if testbed is None or own.text == testbed.text:
        return design
    if (own.configuration, own.setup) != (testbed.configuration, testbed.setup):
        raise ValidationRefused(f"{design.path.name} is a design for a {own.configuration} "
                                f"{own.setup} testbed; this session runs {testbed.path.name}, "
                                f"a {testbed.configuration} {testbed.setup} one")
    if warn is not None:
        warn(f"{design.path.name}: validated on this session's testbed {testbed.path.name} "
             f"(the design names {own.path.name})")
    return replace(design, testbed=testbed)


def prepare(design: ControllerDesign | str | Path, dictionary: Dictionary,
            base: Mapping[str, Any] | None = None) -> PreparedTable:
    """The design's table over `base` (a device's table; the defaults without one) and
    its validation.  No device is needed: a caller can refuse a design before opening
    one, or show what an upload would send."""
    d = design_of(design)
    values = table_values(d, base=base, dictionary=dictionary)
    return PreparedTable(d, values, validate(d, values, dictionary))


def upload_design(loader: ParameterLoader, design: ControllerDesign | str | Path, *,
                  source: str | None = None, accept_risk: str | None = None,
                  progress: Progress | None = None,
                  on_report: Callable[[ValidationReport], None] | None = None,
                  warn: Callable[[str], None] | None = None,
                  testbed=None) -> UploadOutcome:
    """Build the design's table over the device's active one and upload it through the
    gate (see upload_table).  `source` names it in the history (default: the file);
    `testbed`, the session's testbed when one was chosen (see judged_on)."""
    d = judged_on(design_of(design), testbed, warn)
    active = loader.read_active()
    values = table_values(d, base=active.values, dictionary=loader.d)
    return upload_table(loader, values, source or source_of(design), design=d,
                        accept_risk=accept_risk, progress=progress, on_report=on_report, warn=warn)


def upload_table(loader: ParameterLoader, values: Mapping[str, Any], source: str, *,
                 design: ControllerDesign | None = None, accept_risk: str | None = None,
                 progress: Progress | None = None,
                 on_report: Callable[[ValidationReport], None] | None = None,
                 warn: Callable[[str], None] | None = None) -> UploadOutcome:
    """Clear `values` at the gate and upload them, verified.

    With `design` the table is validated against it; a refused or marginal table goes
    only with `accept_risk`, the reason an engineer accepts it.  Without a design the
    closed loop cannot be checked, so the table goes only with `accept_risk`.  An
    override is written into the record's source and said to `warn` before anything is
    sent.  `on_report` receives the validation's report, passed or refused, before
    anything is sent.  Raises ValidationRefused when the gate refuses (nothing sent)."""
    report = None
    try:
        if design is not None:
            clearance, report = clear_design(design, values, loader.d, accept_risk)
        else:
            clearance = override_table(values, loader.d, accept_risk or "")
    except ValidationRefused as exc:
        if on_report is not None and exc.report is not None:
            on_report(exc.report)
        raise
    if on_report is not None and report is not None:
        on_report(report)
    if clearance.risk == "marginal":
        note = f"WARNING: uploading {source} with its margins accepted: {clearance.text()}"
        source += f" (margins accepted: {clearance.override_reason})"
    elif clearance.overridden:
        note = (f"WARNING: uploading {source} although it is not validated "
                f"({'; '.join(clearance.problems)}); reason given: {clearance.override_reason}")
        source += f" (not validated; accepted: {clearance.override_reason})"
    else:
        note = ""
    if note and warn is not None:
        warn(note)
    record = loader.upload(values, source=source, progress=progress, clearance=clearance)
    return UploadOutcome(record, dict(values), clearance, report, source)


__all__ = ["PreparedTable", "UploadOutcome", "design_of", "source_of", "prepare",
           "upload_design", "upload_table"]
