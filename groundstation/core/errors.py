"""Exceptions a user can cause, each with a message that says what and where.

Every error the ground station raises on purpose derives from GroundStationError, so a
front end (CLI, GUI, campaign runner) can show the message and keep running.
"""

from __future__ import annotations


class GroundStationError(Exception):
    """Base of all errors the ground station raises on purpose."""


# --- protocol dictionary -------------------------------------------------------------
class DictionaryError(GroundStationError):
    """A protocol TOML file is malformed or inconsistent (the message names file and key)."""


# --- decoding --------------------------------------------------------------------------
class DecodeError(GroundStationError):
    """A frame or payload could not be decoded."""


class ProtocolVersionError(DecodeError):
    """A frame carries a protocol major version this ground station does not speak."""


class UnknownPacketError(DecodeError):
    """A frame carries a packet id the dictionary does not define."""


class FrameLengthError(DecodeError):
    """A frame's length field does not fit its packet definition."""


class CrcError(DecodeError):
    """A frame's CRC does not match its contents."""


class EncodeError(GroundStationError):
    """Values cannot be encoded (wrong names, out of the wire type's range, ...)."""


# --- link ------------------------------------------------------------------------------
class LinkError(GroundStationError):
    """A transport could not be opened or was lost."""


class PortInUseError(LinkError):
    """A local port is already taken by another program."""


class LinkLostError(LinkError):
    """An open transport went away (cable pulled, serial adapter unplugged, peer closed)."""


class DeviceUnreachableError(LinkError):
    """The device could not be reached at all - refused, no answer, no such port - so
    nothing was sent to it.  Every command exits with status 2 for it (cli/exit_status)."""


# --- commands --------------------------------------------------------------------------
class CommandError(GroundStationError):
    """A command did not complete."""


class CommandArgumentError(CommandError):
    """A command's arguments are missing, unknown or out of range (nothing was sent)."""


class CommandTimeout(CommandError):
    """No answer from the device within the command's timeout."""


class CommandRejected(CommandError):
    """The device refused the command (REJECTED stage) with a reason code."""

    def __init__(self, message: str, reason: str = "", data: bytes = b""):
        super().__init__(message)
        self.reason = reason
        self.data = data


class CommandFailed(CommandError):
    """The device accepted the command but could not complete it (FAILED stage)."""

    def __init__(self, message: str, reason: str = ""):
        super().__init__(message)
        self.reason = reason


class DictionaryMismatchError(CommandRejected):
    """Ground and firmware protocol dictionaries differ (names both versions and hashes)."""


class NotConnectedError(CommandError):
    """A command needs an open session and there is none."""


class SessionEndedError(CommandRejected):
    """The device ended this host's session (another host took it over): the message says
    who took it and when."""
