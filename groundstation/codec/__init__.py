"""protocol/*.toml -> numpy dtypes; frame encode/decode; stream and datagram deframing; CRC."""

from .deframer import DatagramDecoder, FramingCounters, StreamDeframer
from .frames import FrameCodec, TelemetryBlock, decode_items, encode_items

__all__ = ["DatagramDecoder", "FrameCodec", "FramingCounters", "StreamDeframer",
           "TelemetryBlock", "decode_items", "encode_items"]
