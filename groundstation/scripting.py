"""The script-facing names: `from groundstation import Testbed`.

`Testbed` is the Station (station/station.py) under the name scripts and notebooks have
always used; its docstring shows a whole session.  `ScriptError` is what a verb raises
when it cannot do its job, `ScriptAborted` what a wait raises after an abort."""

from __future__ import annotations

from .clock import ScriptAborted
from .station.station import ScriptError, Station

Testbed = Station

__all__ = ["Testbed", "Station", "ScriptError", "ScriptAborted"]
