"""What every check gets: the dictionary, the session host, second hosts on demand,
decoded telemetry views, and the verdict it builds (PASS/FAIL/SKIP with evidence)."""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Any, Callable

from ..codec.frames import decode_items
from ..core.dictionary import Dictionary
from ..link.address import DeviceAddress
from .probe import Exchange, Host

PASS, FAIL, SKIP = "PASS", "FAIL", "SKIP"
READ_BLOCK = 1000           # PARAM_READ count is 1 ... 1000 (commands.toml)
WRITE_BLOCK = 1014          # max_payload_bytes - 10 (§11.1)


class Skip(Exception):
    """A check cannot run here (serial link, motion not allowed, ...): the reason."""


@dataclass
class Verdict:
    """Evidence lines and the expectations that failed."""

    lines: list[str] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)

    def note(self, text: str) -> None:
        self.lines.append(text)

    def expect(self, ok: bool, text: str) -> bool:
        """Record an expectation of the SPEC: `text` says what was expected and seen."""
        self.lines.append(("ok   " if ok else "FAIL ") + text)
        if not ok:
            self.failures.append(text)
        return ok


@dataclass
class Result:
    section: str
    title: str
    status: str
    lines: list[str]
    seconds: float = 0.0

    @property
    def name(self) -> str:
        return f"{self.section} {self.title}"


