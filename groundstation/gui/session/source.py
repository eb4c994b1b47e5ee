"""What the window's data come from, in words (no Qt here): the source bar and the
window title say it, whatever chooser the operator last touched.

The Session tells the source by `sig_source(kind, text)`: "live" (a device link:
the simulated testbed or a rig, `text` the address opened), "replay" (`text` the log's
path), "watch" (a read-only console, `text` the publisher's endpoint), "none".  A device
names its configuration in GET_INFO's free-text description (the simulated testbed
names its testbed file there), read once when the link comes up."""

from __future__ import annotations

from pathlib import Path

from ...core.contracts import CommandChannel
from ...core.errors import GroundStationError
from ...plant.testbed import DEFAULT_TESTBED


def device_description(client: CommandChannel) -> str:
    """What the device says it is (GET_INFO's description), "" when it will not say."""
    try:
        return str(client.command("GET_INFO").reply.get("description", "")).strip()
    except GroundStationError:
        return ""


def source_text(kind: str, text: str, *, simulated: bool = False, testbed: str | None = None,
                description: str = "", watched_device: str = "") -> str:
    """The source in a few words: the simulator's testbed file only when the link is the
    simulator's; a rig's address and what it says it is; the replayed file's name; the
    watched publisher's endpoint and the device it watches (once its hello told)."""
    if kind == "live" and simulated:
        name = Path(testbed).name if testbed else DEFAULT_TESTBED.name
        return f"Simulated testbed: {name}"
    if kind == "live":
        return f"Rig {text}" + (f" - {description}" if description else "")
    if kind == "replay":
        return f"Replay of {Path(text).name}"
    if kind == "watch":
        return (f"Read-only console watching {text}"
                + (f" (device {watched_device})" if watched_device else ""))
    return "Not connected"


__all__ = ["device_description", "source_text"]
