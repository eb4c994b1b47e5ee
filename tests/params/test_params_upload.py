"""Parameter upload to the simulated device: verify, read back, roll back, refuse."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.core.errors import CommandFailed
from groundstation.link import open_client
from groundstation.params import table as ptable
from groundstation.params.clearance import override_table
from groundstation.params.upload import (ParameterHistory, ParameterLoader, UploadError,
                                         entry_differences)
from groundstation.sim import SimulatedDevice


@pytest.fixture
def live(dictionary):
    """A device running in real time (HOUSEKEEPING at 10 Hz confirms each commit)."""
    dev = SimulatedDevice(dictionary, pacing="realtime", seed=3, speed=4.0).start()
    c = open_client(dictionary, f"127.0.0.1:{dev.tcp_port}", heartbeat=True)
    c.connect()
    yield dev, c
    c.close()
    dev.stop()


def cleared(dictionary, values):
    """These tests exercise the loader's mechanics on hand-made tables (no design to
    validate against): cleared by the recorded override, as a bench engineer would."""
    return override_table(values, dictionary, "test of the loader's mechanics")


def send(loader, values, source: str = ""):
    return loader.upload(values, source, clearance=cleared(loader.d, values))


def changed_table(dictionary, **changes):
    values = ptable.default_values(dictionary)
    values.update(changes)
    return values


def test_upload_is_verified_journaled_and_kept_in_the_history(dictionary, live, tmp_path):
    dev, client = live
    journal = []
    loader = ParameterLoader(client, dictionary, ParameterHistory(tmp_path / "hist"),
                             journal=lambda kind, rec, blob: journal.append((kind, rec, blob)))
    before = loader.read_active()
    values = changed_table(dictionary, outer_loop_gain=20.0, saturation_fine=12.5)
    steps = []
    record = loader.upload(values, source="test table", progress=lambda s, f: steps.append(s),
                           clearance=cleared(dictionary, values))
    blob = ptable.pack(dictionary, values)
    assert record.crc == ptable.table_crc(blob) and record.previous_crc == before.crc
    assert {"upload", "read back"} <= set(steps)
    active = loader.read_active()
    assert active.blob == blob                                  # bit for bit
    assert dev.firmware.param_crc == record.crc
    assert set(entry_differences(dictionary, before.values, active.values)) == {
        "saturation_fine", "outer_loop_gain"}
    assert journal and journal[0][0] == "parameter_table" and journal[0][2] == blob
    assert journal[0][1]["source"] == "test table" and journal[0][1]["crc"] == record.crc
    hist = ParameterHistory(tmp_path / "hist")
    assert [r.crc for r in hist.records()] == [record.crc]
    assert hist.table(record.crc) == blob and hist.table(before.crc) == before.blob
    again = send(loader, changed_table(dictionary, outer_loop_gain=21.0))
    assert again.version == (record.version + 1) & 0xFFFF


def test_rollback_restores_the_previous_table_even_from_a_new_program_run(dictionary, live, tmp_path):
    dev, client = live
    loader = ParameterLoader(client, dictionary, ParameterHistory(tmp_path))
    original = loader.read_active()
    first = send(loader, changed_table(dictionary, outer_loop_gain=11.0), source="a")
    send(loader, changed_table(dictionary, outer_loop_gain=12.0), source="b")
    back = loader.rollback()
    assert back.crc == first.crc and loader.read_active().crc == first.crc
    # a new run (the CLI) knows only the history on disk
    fresh = ParameterLoader(client, dictionary, ParameterHistory(tmp_path))
    fresh.rollback()
    assert fresh.read_active().blob == original.blob
    nowhere = ParameterLoader(client, dictionary, ParameterHistory(tmp_path / "empty"))
    with pytest.raises(UploadError, match="nothing to roll back to"):
        nowhere.rollback()


def test_a_nan_is_refused_before_anything_is_sent(dictionary, live):
    dev, client = live
    sent = []
    client.add_command_listener(lambda result: sent.append(result.name))
    loader = ParameterLoader(client, dictionary)
    sos = np.array(ptable.default_values(dictionary)["inertial_c0"], dtype=float)
    sos[3, 1] = np.nan
    with pytest.raises(ptable.ParameterError, match="inertial_c0"):
        send(loader, changed_table(dictionary, inertial_c0=sos))
    assert not [n for n in sent if n.startswith("PARAM")]


def test_a_corrupted_block_fails_the_commit_and_the_previous_table_stays(dictionary, live):
    dev, client = live
    loader = ParameterLoader(client, dictionary)
    before = loader.read_active()
    blob = bytearray(ptable.pack(dictionary, changed_table(dictionary, outer_loop_gain=30.0)))
    crc = ptable.table_crc(bytes(blob))
    blob[100] ^= 0x40                                         # one bit flipped on the way
    client.command("PARAM_BEGIN", table_version=9, table_length=len(blob))
    for off in range(0, len(blob), loader.write_block):
        client.command("PARAM_WRITE", offset=off, data=bytes(blob[off:off + loader.write_block]))
    with pytest.raises(CommandFailed, match="CRC_MISMATCH"):
        client.command("PARAM_COMMIT", table_crc=crc)
    assert loader.read_active().blob == before.blob


def test_the_device_refuses_an_unstable_controller_sent_raw(dictionary, live):
    """A table that skips the local checks (another host, a bug) is refused by the
    device's own validation, and the previous table stays active."""
    dev, client = live
    loader = ParameterLoader(client, dictionary)
    before = loader.read_active()
    sos = np.array(ptable.default_values(dictionary)["relative_c0"], dtype=float)
    sos[0] = [1.0, 0.0, 0.0, 1.0, -2.5, 1.2]                   # poles at 1.85 and 0.65
    values = changed_table(dictionary, relative_c0=sos)
    assert ptable.problems(dictionary, values)                 # the local check would refuse it
    raw = np.zeros(1, ptable.table_dtype(dictionary))       # packed without pack()'s checks
    for p in dictionary.parameters:
        raw[p.name] = values[p.name]
    with pytest.raises(UploadError, match="VALIDATION_FAILED"):
        loader._upload_blob(raw.tobytes(), "raw", None)
    assert loader.read_active().blob == before.blob


def test_an_armed_device_keeps_its_table_and_says_why(dictionary, live):
    dev, client = live
    loader = ParameterLoader(client, dictionary)
    before = loader.read_active()
    client.command("SET_MODE", mode="OPEN_LOOP")
    client.command("ARM")
    with pytest.raises(UploadError, match="disarm first"):
        send(loader, changed_table(dictionary, outer_loop_gain=5.0))
    client.command("DISARM")
    assert loader.read_active().blob == before.blob
