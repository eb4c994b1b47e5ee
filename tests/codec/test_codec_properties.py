"""Property tests of the codec (hypothesis, derandomised):

1. every packet round-trips through encode and decode, over the wire types' full ranges;
2. a stream of known frames, corrupted at random (bit flips, deletions, insertions,
   truncation, junk) and fed in random chunk sizes, never raises, never yields a frame
   that was not sent, and yields every frame that the corruption left intact;
3. random bytes never raise.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from groundstation.codec import DatagramDecoder, FrameCodec, StreamDeframer
from groundstation.core.dictionary import CRC_SIZE, HEADER_SIZE, load_dictionary
from groundstation.core.errors import DecodeError

DICTIONARY = load_dictionary()
CODEC = FrameCodec(DICTIONARY)
FIXED = [p for p in DICTIONARY.packets if p.variable_item is None]
VARIABLE = [p for p in DICTIONARY.packets if p.variable_item is not None]
RESIDUE = 0x2144DF1C


def fast(max_examples: int):
    return settings(max_examples=max_examples, deadline=None, derandomize=True,
                    database=None, suppress_health_check=[HealthCheck.too_slow,
                                                          HealthCheck.data_too_large])


u32 = st.integers(0, 2**32 - 1)


# ===================================================================== 1. round trips
def raw_values(item):
    """Raw wire values over the type's full range (floats: every f32/f64, NaN and inf too)."""
    dt = item.wire_dtype
    if dt.kind in "iu":
        info = np.iinfo(dt)
        return st.integers(int(info.min), int(info.max))
    return st.floats(width=8 * dt.itemsize)


def same_raw(got: np.ndarray, want: np.ndarray, dt: np.dtype) -> bool:
    want = np.asarray(want).astype(dt)
    if dt.kind == "f":
        return np.array_equal(got.astype(np.float64), want.astype(np.float64), equal_nan=True)
    return np.array_equal(got, want)


@pytest.mark.parametrize("name", [p.name for p in FIXED])
@fast(60)
@given(data=st.data())
def test_fixed_packets_round_trip(name, data):
    pkt = DICTIONARY.packet(name)
    n = data.draw(st.integers(1, 5), label="frames")
    rows = data.draw(st.lists(st.fixed_dictionaries({i.name: raw_values(i) for i in pkt.items}),
                              min_size=n, max_size=n), label="rows")
    seq = data.draw(st.lists(u32, min_size=n, max_size=n), label="sequence")
    tick = data.draw(st.lists(u32, min_size=n, max_size=n), label="tick")
    columns = {i.name: np.array([r[i.name] for r in rows],
                                dtype=np.float64 if i.wire_dtype.kind == "f" else np.int64)
               for i in pkt.items}
    stream = CODEC.encode(pkt, columns, sequence=seq, tick=tick, engineering=False)
    size = pkt.frame_dtype.itemsize
    assert len(stream) == n * size

    strict = [CODEC.decode_frame(stream[k * size:(k + 1) * size], float(k)) for k in range(n)]
    deframer = StreamDeframer(CODEC)
    blocks = deframer.feed(stream, 1.0) + deframer.flush(2.0)
    assert len(blocks) == 1 and len(blocks[0]) == n
    assert deframer.counters.junk_bytes == 0
    for k, block in enumerate(strict):
        assert block.raw.tobytes() == stream[k * size:(k + 1) * size]
    block = blocks[0]
    assert block.raw.tobytes() == stream
    assert block["sequence"].tolist() == seq and block["tick"].tolist() == tick
    for item in pkt.items:
        assert same_raw(block.raw[item.name], columns[item.name], item.wire_dtype), item.name
        eng = item.to_engineering(block.raw[item.name])
        assert np.array_equal(block[item.name], eng, equal_nan=eng.dtype.kind == "f")
        for flag, bit in item.bits.items():
            assert block[flag].tolist() == [bool((int(v) >> bit) & 1) for v in columns[item.name]]


