"""Putting a parameter table on the device and proving it is there.

The sequence (SPEC.md §11.1): check the table here, read the active table back (it
becomes the rollback point), PARAM_BEGIN, the table in PARAM_WRITE blocks, PARAM_COMMIT
with the CRC-32 of the whole table (the device checks the CRC and validates the table
again, then activates it between two control periods), read the active table back and
compare it byte for byte and entry by entry, and wait for HOUSEKEEPING to report the new
CRC.  Only then is the upload "verified" and added to the history.

No Qt here: the CLI, the GUI's parameter panel and campaigns use the same class.
"""

from __future__ import annotations

import json
import os
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from ..core.contracts import DeviceLink
from ..core.dictionary import Dictionary
from ..core.errors import CommandFailed, CommandRejected, GroundStationError
from . import table as ptable
from .clearance import Clearance

#: how long HOUSEKEEPING (10 Hz) may take to show the new CRC after the commit
HOUSEKEEPING_WAIT_S = 3.0

#: what a device's refusal means for an operator
_REASON_ADVICE = {
    "INVALID_STATE": "the device refuses to change its table while armed - disarm first",
    "CRC_MISMATCH": "the table arrived corrupted (CRC mismatch); the previous table stays active - upload again",
    "VALIDATION_FAILED": "the device's own validation refused the table; the previous table stays active",
    "OUT_OF_RANGE": "the device expects a table of another size - are host and device on the same protocol?",
    "NOTHING_STAGED": "the device lost the staged table (another upload or a reboot?) - upload again",
}


class UploadError(GroundStationError):
    """An upload did not end with the table verified on the device."""


class VerifyError(UploadError):
    """The device reports a table other than the one sent."""


class NotClearedError(UploadError):
    """A table offered for upload without a Clearance for exactly its bytes."""


@dataclass
class ActiveTable:
    """A parameter table as read from the device."""

    blob: bytes
    crc: int
    values: dict[str, Any]

    @classmethod
    def from_blob(cls, dictionary: Dictionary, blob: bytes) -> "ActiveTable":
        return cls(blob, ptable.table_crc(blob), ptable.unpack(dictionary, blob))


@dataclass
class UploadRecord:
    """One verified upload (what the history and the log keep)."""

    time: float                     # s since the epoch, when it was verified
    source: str                     # design file, "edited in the GUI", "rollback to ..."
    version: int                    # table_version given at PARAM_BEGIN
    crc: int
    previous_crc: int
    activated_tick: int
    device: str = ""                # the device's GET_INFO description
    notes: list[str] = field(default_factory=list)
    #: the upload gate (clearance.py): validated, or the override's reason and the
    #: problems it overrode.  A rollback re-activates a table the device ran before.
    validated: bool = True
    override_reason: str = ""
    validation_problems: list[str] = field(default_factory=list)
    #: what the override accepted: "marginal" (a stable loop below the margin limits, the
    #: shortfalls in validation_problems), "refused" (what validation refused), "" none
    accepted_risk: str = ""
    #: where the device was reached (DeviceIdentity.address); with `device`, which device
    #: the table went to.  "" in records written before the history was kept per device
    device_address: str = ""

    @property
    def identity(self) -> "DeviceIdentity | None":
        return DeviceIdentity(self.device_address, self.device) if self.device_address else None


@dataclass(frozen=True)
class DeviceIdentity:
    """Which device a table went to: where it was reached and what it says it is.

    The protocol gives a device no serial number; GET_INFO's description names its
    firmware and testbed (the simulator: its testbed file), and the address tells apart
    two devices that describe themselves alike (two simulators of one testbed file).
    Both must match for one device's uploads to count as another's history: a history
    compared with the wrong device's table says "not the active table" of a table that
    was never sent there."""

    address: str
    description: str

    def text(self) -> str:
        return f"{self.address} ({self.description})" if self.description else self.address


