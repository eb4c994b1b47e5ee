"""Deliberate deviations from protocol/SPEC.md, for testing the conformance suite only.

`groundstation sim --deviate NAME` (repeatable) starts a simulated device that breaks
one rule of the SPEC on purpose, so a test can show that `groundstation conformance`
catches it in the right section.  With no deviation (the default) every hook below is
a no-op and the simulated device behaves exactly as before.

    crc-range       telemetry frames carry a CRC computed over the wrong bytes (§2.1)
    retry-twice     a resent command (same sequence and opcode) is executed again (§6.4)
    watchdog-x2     the watchdog waits twice the table's watchdog_timeout (§9.1)
    commit-no-crc   PARAM_COMMIT activates a table whatever its CRC (§11.1)
    profile-late    a profile plays one control period late (§11.2)
    foreign-host    a second host's CONNECT is accepted without take_over (§7)
    shared-history  one retry history for all connections: another host that repeats the
                    owner's CONNECT sequence gets the owner's answer and its token (§6.4)
"""

from __future__ import annotations

import zlib

#: each deviation and the SPEC section whose rule it breaks (where the suite must FAIL it);
#: the C reference device takes the same names
BREAKS = {"crc-range": "§2.1", "retry-twice": "§6.4", "watchdog-x2": "§9.1",
          "commit-no-crc": "§11.1", "profile-late": "§11.2", "foreign-host": "§7",
          "shared-history": "§6.4"}
NAMES = tuple(BREAKS)

# telemetry packet ids (SPEC §1): the CRC deviation spares the command channel so the
# suite can still open a session and see the broken frames
_TELEMETRY_IDS = (0x01, 0x02, 0x03)


class Deviations:
    """The set of deviations a simulated device was started with (empty: conforming)."""

    def __init__(self, names=()):
        unknown = sorted(set(names) - set(NAMES))
        if unknown:
            raise ValueError(f"unknown deviation(s) {unknown}; known: {', '.join(NAMES)}")
        self.names = frozenset(names)

    def __bool__(self) -> bool:
        return bool(self.names)

    # ---- the hooks, read by sim/firmware.py and sim/device.py
    @property
    def replays_execute(self) -> bool:
        return "retry-twice" in self.names

    @property
    def watchdog_factor(self) -> float:
        return 2.0 if "watchdog-x2" in self.names else 1.0

    @property
    def commit_checks_crc(self) -> bool:
        return "commit-no-crc" not in self.names

    @property
    def profile_start_position(self) -> float:
        # the engine plays sample `pos` and reports index pos + 1: starting at -1 leaves
        # the first period without an index, every sample one period late
        return -1.0 if "profile-late" in self.names else 0.0

    @property
    def history_per_connection(self) -> bool:
        return "shared-history" not in self.names

    @property
    def connect_ignores_owner(self) -> bool:
        return "foreign-host" in self.names

    def outgoing(self, frames):
        """Telemetry frames (a list, or a FrameRun) as this device sends them: as given,
        or a list of the changed frames."""
        if "crc-range" not in self.names:
            return frames
        return [_crc_over_wrong_range(f) for f in frames]


def _crc_over_wrong_range(frame: bytes) -> bytes:
    """The CRC computed from the version byte on, leaving out the sync word: a classic
    slip, and one that a receiver following §2.1 must count as a CRC error."""
    if len(frame) < 18 or frame[3] not in _TELEMETRY_IDS:
        return frame
    body = frame[:-4]
    return body + zlib.crc32(body[2:]).to_bytes(4, "little")


NONE = Deviations()