def variable_values(pkt):
    fields = {}
    for item in pkt.items:
        if item.type == "str":
            room = DICTIONARY.max_payload - pkt.fixed_payload_size
            fields[item.name] = st.text(st.characters(codec="utf-8"), max_size=room // 4)
        elif item.type == "bytes":
            fields[item.name] = st.binary(max_size=DICTIONARY.max_payload - pkt.fixed_payload_size)
        else:
            fields[item.name] = raw_values(item)
    return st.fixed_dictionaries(fields)


@pytest.mark.parametrize("name", [p.name for p in VARIABLE])
@fast(60)
@given(data=st.data())
def test_variable_packets_round_trip(name, data):
    pkt = DICTIONARY.packet(name)
    rows = data.draw(st.lists(variable_values(pkt), min_size=1, max_size=4), label="rows")
    frames = [CODEC.encode_variable(pkt, row, sequence=k * 7919, tick=k) for k, row in enumerate(rows)]
    for frame, row in zip(frames, rows):
        assert zlib.crc32(frame) == RESIDUE
        block = CODEC.decode_frame(frame)
        assert block.frames == [frame]
        for item in pkt.items:
            assert block[item.name][0] == row[item.name], item.name
    decoder = DatagramDecoder(CODEC)
    blocks = decoder.decode(frames, [float(k) for k in range(len(frames))])
    assert len(blocks) == 1 and blocks[0].frames == frames
    for item in pkt.items:
        assert blocks[0][item.name].tolist() == [r[item.name] for r in rows]
    assert blocks[0]["sequence"].tolist() == [k * 7919 for k in range(len(rows))]


# ===================================================================== 2. corruption
# Payload bytes biased towards the bytes of a plausible header (EB 90 01 01 00 3C ...), so
# that false sync words and false headers inside payloads and junk are common.
header_ish = st.sampled_from([0xEB, 0x90, 0x01, 0x02, 0x03, 0x00, 0x3C, 0x2D, 0x11, 0x10])
payload_byte = st.one_of(header_ish, st.integers(0, 255))


def byte_string(min_size: int, max_size: int):
    return st.lists(payload_byte, min_size=min_size, max_size=max_size).map(bytes)


@st.composite
def frame_lists(draw, max_frames: int = 20):
    """Frames of mixed packets, each identified by its index (= sequence number)."""
    n = draw(st.integers(1, max_frames), label="n_frames")
    frames = []
    for k in range(n):
        pkt = draw(st.sampled_from(DICTIONARY.packets), label="packet")
        extra = draw(st.integers(0, 40), label="extra") if pkt.variable_item is not None else 0
        size = pkt.fixed_payload_size + extra
        payload = draw(st.one_of(st.binary(min_size=size, max_size=size),
                                 byte_string(size, size)), label="payload")
        frames.append(CODEC.frame(pkt.id, payload, sequence=k, tick=1000 + k))
    return frames


junk = byte_string(1, 60)
# a false header that passes the header check: it claims a span that may hide later frames
false_header = st.builds(
    lambda pid, length, rest: b"\xEB\x90\x01" + bytes([pid]) + length.to_bytes(2, "big") + rest,
    st.sampled_from([p.id for p in DICTIONARY.packets]), st.integers(0, DICTIONARY.max_payload),
    byte_string(0, 12))
position = st.integers(0, 10**6)
corruption = st.one_of(
    st.tuples(st.just("flip"), position, st.integers(0, 7)),
    st.tuples(st.just("delete"), position, st.integers(1, 80)),
    st.tuples(st.just("insert"), position, junk),
    st.tuples(st.just("insert"), position, false_header),
    st.tuples(st.just("insert_near_end"), st.integers(0, 200), false_header),
    st.tuples(st.just("cut_frame"), position),
    st.tuples(st.just("truncate"), position),
    st.tuples(st.just("prepend"), junk),
    st.tuples(st.just("append"), junk),
)


def corrupt(frames: list[bytes], ops) -> tuple[bytes, list[int]]:
    """Apply `ops` to the concatenated frames; returns the bytes and the indices of the
    frames still present, unmodified and contiguous (intact)."""
    data = bytearray(b"".join(frames))
    labels: list[tuple[int, int] | None] = [(i, k) for i, f in enumerate(frames) for k in range(len(f))]
    for op in ops:
        kind = op[0]
        if kind == "flip" and data:
            p = op[1] % len(data)
            data[p] ^= 1 << op[2]
        elif kind == "delete" and data:
            p = op[1] % len(data)
            del data[p:p + op[2]]
            del labels[p:p + op[2]]
        elif kind in ("insert", "insert_near_end"):
            p = op[1] % (len(data) + 1)
            if kind == "insert_near_end":
                p = len(data) - p if p <= len(data) else 0
            data[p:p] = op[2]
            labels[p:p] = [None] * len(op[2])
        elif kind == "cut_frame" and data:
            # a frame truncated: its bytes from p to its end are lost, the next frame follows
            p = op[1] % len(data)
            if labels[p] is not None:
                end = p
                while end < len(labels) and labels[end] is not None and labels[end][0] == labels[p][0]:
                    end += 1
                del data[p:end]
                del labels[p:end]
        elif kind == "truncate" and data:
            p = op[1] % len(data)
            del data[p:]
            del labels[p:]
        elif kind == "prepend":
            data[0:0] = op[1]
            labels[0:0] = [None] * len(op[1])
        elif kind == "append":
            data += op[1]
            labels += [None] * len(op[1])
    first: dict[int, int] = {}
    for p, lab in enumerate(labels):
        if lab is not None and lab[1] == 0 and lab[0] not in first:
            first[lab[0]] = p
    intact = []
    for i, p in first.items():
        f = frames[i]
        if (bytes(data[p:p + len(f)]) == f
                and labels[p:p + len(f)] == [(i, k) for k in range(len(f))]):
            intact.append(i)
    return bytes(data), sorted(intact)


def chunked(data: bytes, sizes: list[int]) -> list[bytes]:
    out, pos, k = [], 0, 0
    while pos < len(data):
        step = sizes[k % len(sizes)]
        out.append(data[pos:pos + step])
        pos += step
        k += 1
    return out


def decoded_frames(blocks) -> list[bytes]:
    """The frames of decoded blocks as bytes; checks the columns were decoded from them."""
    out = []
    for b in blocks:
        frames = [r.tobytes() for r in b.raw] if b.raw is not None else list(b.frames)
        assert len(frames) == len(b) == len(b.host_time)
        assert all(f[3] == b.packet.id for f in frames)
        assert b["sequence"].tolist() == [int.from_bytes(f[6:10], "big") for f in frames]
        assert b["tick"].tolist() == [int.from_bytes(f[10:14], "big") for f in frames]
        out += frames
    return out


def check_decoded(got: list[bytes], frames: list[bytes]) -> list[int]:
    """Every decoded frame is a sent one (same bytes: packet, sequence, payload, CRC), and
    within each packet they come in the order they were sent.  Returns their indices."""
    index = {f: i for i, f in enumerate(frames)}
    for f in got:
        assert f in index, f"decoded a frame that was never sent: {f.hex()}"
        assert zlib.crc32(f) == RESIDUE
    by_packet: dict[int, list[int]] = {}
    for f in got:
        by_packet.setdefault(f[3], []).append(index[f])
    for seqs in by_packet.values():
        assert seqs == sorted(seqs)
    return [index[f] for f in got]


def check_accounting(counters, got: list[bytes], total: int) -> None:
    """After the end of the input every byte is in an accepted frame or counted as junk."""
    assert counters.bytes_in == total
    assert counters.frames == len(got)
    assert counters.junk_bytes + sum(map(len, got)) == total


chunk_sizes = st.lists(st.integers(1, 150), min_size=1, max_size=30)


@fast(200)
@given(frames=frame_lists(), ops=st.lists(corruption, min_size=1, max_size=5), sizes=chunk_sizes)
def test_corrupted_stream(frames, ops, sizes):
    data, intact = corrupt(frames, ops)
    deframer = StreamDeframer(CODEC)
    blocks = []
    for t, piece in enumerate(chunked(data, sizes)):
        blocks += deframer.feed(piece, float(t))
    blocks += deframer.flush(-1.0)
    got = decoded_frames(blocks)
    found = check_decoded(got, frames)
    check_accounting(deframer.counters, got, len(data))
    assert deframer.buffered == 0
    # every frame the corruption left intact is recovered (a fortiori those separated from
    # the corruption by intact frames)
    missing = sorted(set(intact) - set(found))
    assert not missing, f"intact frames {missing} lost"


@fast(150)
@given(frames=frame_lists(), ops=st.lists(corruption, min_size=1, max_size=5),
       cuts=st.lists(position, max_size=8))
def test_corrupted_datagrams(frames, ops, cuts):
    data, intact = corrupt(frames, ops)
    bounds = sorted({0, len(data), *(c % (len(data) + 1) for c in cuts)})
    datagrams = [data[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
    decoder = DatagramDecoder(CODEC)
    got = decoded_frames(decoder.decode(datagrams, [float(k) for k in range(len(datagrams))]))
    found = check_decoded(got, frames)
    check_accounting(decoder.counters, got, len(data))
    # intact frames that lie wholly inside one datagram are recovered
    starts = {}
    pos = 0
    for i in intact:
        starts[i] = data.index(frames[i], pos)
        pos = starts[i] + len(frames[i])
    whole = [i for i in intact
             if np.searchsorted(bounds, starts[i], side="right")
             == np.searchsorted(bounds, starts[i] + len(frames[i]) - 1, side="right")]
    missing = sorted(set(whole) - set(found))
    assert not missing, f"intact frames {missing} lost"


@fast(60)
@given(frames=frame_lists(max_frames=12), sizes=chunk_sizes)
def test_uncorrupted_stream_in_any_chunks_yields_everything(frames, sizes):
    data = b"".join(frames)
    deframer = StreamDeframer(CODEC)
    blocks = []
    for piece in chunked(data, sizes):
        blocks += deframer.feed(piece, 0.0)
    assert deframer.flush(0.0) == []            # nothing left over once the last byte is in
    got = decoded_frames(blocks)
    assert sorted(check_decoded(got, frames)) == list(range(len(frames)))
    c = deframer.counters
    assert (c.junk_bytes, c.resyncs, c.crc_errors, c.version_errors,
            c.unknown_packet_errors, c.length_errors) == (0, 0, 0, 0, 0, 0)


# ===================================================================== 3. random bytes
random_bytes = st.one_of(st.binary(max_size=1500), byte_string(0, 1500))


@fast(150)
@given(data=random_bytes, sizes=chunk_sizes)
def test_random_bytes_never_raise(data, sizes):
    deframer = StreamDeframer(CODEC)
    blocks = []
    for t, piece in enumerate(chunked(data, sizes)):
        blocks += deframer.feed(piece, float(t))
    blocks += deframer.flush(0.0)
    got = decoded_frames(blocks)
    for f in got:                                 # (a random valid frame is possible in
        assert zlib.crc32(f) == RESIDUE           # principle; it must then be well formed)
    check_accounting(deframer.counters, got, len(data))

    decoder = DatagramDecoder(CODEC)
    got = decoded_frames(decoder.decode(chunked(data, sizes), 0.0))
    check_accounting(decoder.counters, got, len(data))


@fast(150)
@given(data=st.one_of(random_bytes, st.builds(
    lambda head, rest: b"\xEB\x90\x01" + head + rest,
    st.sampled_from([b"\x01\x00\x3C", b"\x02\x00\x2D", b"\x03\x00\x05", b"\x10\x00\x06",
                     b"\x11\x00\x09", b"\x7F\x00\x00"]), byte_string(0, 100))))
def test_strict_decode_of_random_bytes_raises_only_decode_errors(data):
    # give some of them a correct CRC so the later checks are reached too
    for frame in (data, data + zlib.crc32(data).to_bytes(4, "little")):
        try:
            block = CODEC.decode_frame(frame)
        except DecodeError:
            continue
        assert len(block) == 1
        assert zlib.crc32(frame) == RESIDUE
        assert frame[:2] == b"\xEB\x90" and len(frame) == HEADER_SIZE + CRC_SIZE + int.from_bytes(
            frame[4:6], "big")