def device_identity(client: DeviceLink) -> DeviceIdentity:
    """The identity of the device at the other end of `client` (one GET_INFO)."""
    link = getattr(client, "command_link", None)
    peer = getattr(link, "peer", None)
    # the peer as the socket sees it: "localhost:5020" and "127.0.0.1:5020" are one device
    address = (f"tcp://{peer[0]}:{peer[1]}" if peer else
               str(getattr(link, "name", "") or getattr(client, "address", "") or "device"))
    description = str(client.command("GET_INFO").reply.get("description", "")).strip()
    return DeviceIdentity(address, description)


def entry_differences(dictionary: Dictionary, a: Mapping[str, Any], b: Mapping[str, Any]) -> list[str]:
    """Names of the entries whose values differ (bit for bit: NaN equals NaN, -0 differs
    from +0 only where the wire bytes differ, which pack() decides)."""
    out = []
    for p in dictionary.parameters:
        if p.name not in a or p.name not in b:
            out.append(p.name)
            continue
        x = np.asarray(a[p.name], dtype=p.dtype)
        y = np.asarray(b[p.name], dtype=p.dtype)
        if x.shape != y.shape or x.tobytes() != y.tobytes():
            out.append(p.name)
    return out


class ParameterHistory:
    """Verified uploads kept on disk, so a rollback works from a new program run too.

    folder/history.jsonl holds one UploadRecord per line; folder/tables/<crc>.bin the
    table bytes (content-addressed: a table uploaded twice is stored once)."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)

    @staticmethod
    def default_folder() -> Path:
        base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
        return Path(base) / "groundstation" / "parameter_history"

    def add(self, record: UploadRecord, blob: bytes, previous_blob: bytes) -> None:
        tables = self.folder / "tables"
        tables.mkdir(parents=True, exist_ok=True)
        for b in (blob, previous_blob):
            path = tables / f"{ptable.table_crc(b):08x}.bin"
            if not path.exists():
                tmp = path.with_suffix(".tmp")
                tmp.write_bytes(b)
                os.replace(tmp, path)          # never a half-written table under its CRC's name
        with open(self.folder / "history.jsonl", "a", encoding="utf-8") as f:
            f.write(json.dumps(asdict(record)) + "\n")
            f.flush()
            os.fsync(f.fileno())

    def records(self) -> list[UploadRecord]:
        path = self.folder / "history.jsonl"
        if not path.exists():
            return []
        out = []
        for line in path.read_text(encoding="utf-8").splitlines():
            try:
                out.append(UploadRecord(**json.loads(line)))
            except (ValueError, TypeError):
                continue                       # a line cut short by a crash: skip it
        return out

    def table(self, crc: int) -> bytes:
        path = self.folder / "tables" / f"{crc:08x}.bin"
        try:
            blob = path.read_bytes()
        except OSError as exc:
            raise UploadError(f"{path}: stored table missing ({exc.strerror})") from None
        if ptable.table_crc(blob) != crc:
            raise UploadError(f"{path}: stored table is damaged (CRC {ptable.table_crc(blob):08x}, "
                              f"expected {crc:08x})")
        return blob


class MemoryHistory:
    """The same as ParameterHistory, for this program run only (no folder given)."""

    def __init__(self) -> None:
        self._records: list[UploadRecord] = []
        self._tables: dict[int, bytes] = {}

    def add(self, record: UploadRecord, blob: bytes, previous_blob: bytes) -> None:
        for b in (blob, previous_blob):
            self._tables[ptable.table_crc(b)] = b
        self._records.append(record)

    def records(self) -> list[UploadRecord]:
        return list(self._records)

    def table(self, crc: int) -> bytes:
        try:
            return self._tables[crc]
        except KeyError:
            raise UploadError(f"no table with CRC {crc:08x} was uploaded in this run") from None


class DeviceHistory:
    """One device's part of a history (ParameterHistory or MemoryHistory): the records
    of uploads to that device only, and new records stamped with its identity.  The
    tables stay shared (content-addressed by CRC)."""

    def __init__(self, store: "ParameterHistory | MemoryHistory", identity: DeviceIdentity):
        self.store = store
        self.identity = identity

    def add(self, record: UploadRecord, blob: bytes, previous_blob: bytes) -> None:
        record.device_address, record.device = self.identity.address, self.identity.description
        self.store.add(record, blob, previous_blob)

    def records(self) -> list[UploadRecord]:
        return [r for r in self.store.records() if r.identity == self.identity]

    def other_records(self) -> list[UploadRecord]:
        """The store's records of other devices, and those that name none (older ones)."""
        return [r for r in self.store.records() if r.identity != self.identity]

    def table(self, crc: int) -> bytes:
        return self.store.table(crc)


