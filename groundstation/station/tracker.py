"""The newest device state a session needs between commands, kept from HIGH_RATE.

A subscriber: the receiver thread writes, the session's thread reads single fields
(each a plain attribute assignment, so a reader never sees a torn value)."""

from __future__ import annotations


class DeviceStateTracker:
    """mode, armed, fault, profile_active, profile_index and tick of the last HIGH_RATE;
    the active parameter table's version and CRC from the last HOUSEKEEPING (None until
    one came)."""

    def __init__(self) -> None:
        self.mode = 0
        self.armed = False
        self.fault = False
        self.profile_active = False
        self.profile_index = 0
        self.tick = -1
        #: (param_table_version, param_table_crc) of the last HOUSEKEEPING, one tuple
        #: assigned at once so a reader never pairs one report's version with another's CRC
        self.active_table: tuple[int, int] | None = None

    def __call__(self, block) -> None:
        if not len(block):
            return
        if block.name == "HOUSEKEEPING":
            self.active_table = (int(block["param_table_version"][-1]),
                                 int(block["param_table_crc"][-1]))
            return
        if block.name != "HIGH_RATE":
            return
        self.mode = int(block["mode"][-1])
        self.armed = bool(block["armed"][-1])
        self.fault = bool(block["fault"][-1])
        self.profile_active = bool(block["profile_active"][-1])
        self.profile_index = int(block["profile_index"][-1])
        self.tick = int(block["tick"][-1])
