"""The simulated testbed: firmware behaviour, plant, and its protocol endpoint."""

from .device import SimulatedDevice
from .firmware import Firmware

__all__ = ["Firmware", "SimulatedDevice"]
