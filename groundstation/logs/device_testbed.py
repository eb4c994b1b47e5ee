"""The testbed a device names when it is asked who it is, kept in the log's journal.

A log recorded from `--device tcp://...` without `--testbed` holds no testbed file, yet
the analysis needs the testbed's constants (the motor resistances for the control
energy, the autocollimator's calibrated range, the set-up, the model).  The protocol
carries none of them: GET_INFO's free-text description is all a device says of its
configuration (SPEC §7).  The simulated testbed names its testbed file there -
"simulated testbed: NAME (FILE.toml)" - so the recorder asks, and when the file named
is one of the testbed files shipped here (profiles/testbeds/) and is of the testbed
named, it journals the file's text beside the description: the log then carries what
was true when it was made, as a log recorded with --testbed does.  A description that
names no shipped file is journaled alone, so the analysis can say what the device was
and that --testbed must supply the constants.
"""

from __future__ import annotations

import re
from typing import Any

from ..core.errors import GroundStationError
from ..plant.testbed import TESTBEDS_DIR, Testbed, TestbedConfigError, load_testbed

#: the journal kind of the record (schema.JOURNAL_KINDS), shared with the window's
#: account of the device (station/recording.device_record)
JOURNAL_KIND = "testbed"
#: a file name in parentheses, as the simulator puts it: "(relative_2dof.toml)"
_FILE_NAMED = re.compile(r"\(([^()/\\]+\.toml)\)")


def described_testbed(description: str) -> tuple[Testbed | None, str]:
    """(the shipped testbed file `description` names, "") or (None, why none is used)."""
    said = f"the device describes itself as \"{description}\""
    names = _FILE_NAMED.findall(description)
    if not names:
        return None, f"{said}, which names no testbed file"
    path = TESTBEDS_DIR / names[0]
    if not path.is_file():
        return None, (f"{said}: its testbed file {names[0]} is not one of the testbed files "
                      f"here ({TESTBEDS_DIR})")
    try:
        testbed = load_testbed(path)
    except TestbedConfigError as exc:
        return None, f"{said}: its testbed file {path} does not load here ({exc})"
    if testbed.name not in description:
        # the same file name with another testbed in it: not the file the device ran
        return None, (f"{said}: {path} here is of testbed '{testbed.name}', which the "
                      f"description does not name")
    return testbed, ""


def device_record(address: str, reply: dict[str, Any], testbed: Testbed | None) -> dict[str, Any]:
    """The journal record of a device's GET_INFO `reply`, with the testbed file it names
    (`testbed`, from described_testbed) when there is one."""
    fw = int(reply.get("firmware_version", 0))
    record: dict[str, Any] = {
        "device": "as described at connect", "address": address,
        "description": str(reply.get("description", "")),
        "firmware_version": f"{fw >> 16}.{(fw >> 8) & 0xFF}.{fw & 0xFF}"}
    if testbed is not None:
        record.update({"testbed_name": testbed.name, "testbed_file": str(testbed.path),
                       "testbed_text": testbed.text})
    return record


def recorded_device(reader) -> dict[str, Any] | None:
    """The newest device record (device_record) a log's journal holds, None if none
    (a log from before the recorder asked, or recorded with --testbed only)."""
    try:
        records = reader.journal(JOURNAL_KIND)
    except GroundStationError:
        return None                       # a log whose journal has no such kind
    for rec in reversed(records):
        if isinstance(rec.data, dict) and isinstance(rec.data.get("description"), str):
            return rec.data
    return None


__all__ = ["JOURNAL_KIND", "described_testbed", "device_record", "recorded_device"]
