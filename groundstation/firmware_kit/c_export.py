"""`groundstation protocol export-c DIR`: the C header and reference implementation of
the protocol, generated from the dictionary (docs/firmware.md says how to use them).

The text is a pure function of the dictionary: the same TOML files give the same bytes,
so the exported files can be committed to a firmware repository and re-exported to see
what changed.
"""

from __future__ import annotations

from pathlib import Path

from ..core.dictionary import Dictionary
from .c_header import header_text
from .c_source import source_text

BASENAME = "hfb_protocol"


def render_c(dictionary: Dictionary, basename: str = BASENAME) -> dict[str, str]:
    """File name -> text of the kit's C files."""
    return {f"{basename}.h": header_text(dictionary, basename),
            f"{basename}.c": source_text(dictionary, basename)}


def export_c(dictionary: Dictionary, directory: str | Path) -> list[Path]:
    """Write the C files into `directory` (made if missing); returns their paths."""
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, text in render_c(dictionary).items():
        path = out / name
        # bytes, not text: no platform newline translation, so the files are identical
        # wherever they are exported
        path.write_bytes(text.encode("ascii"))
        written.append(path)
    return written