class Context:
    def __init__(self, dictionary: Dictionary, address: DeviceAddress, *, allow_motion: bool,
                 host: Host):
        self.d = dictionary
        self.address = address
        self.allow_motion = allow_motion
        self.host = host
        self.errors = {v: k for k, v in dictionary.error_codes.items()}
        self.events = {v: k for k, v in dictionary.event_codes.items()}
        self.ids = {p.name: p.id for p in dictionary.packets}
        self.hr = dictionary.packet("HIGH_RATE")
        self.hk = dictionary.packet("HOUSEKEEPING")
        self.rate = dictionary.control_rate_hz
        self._others: list[Host] = []
        #: the parameter table as found at the start (bytes) and its version
        self.found_table: bytes | None = None
        self.found_version: int | None = None

    # ------------------------------------------------------------------ hosts
    def other_host(self, *, udp: bool = False) -> Host:
        """A second host: its own TCP connection, so another host as §7 defines it.
        A serial link has one stream only: such checks SKIP there."""
        if self.address.kind != "tcp":
            raise Skip("a serial link has a single host; §7's other hosts need TCP")
        h = Host(self.d, self.address, udp=udp, counter=self.host._arrivals)
        self._others.append(h)
        return h

    @property
    def all_hosts(self) -> list[Host]:
        """This run's session host and the second hosts open now."""
        return [self.host] + self._others

    def close_others(self) -> None:
        for h in self._others:
            h.close()
        self._others.clear()

    def ensure_session(self) -> None:
        """Own the session again (after a take-over test), or say why not."""
        ex = self.host.exchange("HEARTBEAT", {})
        if ex.final is not None and ex.final.stage == 3:
            return
        ex = self.host.connect(take_over=True)
        if ex.final is None or ex.final.stage != 3:
            raise RuntimeError(f"cannot take the session back: CONNECT {self.outcome(ex)}")

    def outcome(self, ex: Exchange) -> str:
        return ex.outcome(self.errors)

    def stages(self, ex: Exchange) -> list[tuple[str, str]]:
        return [(s.name, self.errors.get(s.reason, str(s.reason))) for s in ex.stages]

    def is_ok(self, ex: Exchange) -> bool:
        return [s.stage for s in ex.stages] == [1, 3]

    def refused(self, ex: Exchange, stage: int, reason: str) -> bool:
        return bool(ex.stages) and ex.final.stage == stage \
            and ex.final.reason == self.d.error_codes[reason]

    # ------------------------------------------------------------------ telemetry
    def decode(self, frame, packet: str) -> dict[str, Any]:
        pkt = self.d.packet(packet)
        values = decode_items(pkt.items, frame.payload, packet)
        for item in pkt.items:
            for flag, bit in item.bits.items():
                values[flag] = bool((int(values[item.name]) >> bit) & 1)
        values["tick"] = frame.tick
        values["sequence"] = frame.sequence
        return values

    def high_rate_after(self, mark: int, match: Callable[[dict], bool], timeout: float
                        ) -> dict | None:
        """The first HIGH_RATE frame after `mark` whose decoded values match."""
        pid = self.ids["HIGH_RATE"]
        f = self.host.wait_frame(lambda f: f.packet_id == pid and match(self.decode(f, "HIGH_RATE")),
                                 mark, timeout)
        return None if f is None else self.decode(f, "HIGH_RATE")

    def housekeeping_after(self, tick: int, timeout: float = 3.0) -> dict | None:
        """The first HOUSEKEEPING frame produced after device tick `tick`."""
        pid = self.ids["HOUSEKEEPING"]
        f = self.host.wait_frame(lambda f: f.packet_id == pid and _after(f.tick, tick), 0, timeout)
        return None if f is None else self.decode(f, "HOUSEKEEPING")

    def latest_tick(self, timeout: float = 2.0) -> int:
        """The tick of a HIGH_RATE frame arriving from now on (device time)."""
        f = self.host.wait_frame(lambda f: f.packet_id == self.ids["HIGH_RATE"],
                                 self.host.mark(), timeout)
        if f is None:
            raise RuntimeError("no HIGH_RATE frame arrives: telemetry is not flowing")
        return f.tick

    def events_since(self, mark: int, name: str) -> list[dict]:
        code = self.d.event_codes[name]
        out = []
        for f in self.host.since(mark, self.ids["EVENT"]):
            v = self.decode(f, "EVENT")
            if v["code"] == code:
                out.append(v)
        return out

    def wait_event(self, mark: int, name: str, timeout: float = 2.0) -> dict | None:
        code = self.d.event_codes[name]
        pid = self.ids["EVENT"]
        f = self.host.wait_frame(lambda f: f.packet_id == pid
                                 and int.from_bytes(f.payload[1:3], "big") == code, mark, timeout)
        return None if f is None else self.decode(f, "EVENT")

    # ------------------------------------------------------------------ parameter table
    def table_size(self) -> int:
        return sum(p.size for p in self.d.parameters)

    def read_table(self) -> bytes:
        out = bytearray()
        size = self.table_size()
        while len(out) < size:
            count = min(READ_BLOCK, size - len(out))
            ex = self.host.exchange("PARAM_READ", {"offset": len(out), "count": count})
            if not self.is_ok(ex):
                raise RuntimeError(f"PARAM_READ offset {len(out)}: {self.outcome(ex)}")
            out += self.host.reply(ex, "PARAM_READ")["data"]
        return bytes(out)

    def upload_table(self, blob: bytes, version: int, crc: int | None = None
                     ) -> tuple[list[Exchange], Exchange]:
        """PARAM_BEGIN, PARAM_WRITE blocks, PARAM_COMMIT: (begin+writes, commit)."""
        steps = [self.host.exchange("PARAM_BEGIN", {"table_version": version,
                                                    "table_length": len(blob)})]
        for off in range(0, len(blob), WRITE_BLOCK):
            steps.append(self.host.exchange("PARAM_WRITE", {"offset": off,
                                                            "data": blob[off:off + WRITE_BLOCK]}))
        commit = self.host.exchange("PARAM_COMMIT", {
            "table_crc": zlib.crc32(blob) if crc is None else crc})
        return steps, commit

    def table_unchanged(self, v: Verdict, what: str) -> None:
        """After a refusal: the active table is still the one found (read-back, HK)."""
        blob = self.read_table()
        if not v.expect(blob == self.found_table, f"after {what}: read-back of the active table "
                        f"equals the table found (CRC 0x{zlib.crc32(blob):08X}, found "
                        f"0x{zlib.crc32(self.found_table):08X})"):
            # put it back now, so the checks after this one run on the table found
            _, commit = self.upload_table(self.found_table, self.found_version or 0)
            v.note(f"the found table committed again: {self.outcome(commit)}")

    # ------------------------------------------------------------------ safety
    def require_motion(self) -> None:
        if not self.allow_motion:
            raise Skip("moves the rig (arming, profiles or currents): run with --allow-motion")

    def make_safe(self) -> None:
        """ABORT (anyone, always, §9.2), then DISARM to acknowledge a latched fault."""
        self.host.exchange("ABORT", {})
        self.host.exchange("DISARM", {})


def _after(tick: int, ref: int) -> bool:
    """tick is later than ref on the wrapping u32 tick axis."""
    return 0 < ((tick - ref) & 0xFFFFFFFF) < 0x80000000

