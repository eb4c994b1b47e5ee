"""Decode an old log again with another protocol dictionary (`groundstation log redecode`).

The log keeps every frame as received; this feeds them, with their recorded arrival
times, through the codec of the new dictionary and writes a new log with the same
journal and testbed record.  Use it when a channel's conversion was wrong, or a newer
dictionary names or scales channels better: the raw data never change.

The new log keeps the session's start and end (`created_utc`, `stop_utc`) from the old
one: its length is the session's, not the few tenths of a second the re-decoding took.
It is written to a temporary file and renamed when complete; a damaged source raises
LogDamagedError and leaves nothing behind.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..codec import DatagramDecoder, FrameCodec
from ..core.dictionary import Dictionary
from .atomic import atomic_output
from .h5file import LogFile
from .reader import LogReader
from .opening import LogError

CHUNK_FRAMES = 100_000


class RedecodeError(LogError):
    """The re-decoded log cannot be written (the message names the target)."""


def redecode(source: str | Path, target: str | Path, dictionary: Dictionary) -> dict[str, int]:
    """Write `target` from the frames of `source` decoded with `dictionary`; returns
    frames decoded and rejected per packet (a frame the new dictionary refuses - e.g. a
    packet it no longer defines - is counted, never silently dropped)."""
    counts: dict[str, int] = {}
    with LogReader(source) as r:
        info = r.summary()
        name, path, text = r.testbed()
        with atomic_output(target, RedecodeError) as tmp:
            _write(r, info, tmp, dictionary, source, name, path, text, counts)
    return counts


def _write(r: LogReader, info, tmp: Path, dictionary: Dictionary, source, name: str, path: str,
           text: str, counts: dict[str, int]) -> None:
    # the session's times, not the re-decoding's (LogInfo has them also for a log whose
    # recorder never closed it: then the last frame's arrival is its end)
    out = LogFile(tmp, dictionary, test_name=info.test_name, run=info.run, notes=info.notes,
                  testbed_text=text, testbed_name=name, testbed_path=path,
                  created_utc=info.created_utc or None)
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
    out.close(clean=True, stop_utc=info.stop_utc or None)
