"""The messages a publisher sends: one ZeroMQ multipart message each.

    part 0  topic     b"frames" | b"hello" | b"command" | b"link"
    part 1  header    26 bytes, big-endian: magic b"GSFO", wire version (u8), kind (u8),
                      message sequence (u64), host time (f64, s since the epoch), device
                      tick (u32, of the first frame; NO_TICK for other kinds)
    part 2  payload   frames: an index of (length u32, arrival time f64) per chunk;
                      others: UTF-8 JSON
    part 3  data      frames only: the chunks back to back, bytes exactly as received

A chunk is a UDP datagram as the device sent it (one or more whole frames), or, on a
stream link, the frames of one decoded block (RESPONSE frames are never published: the
CONNECT answer carries the session token, and only the commander may hold it).  A
viewer decodes chunks with its own dictionary, exactly as the commander's
DatagramDecoder does, so the blocks and the log are the same and stay re-decodable.

The message sequence counts every message of one publisher; a viewer counts the
messages it missed from its gaps (a slow viewer's messages are dropped at the
publisher's high-water mark, whole).  Frame drops are counted as everywhere else, from
the frames' own sequence numbers (link/stats.py).  Standard library only.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass
from typing import Any

from . import schema

MAGIC = b"GSFO"
WIRE_VERSION = 1
HEADER = struct.Struct(">4sBBQdI")
INDEX = struct.Struct(">Id")
NO_TICK = 0xFFFFFFFF

TOPIC_FRAMES, TOPIC_HELLO, TOPIC_COMMAND, TOPIC_LINK = b"frames", b"hello", b"command", b"link"
KINDS = {TOPIC_FRAMES: 1, TOPIC_HELLO: 2, TOPIC_COMMAND: 3, TOPIC_LINK: 4}
TOPICS = {v: k for k, v in KINDS.items()}

#: byte offset of the tick in a frame header (sync u16, version u8, id u8, length u16,
#: sequence u32, tick u32: SPEC §2)
_TICK_AT = 10


class WireError(ValueError):
    """A message that is not this layout (another program on the port, another version)."""


@dataclass(frozen=True)
class Message:
    topic: bytes
    sequence: int
    host_time: float
    device_tick: int | None
    chunks: list[bytes] | None = None       # frames
    times: list[float] | None = None        # frames: arrival time of each chunk
    record: Any = None                      # the JSON kinds


def _header(topic: bytes, sequence: int, host_time: float, tick: int = NO_TICK) -> bytes:
    return HEADER.pack(MAGIC, WIRE_VERSION, KINDS[topic], sequence, host_time, tick)


def frames_message(sequence: int, chunks: list[bytes], times: list[float]) -> list[bytes]:
    """The parts of a frames message (chunks and their arrival times, same length)."""
    first = chunks[0] if chunks else b""
    tick = int.from_bytes(first[_TICK_AT:_TICK_AT + 4], "big") if len(first) >= _TICK_AT + 4 \
        else NO_TICK
    index = b"".join(INDEX.pack(len(c), t) for c, t in zip(chunks, times))
    return [TOPIC_FRAMES, _header(TOPIC_FRAMES, sequence, times[0] if times else 0.0, tick),
            index, b"".join(chunks)]


def json_message(topic: bytes, sequence: int, host_time: float, record: Any) -> list[bytes]:
    """The parts of a hello, command or link message."""
    body = json.dumps(record, default=_plain, separators=(",", ":")).encode()
    return [topic, _header(topic, sequence, host_time), body]


def _plain(value: Any) -> Any:
    """What JSON cannot hold as such: bytes as hex text, numpy scalars as numbers."""
    if isinstance(value, (bytes, bytearray, memoryview)):
        return bytes(value).hex()
    if hasattr(value, "item"):
        return value.item()
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)


_SCHEMAS = {TOPIC_HELLO: schema.hello, TOPIC_COMMAND: schema.command, TOPIC_LINK: schema.link}


def parse(parts: list[bytes]) -> Message:
    """A received multipart message -> Message; WireError if it is not ours, or not
    within the limits and schema a console accepts (schema.py).  Never anything else:
    whatever the bytes, the caller gets a Message whose fields have their types."""
    if len(parts) not in (3, 4) or len(parts[1]) != HEADER.size:
        raise WireError(f"a message of {len(parts)} part(s) that is not a fan-out message")
    size = sum(len(p) for p in parts)
    if size > schema.MAX_MESSAGE_BYTES:
        raise WireError(f"a message of {size} bytes, above the {schema.MAX_MESSAGE_BYTES} a "
                        f"console accepts")
    magic, version, kind, seq, host_time, tick = HEADER.unpack(parts[1])
    if magic != MAGIC:
        raise WireError("a message without the fan-out magic (another program on this port?)")
    if version != WIRE_VERSION:
        raise WireError(f"fan-out wire version {version}, this console reads {WIRE_VERSION}: "
                        f"run the same ground station version on both consoles")
    topic = TOPICS.get(kind)
    if topic is None or topic != parts[0]:
        raise WireError(f"unknown fan-out message kind {kind}")
    if not math.isfinite(host_time):
        raise WireError(f"a {topic.decode()} message with host time {host_time}")
    device_tick = None if tick == NO_TICK else tick
    if topic != TOPIC_FRAMES:
        if len(parts) != 3:
            raise WireError(f"a {topic.decode()} message of {len(parts)} parts, not 3")
        return Message(topic, seq, host_time, device_tick, record=_record(topic, parts[2]))
    if len(parts) != 4 or len(parts[2]) % INDEX.size:
        raise WireError("a frames message with a damaged index")
    if len(parts[2]) // INDEX.size > schema.MAX_CHUNKS:
        raise WireError(f"a frames message of {len(parts[2]) // INDEX.size} chunks, above "
                        f"{schema.MAX_CHUNKS}")
    data, chunks, times, at = parts[3], [], [], 0
    for length, when in INDEX.iter_unpack(parts[2]):
        if not math.isfinite(when):
            raise WireError(f"a frames message with arrival time {when}")
        chunks.append(data[at:at + length])
        times.append(when)
        at += length
    if at != len(data):
        raise WireError(f"a frames message whose index covers {at} of {len(data)} bytes")
    return Message(topic, seq, host_time, device_tick, chunks=chunks, times=times)


def _record(topic: bytes, body: bytes) -> Any:
    """The checked record of a JSON kind: size, then nesting (before json.loads, whose
    parser recurses per level), then the kind's schema."""
    what = topic.decode()
    if len(body) > schema.MAX_JSON_BYTES:
        raise WireError(f"a {what} message of {len(body)} bytes of JSON, above "
                        f"{schema.MAX_JSON_BYTES}")
    if schema.json_depth(body) > schema.MAX_JSON_DEPTH:
        raise WireError(f"a {what} message nested deeper than {schema.MAX_JSON_DEPTH} levels")
    try:
        record = json.loads(body)
    except (ValueError, RecursionError) as exc:   # UnicodeDecodeError is a ValueError
        raise WireError(f"a {what} message that is not JSON ({str(exc)[:120]})") from None
    try:
        return _SCHEMAS[topic](record)
    except schema.SchemaError as exc:
        raise WireError(f"a {what} message: {exc}") from None
