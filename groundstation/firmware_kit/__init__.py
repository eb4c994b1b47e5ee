"""A firmware kit generated from the protocol dictionary (protocol/*.toml).

`export_c` writes a C99 header and reference implementation (CRC, frame encoder, stream
deframer, pack/unpack of every layout) for the device firmware; `export_wireshark`
writes a Lua dissector of the UDP telemetry and the TCP command channel.  Both are pure
functions of the dictionary.  docs/firmware.md is the user's guide.
"""

from .c_export import export_c, render_c
from .wireshark_export import export_wireshark, render_lua

__all__ = ["export_c", "export_wireshark", "render_c", "render_lua"]
