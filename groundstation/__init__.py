"""Ground station for hybrid-flexure-bearing precision-pointing testbeds."""

__version__ = "0.1.0"


def __getattr__(name: str):
    # `from groundstation import Testbed` without importing the link, the simulator and
    # the recorder for every user of the package (the CLI, the GUI) at start-up
    if name == "Testbed":
        from .scripting import Testbed
        return Testbed
    raise AttributeError(f"module 'groundstation' has no attribute {name!r}")