ROLLBACK_SOURCE = "rollback"


def _when(t: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(t))


@dataclass
class Provenance:
    """What the history knows about one table (by CRC): the one answer `params show` and
    `params rollback` both give, so they cannot contradict each other."""

    crc: int
    activated_by: UploadRecord | None = None    # newest record that made it active (upload or rollback)
    uploaded_by: UploadRecord | None = None     # newest upload of it that was not a rollback
    replaced_by: UploadRecord | None = None     # newest upload made while it was the active table

    @property
    def known(self) -> bool:
        return any((self.activated_by, self.uploaded_by, self.replaced_by))

    @property
    def rollback_target(self) -> int | None:
        """The table a rollback from this one re-activates: the one active before the
        upload that made it (rollbacks skipped, so rolling back twice goes two back)."""
        return self.uploaded_by.previous_crc if self.uploaded_by is not None else None

    def text(self) -> str:
        """One line: where this table came from, as far as this history knows."""
        crc = f"{self.crc:08x}"
        a, u, r = self.activated_by, self.uploaded_by, self.replaced_by
        if a is None and r is None:
            return f"table {crc} was not uploaded from here (not in this history)"
        parts = []
        if a is not None:
            parts.append(f"put there from here at {_when(a.time)} by "
                         + (a.source if a.source.startswith(ROLLBACK_SOURCE) else f"an upload of {a.source}"))
        if u is not None and u is not a:
            parts.append(f"first uploaded from here as {u.source} at {_when(u.time)}")
        if u is None and r is not None:
            parts.append(f"it was the device's table when {r.source} was uploaded at "
                         f"{_when(r.time)}; it was never uploaded from here as a design")
        return f"table {crc}: " + "; ".join(parts)


def provenance(records: list[UploadRecord], crc: int) -> Provenance:
    """What `records` (oldest first, as history.records() gives them) say about table `crc`."""
    out = Provenance(crc)
    for rec in reversed(records):
        if rec.crc == crc:
            if out.activated_by is None:
                out.activated_by = rec
            # a rollback, or an upload of the table that was already active, made nothing
            # new: the table to go back to is the one before the upload that changed it
            if out.uploaded_by is None and not rec.source.startswith(ROLLBACK_SOURCE) \
                    and rec.previous_crc != crc:
                out.uploaded_by = rec
        if rec.previous_crc == crc and rec.crc != crc and out.replaced_by is None:
            out.replaced_by = rec
    return out


