"""The simulated testbed: firmware behaviour, plant, and its protocol endpoint.

The names below are imported on first use (PEP 562): a session whose simulator runs in a
child process (`--fast`, sim/stepped_process.py) imports this package for the child's
handle only, and must not pay the engine's imports - numba and the compiled core - that
only the child uses (in a py-spy profile, about 0.4 s of a `campaign run`'s start, on
its critical path: docs/campaigns.md, "Fifth round").
"""

from __future__ import annotations

from ..core.lazy_names import lazy_dir, lazy_getattr

_LAZY = {"SimulatedDevice": "device", "Firmware": "firmware"}

__getattr__ = lazy_getattr(__name__, _LAZY, globals())
__dir__ = lazy_dir(_LAZY, globals())

__all__ = sorted(_LAZY)
