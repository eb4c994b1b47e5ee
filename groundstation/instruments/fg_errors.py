"""What can go wrong with the generator, as exceptions the rest of the station catches:
the link (cannot open, no answer), the instrument (it reported an error), and a setting
refused before anything was sent (by the instrument's limits or by the testbed's)."""

from __future__ import annotations

from ..core.errors import GroundStationError, LinkError


class InstrumentError(GroundStationError):
    """The instrument reported an error for a command (its own text is in the message)."""

    def __init__(self, message: str, command: str = "", instrument_text: str = ""):
        super().__init__(message)
        self.command = command
        self.instrument_text = instrument_text


class InstrumentLinkError(LinkError):
    """The instrument cannot be opened or stopped answering (VISA I/O error, timeout)."""


class SettingRefusedError(GroundStationError):
    """A setting was refused before anything was sent (value, limit and its source named)."""

    def __init__(self, message: str, *, setting: str, value: float | str, limit: float | str,
                 source: str):
        super().__init__(message)
        self.setting = setting
        self.value = value
        self.limit = limit
        self.source = source

    @classmethod
    def on_channel(cls, channel: int, text: str, *, setting: str, value: float | str,
                   limit: float | str, source: str) -> "SettingRefusedError":
        """The refusal as every caller words it: channel, the reason, 'nothing was sent'."""
        return cls(f"channel {channel}: {text}; nothing was sent", setting=setting, value=value,
                   limit=limit, source=source)


class InstrumentLimitError(SettingRefusedError):
    """Beyond what the 4050-series generator accepts (its specification)."""


class SafetyLimitError(SettingRefusedError):
    """Beyond what the testbed tolerates (the testbed file's [limits])."""


__all__ = ["InstrumentError", "InstrumentLimitError", "InstrumentLinkError", "SafetyLimitError",
           "SettingRefusedError"]