class ParameterLoader:
    """Uploads, reads back and rolls back parameter tables through a DeviceClient."""

    def __init__(self, client: DeviceLink, dictionary: Dictionary, history: ParameterHistory | None = None,
                 journal: Callable[[str, dict, bytes], None] | None = None,
                 active_table_seen: Callable[[], tuple[int, int] | None] | None = None,
                 reports_between_steps: bool = True):
        self.client = client
        #: (version, CRC) of the active table from the HOUSEKEEPING a subscriber of this
        #: link saw last, or None: spares waiting for the next report before an upload -
        #: which on a simulated device held between steps (fast campaigns) never comes,
        #: so each upload used to wait out HOUSEKEEPING_WAIT_S of wall time for it
        self.active_table_seen = active_table_seen
        #: False: the device's time stands still until a command moves it (a simulated
        #: device held between steps), so no HOUSEKEEPING comes on its own - an upload
        #: that has seen none does not wait for one (the device then runs its first table,
        #: version 0, as a simulated device does from its start)
        self.reports_between_steps = reports_between_steps
        self.d = dictionary
        #: every device's uploads; `history` is the part of this loader's device
        self.store = history if history is not None else MemoryHistory()
        self._history: DeviceHistory | None = None
        #: called with ("parameter_table", record, table bytes) after each verified upload
        self.journal = journal
        self.last_uploaded: UploadRecord | None = None
        self.write_block = dictionary.max_payload - 10  # token, opcode, offset
        count = next(i for i in dictionary.command("PARAM_READ").args if i.name == "count")
        self.read_block = int(count.value_range[1]) if count.value_range else 512

    @property
    def history(self) -> DeviceHistory:
        """The uploads to this loader's device (asked for its identity once, when first
        needed: a loader that only reads the table sends no GET_INFO)."""
        if self._history is None:
            self._history = DeviceHistory(self.store, device_identity(self.client))
        return self._history

    # ------------------------------------------------------------------ reading
    def read_active(self, progress: Callable[[str, float], None] | None = None) -> ActiveTable:
        size = ptable.table_size(self.d)
        parts = []
        for off in range(0, size, self.read_block):
            n = min(self.read_block, size - off)
            reply = self.client.command("PARAM_READ", offset=off, count=n).reply
            data = bytes(reply["data"])
            if reply["offset"] != off or len(data) != n:
                raise UploadError(f"PARAM_READ at {off}: the device sent {len(data)} bytes at "
                                  f"offset {reply['offset']}, not {n} at {off}")
            parts.append(data)
            if progress:
                progress("read back", (off + n) / size)
        return ActiveTable.from_blob(self.d, b"".join(parts))

    # ------------------------------------------------------------------ uploading
    def upload(self, values: Mapping[str, Any], source: str = "",
               progress: Callable[[str, float], None] | None = None, *,
               clearance: Clearance | None = None) -> UploadRecord:
        """Send a complete table and verify it; raise UploadError (or ParameterError
        for a table refused here) on anything short of verified.

        `clearance` (clearance.py) must clear exactly this table: validated against its
        design, or overridden with a recorded reason.  Without one nothing is sent."""
        problems = ptable.problems(self.d, values)
        if problems:
            raise ptable.ParameterError("table refused before sending: " + "; ".join(problems))
        blob = ptable.pack(self.d, values)
        if not isinstance(clearance, Clearance):
            raise NotClearedError(
                f"{source or 'table'}: refused, nothing sent: the table has not been validated "
                f"(clear it with clear_design(design, values, dictionary), or give the reason to "
                f"send it unvalidated with override_table(values, dictionary, reason))")
        crc = ptable.table_crc(blob)
        if clearance.table_crc != crc:
            raise NotClearedError(
                f"{source or 'table'}: refused, nothing sent: the clearance is for table "
                f"{clearance.table_crc:08x}, this table is {crc:08x} (changed after validation?)")
        return self._upload_blob(blob, source, progress, clearance.record())

    def _upload_blob(self, blob: bytes, source: str,
                     progress: Callable[[str, float], None] | None,
                     gate: Mapping[str, Any] | None = None) -> UploadRecord:
        crc = ptable.table_crc(blob)
        # who the device is, asked before anything is sent: a verified upload must not
        # miss its history record because the question failed afterwards
        history = self.history
        waiter = _HousekeepingWaiter(self.client, crc)
        try:
            previous = self.read_active()
            # the new table's version follows the active one's (HOUSEKEEPING reports it);
            # a report already seen counts when it is of the table just read back (the
            # device changes tables only on a commit, and only the session's owner commits)
            seen = self.active_table_seen() if self.active_table_seen is not None else None
            if seen is not None and seen[1] == previous.crc:
                active_version = seen[0]
            elif self.reports_between_steps:
                active_version = waiter.wait_any(HOUSEKEEPING_WAIT_S)
            else:
                active_version = 0
            version = ((active_version or 0) + 1) & 0xFFFF or 1
            self._command("PARAM_BEGIN", table_version=version, table_length=len(blob))
            for off in range(0, len(blob), self.write_block):
                self._command("PARAM_WRITE", offset=off, data=blob[off:off + self.write_block])
                if progress:
                    progress("upload", min(1.0, (off + self.write_block) / len(blob)))
            reply = self._command("PARAM_COMMIT", table_crc=crc).reply
            if reply["table_crc"] != crc:
                raise VerifyError(f"PARAM_COMMIT: the device activated a table with CRC "
                                  f"{reply['table_crc']:08x}, not the {crc:08x} sent")
            back = self.read_active(progress)
            if back.blob != blob:
                sent = ptable.unpack(self.d, blob)
                differ = entry_differences(self.d, sent, back.values)
                raise VerifyError("read-back differs from the table sent in: "
                                  + ", ".join(differ or ["(padding bytes)"]))
            hk_crc = waiter.wait(HOUSEKEEPING_WAIT_S)
            if hk_crc != crc:
                raise VerifyError(f"HOUSEKEEPING reports active table CRC "
                                  f"{'none' if hk_crc is None else format(hk_crc, '08x')} "
                                  f"{HOUSEKEEPING_WAIT_S:g} s after the commit, expected {crc:08x}")
        finally:
            waiter.close()
        record = UploadRecord(time=time.time(), source=source, version=version, crc=crc,
                              previous_crc=previous.crc, activated_tick=int(reply["tick"]))
        if gate is not None:
            record.validated = bool(gate["validated"])
            record.override_reason = str(gate["override_reason"])
            record.validation_problems = list(gate["validation_problems"])
            record.accepted_risk = str(gate.get("accepted_risk", ""))
        self.last_uploaded = record
        history.add(record, blob, previous.blob)
        if self.journal is not None:
            self.journal("parameter_table", asdict(record), blob)
        return record

    def rollback(self, progress: Callable[[str, float], None] | None = None) -> UploadRecord:
        """Re-activate the table that was active before the upload that made the active
        one.  Rollbacks are skipped when looking for that upload, so a second rollback
        goes one table further back instead of undoing the first."""
        active = self.read_active()
        origin = provenance(self.history.records(), active.crc)
        target = origin.rollback_target
        if target is None:
            if not origin.known:
                raise UploadError(f"nothing to roll back to: the device's active table "
                                  f"(CRC {active.crc:08x}) was not uploaded from here, and no "
                                  f"upload from here replaced it")
            raise UploadError(f"nothing further to roll back to: the device's active {origin.text()}; "
                              f"the history holds no table that was active before it")
        if target == active.crc:
            raise UploadError(f"the previous table is the active one (CRC {active.crc:08x})")
        blob = self.history.table(target)
        return self._upload_blob(blob, f"{ROLLBACK_SOURCE} from {active.crc:08x} to {target:08x}",
                                 progress)

    # ------------------------------------------------------------------ helpers
    def _command(self, name: str, **args: Any):
        try:
            return self.client.command(name, **args)
        except (CommandRejected, CommandFailed) as exc:
            reason = getattr(exc, "reason", "")
            advice = _REASON_ADVICE.get(reason, "")
            raise UploadError(f"{exc}" + (f": {advice}" if advice else "")) from exc


class _HousekeepingWaiter:
    """Watches HOUSEKEEPING for the active-table CRC from before the commit on, so a
    report that arrives between the commit and the read-back is not missed."""

    def __init__(self, client: DeviceLink, crc: int):
        self.client = client
        self.crc = crc
        self.latest: int | None = None
        self.latest_version: int | None = None
        self._seen = threading.Event()
        self._any = threading.Event()
        client.subscribe(self)

    def __call__(self, block) -> None:
        if block.name != "HOUSEKEEPING" or not len(block):
            return
        self.latest = int(block["param_table_crc"][-1])
        self.latest_version = int(block["param_table_version"][-1])
        self._any.set()
        if self.latest == self.crc:
            self._seen.set()

    def wait_any(self, timeout: float) -> int | None:
        """The active table's version from the next HOUSEKEEPING (None if none came)."""
        self._any.wait(timeout)
        return self.latest_version

    def wait(self, timeout: float) -> int | None:
        self._seen.wait(timeout)
        return self.latest

    def close(self) -> None:
        unsubscribe = getattr(self.client, "unsubscribe", None)
        if unsubscribe is not None:
            unsubscribe(self)

