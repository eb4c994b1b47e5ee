"""The HDF5 log layout (schema version 1), shared by the recorder and the reader.

    /                       attrs: schema, schema_version, uuid, created_utc, software_version,
                            host, test_name, run, notes, protocol_version, dictionary_hash,
                            tick_rate_hz; on a clean close also stop_utc, clean_close=True
    /protocol/<file>.toml   the protocol files as recorded (fixed-length UTF-8 text)
    /testbed/config         the testbed file as recorded (if known), attrs name, path
    /telemetry/<PACKET>/    one group per packet, attrs id, description, rate_hz
        sequence, tick      header counters (u4, as on the wire)
        device_time         unwrapped tick / tick rate (s since the device booted)
        host_time           host arrival time (s since the Unix epoch)
        <item>              engineering units (float64 where a conversion applies, else the
                            wire type); attrs units, description, conversion, states, limits
        <flag>              bool, one per status bit
        raw/<item>          wire counts of every converted item
        <item>/data|offset|length   a variable (text or bytes) item: byte stream + index
    /frames/<PACKET>/       the frames as received (re-decodable with a newer dictionary):
        data (n, frame_len) u1 for fixed packets; a byte stream plus offset/length for
        variable ones; host_time
    /journal/               everything that is not telemetry, one row per record:
        time (host, s), kind (u1, names in attr 'kinds'), text_offset/text_length into
        text (u1 stream of UTF-8 JSON), blob_offset/blob_length into blob (u1 stream)

Everything is created before SWMR mode starts and only ever appended to, with fixed-size
types (no variable-length HDF5 types: their heap is not SWMR-safe), so a reader in
SWMR mode (ours, h5py with swmr=True) sees a consistent file while it grows and after a
crash.  HDF5's own tools (h5dump, h5ls), MATLAB and HDFView refuse a file while it is
open for SWMR writing and open it once the recording has stopped.  A log whose writer
was killed keeps HDF5's "open for writing" mark: our reader (SWMR read mode) opens it
as it is; other tools want `h5clear -s FILE` first.
"""

from __future__ import annotations

SCHEMA = "groundstation-log"
SCHEMA_VERSION = 1
# rows per chunk of a per-frame dataset: about what arrives between two flushes (0.25 s
# = 300 HIGH_RATE frames), so live recording writes whole chunks; larger chunks get
# rewritten, compressed anew, at every flush and leave the old copies as dead space
# (measured: 8192 rows made live files 6.5x larger than batch-written ones; 256 none)
CHUNK_ROWS = 256
# rows per chunk in a fast campaign's logs (the simulator in this process, many device
# seconds a wall second): a flush then carries thousands of frames, and what costs is
# the number of chunks, not their size - each one is a pass through HDF5's chunk
# allocation and index in the writer, and a shuffle, a deflate set-up and a
# write_direct_chunk call when the log is compressed behind the session.  The writer
# writes these logs uncompressed, so a chunk a flush fills only in part is completed in
# place by the next one (no dead space, unlike the compressed chunks above).  8192 rows:
# 64 KiB a chunk of a float64 column, and the raw frames' chunks stay capped at
# WIDE_ROW_CHUNK_BYTES, so every chunk fits HDF5's default 1 MiB chunk cache and a reader
# paging through a window inflates each chunk once.  Against 1024 rows: the compression
# behind a fast inertial_bm 20 % less CPU, the writers 13 % less, the logs 4 % smaller
# (docs/campaigns.md, "Sixth round")
FAST_CHUNK_ROWS = 8192
#: at most this many bytes a chunk for wide rows (raw frames, 63-78 bytes a row): fewer
#: rows a chunk than the per-frame columns have
WIDE_ROW_CHUNK_BYTES = 512 * 1024
# the log writer's niceness in a fast campaign: on a contended machine the simulator
# (which the writer waits for anyway) gets the core first
FAST_WRITER_NICENESS = 10
STREAM_CHUNK = 65536              # bytes per chunk of a byte stream

JOURNAL_KINDS = ("note", "command", "event", "parameter_table", "profile",
                 "function_generator", "link", "recorder", "testbed")

#: compression of per-frame datasets: deflate (gzip) level 1 after byte shuffling. Among
#: the filters every HDF5 reader has (h5dump, MATLAB, HDFView), it is the fast one;
#: benchmarks/bench_logs.py measures it against LZF (h5py-only) and no compression.  A
#: fast session's writer records without it and compresses behind the runs instead
#: (compress_behind.py): deflate was that writer's whole cost.
COMPRESSION = {"compression": "gzip", "compression_opts": 1, "shuffle": True}
#: file format bounds: HDF5 1.10 (the first with SWMR), so 1.10-era tools and MATLAB
#: read our logs; "latest" would tie them to the newest library
LIBVER = ("v110", "v110")
