"""Wiring a recorder to a live link: telemetry, commands with their stages, link health."""

from __future__ import annotations

from typing import Callable

from ..core.contracts import DeviceLink
from ..link.client import CommandResult
from .recorder import Recorder

#: commands too frequent and too dull for the journal (the link statistics cover them)
UNJOURNALED = {"HEARTBEAT"}


def command_record(result: CommandResult) -> dict:
    """What asdict(result) gives, without its deep copies (the values are numbers, text
    and bytes; the dicts and lists are new).  asdict took about 0.3 ms a command, the
    largest part of a profile upload's host time (hundreds of PROFILE_WRITE blocks)."""
    return {"name": result.name, "sequence": result.sequence,
            "arguments": dict(result.arguments),
            "stages": [dict(vars(stage)) for stage in result.stages],
            "reply": dict(result.reply), "retries": result.retries}


def attach_recorder(client: DeviceLink, recorder: Recorder) -> Callable[[], None]:
    """Subscribe the recorder to the client's telemetry, journal every command and every
    link state change, and the link statistics once a second (drops and CRC errors with
    their times).  Returns the function that undoes all of it: a long-lived link (the
    GUI's) sees many recordings, and each must leave nothing behind."""
    if recorder.link_stats is None:
        recorder.link_stats = client.stats.snapshot
    client.subscribe(recorder)

    def journal_command(result: CommandResult) -> None:
        if result.name in UNJOURNALED:
            return
        record = command_record(result)
        record["final_stage"] = result.final_stage
        t = result.stages[0].host_time if result.stages else None
        recorder.record("command", record, at=t)

    def journal_link(state: str, message: str) -> None:
        recorder.record("event", {"source": "link", "state": state, "message": message})

    client.add_command_listener(journal_command)
    client.add_link_listener(journal_link)

    def detach() -> None:
        client.unsubscribe(recorder)
        client.remove_command_listener(journal_command)
        client.remove_link_listener(journal_link)
    return detach


def recorder_from_args(dictionary, args, testbed, on_failure) -> Recorder:
    """The Recorder that the `record` command's options describe (args.folder, name,
    notes, rollover_mb, rollover_min) for `testbed` (a loaded Testbed or None): the same
    for a station's own link and for a watching console."""
    return Recorder(dictionary, args.folder, test_name=args.name, notes=args.notes,
                    testbed_text=testbed.text if testbed else "",
                    testbed_name=testbed.name if testbed else "",
                    testbed_path=str(testbed.path) if testbed else "",
                    rollover_bytes=int(args.rollover_mb * 1e6) if args.rollover_mb else None,
                    rollover_seconds=args.rollover_min * 60 if args.rollover_min else None,
                    on_failure=on_failure)
