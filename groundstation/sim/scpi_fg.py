"""The simulated base-disturbance function generator (B&K 4053B, a 4050-series SCPI
subset on a TCP socket), whose output voltage drives the simulated base stage through
`SimulatedDevice.base_drive`.

This module is the place every name has always been imported from; the code lives in
two modules with one job each:

* `fg_instrument` - the instrument: channels, settings checked against
  `groundstation.instruments.spec4050.LIMITS`, error queue, arbitrary-waveform upload,
  output voltages (`SimulatedGenerator`; the SCPI subset and output model are
  documented there);
* `scpi_server` - the TCP server: listening socket, connections, framing of SCPI lines
  and binary blocks, the fault-injection hook `ScpiServer.inject_reply`, and
  `attach_generator`.
"""

from __future__ import annotations

# the private helpers stay importable from here too, as they always were (not in __all__)
from .fg_instrument import (  # noqa: F401
    ERROR_QUEUE_DEPTH,
    ScpiError,
    SimulatedGenerator,
    UserWave,
    _ALIASES,
    _Channel,
    _builtin_shape,
    _check_levels,
    _number,
    _out_of_range,
    _pairs,
    log,
    parse_length,
)
from .scpi_server import (  # noqa: F401
    MAX_LINE_BYTES,
    MAX_UPLOAD_BYTES,
    ScpiServer,
    _Conn,
    attach_generator,
)

__all__ = [
    "ERROR_QUEUE_DEPTH",
    "MAX_LINE_BYTES",
    "MAX_UPLOAD_BYTES",
    "ScpiError",
    "ScpiServer",
    "SimulatedGenerator",
    "UserWave",
    "attach_generator",
    "parse_length",
]
