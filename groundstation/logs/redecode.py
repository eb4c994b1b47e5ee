"""Decode an old log again with another protocol dictionary (`groundstation log redecode`).

The log keeps every frame as received; this feeds them, with their recorded arrival
times, through the codec of the new dictionary and writes a new log with the same
journal and testbed record.  Use it when a channel's conversion was wrong, or a newer
dictionary names or scales channels better: the raw data never change.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..codec import DatagramDecoder, FrameCodec
from ..dictionary import Dictionary
from .h5file import LogFile
from .reader import LogReader

CHUNK_FRAMES = 100_000


def redecode(source: str | Path, target: str | Path, dictionary: Dictionary) -> dict[str, int]:
    """Write `target` from the frames of `source` decoded with `dictionary`; returns
    frames decoded and rejected per packet (a frame the new dictionary refuses - e.g. a
    packet it no longer defines - is counted, never silently dropped)."""
    counts: dict[str, int] = {}
    with LogReader(source) as r:
        info = r.summary()
        name, path, text = r.testbed()
        out = LogFile(Path(target), dictionary, test_name=info.test_name, run=info.run,
                      notes=info.notes, testbed_text=text, testbed_name=name, testbed_path=path)
        try:
            decoder = DatagramDecoder(FrameCodec(dictionary))
            for packet in r.packets():
                n = r.n_frames(packet)
                for i0 in range(0, n, CHUNK_FRAMES):
                    i1 = min(n, i0 + CHUNK_FRAMES)
                    frames = r.frames(packet, i0, i1)
                    host = r.read_rows(packet, [], i0, i1, with_time=True)["host_time"]
                    datagrams = [bytes(f) for f in frames] if isinstance(frames, list) \
                        else [row.tobytes() for row in np.asarray(frames)]
                    blocks = decoder.decode(datagrams, host)
                    out.append(blocks)
                    out.flush()
                counts[f"{packet}_frames"] = n
            c = decoder.counters
            counts["rejected"] = (c.crc_errors + c.version_errors + c.unknown_packet_errors
                                  + c.length_errors)
            out.journal([(rec.time, rec.kind, rec.data, rec.blob) for rec in r.journal()])
            out.journal([(info.stop, "recorder", {
                "action": "redecoded", "source": str(source), "source_uuid": info.uuid,
                "source_dictionary_hash": info.dictionary_hash,
                "dictionary_hash": f"{dictionary.hash:08x}", **counts}, b"")])
            out.flush()
        except BaseException:
            out.close(clean=False)
            raise
        out.close(clean=True)
    return counts
