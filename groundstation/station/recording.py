"""One recording of a session: the Recorder on the session's link, its journal, and a
closing record that says why it ended.

The Station starts and stops it; every journal entry of the session (parameter tables,
profiles, generator settings, script marks) goes through `journal()`, which writes
nothing when no recording runs."""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any, Callable

from ..core.contracts import DeviceLink
from ..core.errors import GroundStationError
from ..logs import Recorder
from ..logs.live import attach_recorder
from ..logs.schema import FAST_CHUNK_ROWS, FAST_WRITER_NICENESS
from ..params.upload import ParameterLoader

log = logging.getLogger(__name__)


class RecordingSlot:
    """At most one recording at a time on a session's link; `entries` lists every one
    that ended (name, files, frames, discarded blocks, link drops, how it ended)."""

    def __init__(self, echo: Callable[[str], None]):
        self.echo = echo
        self.recorder: Recorder | None = None
        self.entries: list[dict[str, Any]] = []
        self._detach: Callable[[], None] | None = None
        self._drops_at_start = 0
        self._t0 = 0.0
        #: the log writers started ahead (prepare_ahead), or None
        self.standby = None
        #: the process compressing a fast session's logs behind it (made by its first
        #: recording), or None
        self.compress_behind = None

    @property
    def active(self) -> bool:
        return self.recorder is not None

    def start(self, client: DeviceLink, dictionary, testbed, folder: Path, name: str, notes: str = "",
              on_failure: Callable[[str], None] | None = None, fast: bool = False) -> Path:
        """`fast`: the session runs on the fast simulator, which delivers thousands of
        frames a flush: larger HDF5 chunks (schema.FAST_CHUNK_ROWS), a writer process
        that yields a contended core to the simulator (schema.FAST_WRITER_NICENESS),
        and no deflate in the writer - a log closed cleanly is compressed behind the
        session, off the runs' path (logs/compress_behind.py; `finish_compression`
        waits for it)."""
        assert self.recorder is None, "one recording at a time (the Station checks)"
        rec = Recorder(dictionary, folder, test_name=name, notes=notes,
                       testbed_text=testbed.path.read_text(), testbed_name=testbed.name,
                       testbed_path=str(testbed.path), on_failure=on_failure,
                       chunk_rows=FAST_CHUNK_ROWS if fast else None,
                       writer_niceness=FAST_WRITER_NICENESS if fast else 0,
                       standby=self.standby, compression={} if fast else None)
        if fast and self.compress_behind is None:
            from ..logs.compress_behind import CompressBehind
            self.compress_behind = CompressBehind(echo=self.echo)
            self.compress_behind.prepare()
        path = rec.start()
        try:
            if client is not None:
                self._detach = attach_recorder(client, rec)
        finally:
            # ours from here on, so that a make_safe closes it with its reason even when
            # a Ctrl-C lands in the middle of this step
            self.recorder = rec
        self._drops_at_start = link_drops(client)
        self._t0 = time.monotonic()
        if client is not None:
            # every log carries the table the device runs, whatever was uploaded before
            try:
                active = ParameterLoader(client, dictionary).read_active()
                rec.record("parameter_table", {"source": "active at recording start",
                                               "crc": active.crc}, active.blob)
            except GroundStationError as exc:
                rec.note(f"could not read the active parameter table: {exc}")
        if notes:
            rec.note(notes)
        self.echo(f"recording {path}")
        return path

    def prepare_ahead(self) -> None:
        """Several recordings follow (a campaign's runs): from now on each one's log
        writer process is started ahead, during the recording before it, so a recording
        starts without waiting for a fresh interpreter's imports (logs/standby.py).
        Costs one idle process between recordings."""
        if self.standby is None:
            from ..logs.standby import WriterStandby
            self.standby = WriterStandby()
        self.standby.prepare()

    def close_standby(self) -> None:
        standby, self.standby = self.standby, None
        if standby is not None:
            standby.close()

    def attach(self, client: DeviceLink) -> None:
        """A new link of the same session (a reconnect): the recording goes on on it."""
        if self.recorder is not None and self.recorder.state == "recording":
            self.detach()
            self._detach = attach_recorder(client, self.recorder)

    def detach(self) -> None:
        """The recorder off the link: telemetry, command and link listeners."""
        detach, self._detach = self._detach, None
        if detach is not None:
            detach()

    def stop(self, client: DeviceLink) -> tuple[dict[str, Any], Any]:
        """Close it; returns (entry, RecorderStatus)."""
        rec = self.recorder
        if rec is None:
            raise GroundStationError("stop_recording: nothing is recording")
        self.recorder = None
        self.detach()
        status = rec.stop()
        entry = {"name": rec.test_name, "files": [str(p) for p in status.files],
                 "frames": status.frames, "discarded_blocks": rec.discarded_blocks,
                 "dropped": link_drops(client) - self._drops_at_start,
                 "wall_seconds": round(time.monotonic() - self._t0, 3)}
        self.entries.append(entry)
        if status.removed:
            entry["removed"] = [str(p) for p in status.removed]
            self.echo(status.note)
        elif status.state == "stopped":
            self.echo(f"recorded {status.frames} frames to {', '.join(p.name for p in status.files)}")
        self._compress(status)
        return entry, status

    def close(self, reason: str = "") -> None:
        """Close the recording (if any), its last journal entry saying why: the log then
        explains its own end - an operator's Ctrl-C, a failed step, the end of a script.
        Never raises."""
        rec, self.recorder = self.recorder, None
        if rec is None:
            return
        self.detach()
        why = reason or "end of the session"
        try:
            rec.note(f"recording closed: {why}")
        except Exception:                          # closing must go on regardless
            log.exception("could not note why the recording closes")
        status = rec.stop(reason=why)
        entry = {"name": rec.test_name, "files": [str(p) for p in status.files],
                 "frames": status.frames, "discarded_blocks": rec.discarded_blocks,
                 "state": status.state, "stop_reason": why}
        if status.removed:
            # nothing reached it: say that the file named when it started is gone
            entry["removed"] = [str(p) for p in status.removed]
            self.echo(status.note)
        self.entries.append(entry)
        self._compress(status)

    def _compress(self, status) -> None:
        """A log recorded uncompressed and closed cleanly goes to the compression behind
        the session (a log the writer deflated itself would be skipped there); one that
        ended otherwise stays exactly as recorded (evidence)."""
        compressing = self.compress_behind
        if compressing is not None and status.state == "stopped" and status.files:
            compressing.submit(status.files)

    def finish_compression(self) -> None:
        """Wait for the logs compressed behind the session (Ctrl-C leaves the rest
        uncompressed, whole and readable, and says how to compress them)."""
        compressing, self.compress_behind = self.compress_behind, None
        if compressing is not None:
            compressing.finish()

    def backlog(self) -> float:
        """How full the recorder's queue to its writer is (0..1; 0 when nothing records):
        the fast clock waits above a limit, so the recorder never discards a block."""
        rec = self.recorder
        return rec.queue_fill() if rec is not None else 0.0

    def journal(self, kind: str, record: dict, blob: bytes = b"") -> None:
        rec = self.recorder
        if rec is not None:
            rec.record(kind, record, blob)

    def mark(self, source: str, text: str, **extra: Any) -> None:
        rec = self.recorder
        if rec is not None:
            rec.record("event", {"source": source, "text": text, **extra})


def device_record(simulated: bool, *, address: str = "", seed: int = 0, fast: bool = False,
                  speed: float = 1.0) -> dict:
    """What a log's journal says of the device the session talks to: for the simulated
    testbed, what it takes to run it again the same way (its seed; device time driven by
    the script, or real time at `speed`); for a rig, its address."""
    if simulated:
        # (no address: a loopback port chosen afresh each time, which says nothing)
        return {"device": "simulated testbed", "seed": int(seed),
                "clock": "script (fast)" if fast else f"real time x{speed:g}"}
    return {"device": "rig", "address": address}


def link_drops(client: DeviceLink) -> int:
    """Frames lost on the link so far (sequence gaps, every packet)."""
    if client is None:
        return 0
    return sum(ps.dropped for ps in client.stats.snapshot().packets.values())
