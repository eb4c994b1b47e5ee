"""What a watching console accepts from a publisher: limits, and a small schema per kind.

A console trusts nothing it receives.  Without CURVE keys (loopback) any local process
that binds the publisher's address is "the publisher", and even a genuine one may be a
later version; so every message is checked before anything reads it, in this order:

1. size: at most MAX_MESSAGE_BYTES for all its parts, MAX_JSON_BYTES for a JSON payload
   (wire.parse, before decoding anything);
2. JSON nesting: at most MAX_JSON_DEPTH, measured by json_depth() with a flat scan of
   the bytes, *before* json.loads - whose C parser recurses once per level, so a payload
   nested 100,000 deep ends in RecursionError wherever the stack happens to be;
3. types: the fields the console uses, typed and bounded (hello(), link(), command()
   below); fields it does not use are dropped, so nothing unchecked reaches a listener,
   the terminal or the log.

A message failing any check is a bad message: counted (FanoutCounters.bad_messages),
its reason kept (recent_errors), and otherwise ignored.  Standard library only.
"""

from __future__ import annotations

import math
import re
from typing import Any

#: all parts of one message.  The largest a genuine publisher sends is a frames message
#: of one receive batch: 512 datagrams (link/transports.py max_datagrams) of at most
#: 1472 bytes (SPEC §1.1) plus 12 bytes of index each, 0.76 MB; 4 MiB leaves 5x room.
MAX_MESSAGE_BYTES = 4 << 20
#: ZeroMQ's own cap per part (ZMQ_MAXMSGSIZE): a part above it is never buffered - ZeroMQ
#: drops that connection instead (the console then sees silence and says "lost").  Above
#: MAX_MESSAGE_BYTES so that the usual oversized message is counted, not just cut off.
ZMQ_MAX_PART_BYTES = 4 * MAX_MESSAGE_BYTES
#: a hello, command or link record: a command carrying an UPLOAD chunk (1014 bytes, as
#: hex) is about 3 kB, a hello under 2 kB
MAX_JSON_BYTES = 256 << 10
#: nesting of a JSON payload: a command record is 4 deep (arguments may hold lists)
MAX_JSON_DEPTH = 32
#: chunks in one frames message (512 per receive batch, see above)
MAX_CHUNKS = 4096
#: a text field (a link error, the health line); longer is not something we sent
MAX_TEXT = 4096
#: command stages in one command record (SENT, RETRY..., ACCEPTED, COMPLETED)
MAX_STAGES = 64


class SchemaError(ValueError):
    """A field missing, of the wrong type or out of its bounds (the message says which)."""


_SPECIAL = re.compile(rb'[\[\]{}"\\]')
_OPEN, _CLOSE, _QUOTE, _BACKSLASH = b"[{", b"]}", ord('"'), ord("\\")


def json_depth(body: bytes, limit: int = MAX_JSON_DEPTH) -> int:
    """The nesting depth of the JSON text `body`, counted without recursion; stops
    counting (and returns limit + 1) as soon as it exceeds `limit`.  Brackets inside
    strings are not nesting; escapes inside strings are skipped.  Linear in the size."""
    depth = deepest = 0
    in_string = False
    skip_to = -1
    for m in _SPECIAL.finditer(body):
        at = m.start()
        if at < skip_to:                       # the character after a backslash
            continue
        c = body[at]
        if in_string:
            if c == _BACKSLASH:
                skip_to = at + 2
            elif c == _QUOTE:
                in_string = False
        elif c == _QUOTE:
            in_string = True
        elif c in _OPEN:
            depth += 1
            if depth > deepest:
                deepest = depth
                if deepest > limit:
                    return limit + 1
        elif c in _CLOSE:
            depth -= 1
    return deepest


# ------------------------------------------------------------------------ field types
def _text(record: dict, key: str, *, default: str | None = None, limit: int = MAX_TEXT) -> str:
    value = record.get(key, default)
    if value is None and default is None and key not in record:
        raise SchemaError(f"'{key}' is missing")
    if not isinstance(value, str):
        raise SchemaError(f"'{key}' is {type(value).__name__}, not text")
    if len(value) > limit:
        raise SchemaError(f"'{key}' is {len(value)} characters long, above {limit}")
    # printed on a terminal and shown in the window: no escape sequences, no newlines
    return value if value.isprintable() else "".join(c if c.isprintable() else "?"
                                                      for c in value)


def _name(record: dict, key: str, *, default: str | None = None, limit: int = 64) -> str:
    value = _text(record, key, default=default, limit=limit)
    if not re.fullmatch(r"[A-Za-z0-9_ .-]*", value):
        raise SchemaError(f"'{key}' {value!r} is not a name")
    return value


