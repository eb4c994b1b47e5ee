"""A firmware kit generated from the protocol dictionary (protocol/*.toml).

`export_c` writes a C99 header and reference implementation (CRC, frame encoder, stream
deframer, pack/unpack of every layout) for the device firmware.  It is a pure function
of the dictionary.  docs/firmware.md is the user's guide.
"""

from .c_export import export_c, render_c

__all__ = ["export_c", "render_c"]
