"""Transports (UDP, TCP, serial), the device client, link statistics."""

from .address import DeviceAddress, open_client, parse_address
from .client import CommandResult, DeviceClient, StageRecord
from .stats import LinkSnapshot, LinkStatistics, format_snapshot

__all__ = ["CommandResult", "DeviceAddress", "DeviceClient", "LinkSnapshot", "LinkStatistics",
           "StageRecord", "format_snapshot", "open_client", "parse_address"]