def _int(record: dict, key: str, lo: int, hi: int, *, default: int | None = None,
         optional: bool = False) -> int | None:
    value = record.get(key, default)
    if value is None and optional:
        return None
    if value is None:
        raise SchemaError(f"'{key}' is missing")
    if isinstance(value, bool) or not isinstance(value, int):
        raise SchemaError(f"'{key}' is {type(value).__name__}, not a whole number")
    if not lo <= value <= hi:
        raise SchemaError(f"'{key}' = {value} is outside {lo}..{hi}")
    return value


def _float(record: dict, key: str, *, default: float | None = None) -> float | None:
    value = record.get(key, default)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SchemaError(f"'{key}' is {type(value).__name__}, not a number")
    if not math.isfinite(value):
        raise SchemaError(f"'{key}' is {value}, not a finite number")
    return float(value)


def _object(value: Any, what: str) -> dict:
    if not isinstance(value, dict):
        raise SchemaError(f"{what} is {type(value).__name__}, not an object")
    return value


# ------------------------------------------------------------------------ per kind
U32 = 0xFFFFFFFF


def device(value: Any) -> dict[str, Any]:
    """Where the device is, for ABORT (abort.py): {} before the commander attached."""
    d = _object(value, "'device'")
    if not d:
        return {}
    kind = _name(d, "kind", limit=16)
    if kind == "tcp":
        return {"kind": "tcp", "host": _text(d, "host", limit=255),
                "port": _int(d, "port", 1, 65535), "address": _text(d, "address", default="")}
    if kind == "serial":
        return {"kind": "serial", "port": _text(d, "port", limit=255),
                "address": _text(d, "address", default="")}
    raise SchemaError(f"device kind {kind!r} is neither tcp nor serial")


def hello(value: Any) -> dict[str, Any]:
    """The publisher's hello (publisher.Publisher.hello), the fields a console uses."""
    h = _object(value, "a hello")
    out: dict[str, Any] = {"instance": _name(h, "instance", limit=64),
                           "device": device(h.get("device", {})),
                           "publisher": _text(h, "publisher", default="", limit=255),
                           "sent": _int(h, "sent", 0, 2**63, default=0),
                           "send_errors": _int(h, "send_errors", 0, 2**63, default=0)}
    if "protocol" in h:
        out["protocol"] = _name(h, "protocol", limit=16)
    if "dictionary_hash" in h:
        out["dictionary_hash"] = _name(h, "dictionary_hash", limit=16)
    if "link_state" in h:
        out.update(link_state=_name(h, "link_state", limit=32),
                   link_error=_text(h, "link_error", default=""),
                   health=_text(h, "health", default=""),
                   dropped=_int(h, "dropped", 0, 2**63, default=0))
    return out


def link(value: Any) -> dict[str, str]:
    """A change of the commander's link state."""
    r = _object(value, "a link record")
    return {"state": _name(r, "state", limit=32), "message": _text(r, "message", default="")}


def command(value: Any) -> dict[str, Any]:
    """One command of the commander's journal (a CommandResult as asdict gives it)."""
    r = _object(value, "a command record")
    stages = r.get("stages", [])
    if not isinstance(stages, list):
        raise SchemaError(f"'stages' is {type(stages).__name__}, not a list")
    if len(stages) > MAX_STAGES:
        raise SchemaError(f"{len(stages)} stages, above {MAX_STAGES}")
    out_stages = []
    for i, s in enumerate(stages):
        s = _object(s, f"stage {i}")
        out_stages.append({"stage": _name(s, "stage", limit=32),
                           "reason": _text(s, "reason", default="OK", limit=256),
                           "host_time": _float(s, "host_time", default=0.0),
                           "device_tick": _int(s, "device_tick", 0, U32, optional=True)})
    return {"name": _name(r, "name", limit=64), "sequence": _int(r, "sequence", 0, U32),
            "arguments": _object(r.get("arguments", {}), "'arguments'"),
            "stages": out_stages, "reply": _object(r.get("reply", {}), "'reply'"),
            "retries": _int(r, "retries", 0, 10_000, default=0)}


__all__ = ["MAX_CHUNKS", "MAX_JSON_BYTES", "MAX_JSON_DEPTH", "MAX_MESSAGE_BYTES", "MAX_STAGES",
           "MAX_TEXT", "SchemaError", "ZMQ_MAX_PART_BYTES", "command", "device", "hello",
           "json_depth", "link"]
