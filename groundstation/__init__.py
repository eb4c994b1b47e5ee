"""Ground station for hybrid-flexure-bearing precision-pointing testbeds.

The script-facing names: `from groundstation import Testbed`.  `Testbed` is the Station
(station/station.py) under the name scripts and notebooks have always used; its
docstring shows a whole session.  `ScriptError` is what a verb raises when it cannot do
its job, `ScriptAborted` what a wait raises after an abort."""

__version__ = "0.1.0"

__all__ = ["Testbed", "Station", "ScriptError", "ScriptAborted"]


def __getattr__(name: str):
    # imported on first use, not at `import groundstation`: the CLI and the window start
    # without the link, the simulator and the recorder
    if name in ("Testbed", "Station", "ScriptError"):
        from .station import station
        return station.Station if name == "Testbed" else getattr(station, name)
    if name == "ScriptAborted":
        from .station.clock import ScriptAborted
        return ScriptAborted
    raise AttributeError(f"module 'groundstation' has no attribute {name!r}")
