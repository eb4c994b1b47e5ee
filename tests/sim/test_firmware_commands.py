"""Parameter and profile upload through the real client and simulated device, and the
mode/arming rules of the firmware."""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from conftest import wait_for
from groundstation.core.errors import CommandFailed, CommandRejected
from groundstation.params import table as ptable


def upload(client, dictionary, values, version=3, corrupt_crc=False):
    blob = ptable.pack(dictionary, values) if isinstance(values, dict) else values
    client.command("PARAM_BEGIN", table_version=version, table_length=len(blob))
    for off in range(0, len(blob), 700):                # several blocks on purpose
        client.command("PARAM_WRITE", offset=off, data=blob[off:off + 700])
    crc = zlib.crc32(blob) ^ (1 if corrupt_crc else 0)
    return client.command("PARAM_COMMIT", table_crc=crc), blob


def read_back(client, size):
    out = b""
    while len(out) < size:
        out += client.command("PARAM_READ", offset=len(out), count=min(1000, size - len(out))).reply["data"]
    return out


def test_parameter_table_upload_commit_and_read_back(client, device, dictionary):
    client.connect()
    values = ptable.default_values(dictionary)
    values["outer_loop_gain"] = 12.5
    values["watchdog_timeout"] = 0.5
    result, blob = upload(client, dictionary, values)
    assert result.reply["table_crc"] == zlib.crc32(blob)
    assert read_back(client, len(blob)) == blob
    assert ptable.unpack(dictionary, read_back(client, len(blob)))["outer_loop_gain"] == 12.5
    assert device.firmware.params["watchdog_timeout"] == pytest.approx(0.5)
    blocks = []
    client.subscribe(blocks.append)
    device.run_ticks(120)
    wait_for(lambda: any(b.name == "HOUSEKEEPING" for b in blocks))
    hk = [b for b in blocks if b.name == "HOUSEKEEPING"][-1]
    assert hk["param_table_crc"][-1] == zlib.crc32(blob) and hk["param_table_version"][-1] == 3


def test_a_table_with_a_wrong_crc_or_bad_values_is_not_activated(client, device, dictionary):
    client.connect()
    before = device.firmware.param_crc
    values = ptable.default_values(dictionary)
    with pytest.raises(CommandFailed) as err:
        upload(client, dictionary, values, corrupt_crc=True)
    assert err.value.reason == "CRC_MISMATCH"
    # out-of-range value packed by hand (the host-side pack() would refuse it)
    rec = np.zeros(1, ptable.table_dtype(dictionary))
    for k, v in values.items():
        rec[k] = v
    rec["saturation_coarse"] = 500.0
    with pytest.raises(CommandFailed) as err:
        upload(client, dictionary, rec.tobytes())
    assert err.value.reason == "VALIDATION_FAILED"
    assert device.firmware.param_crc == before
    with pytest.raises(ptable.ParameterError, match="saturation_coarse"):
        ptable.pack(dictionary, {**values, "saturation_coarse": 500.0})


def test_commit_is_refused_while_armed(client, dictionary):
    client.connect()
    client.command("SET_MODE", mode="OPEN_LOOP")
    client.command("ARM")
    with pytest.raises(CommandRejected) as err:
        upload(client, dictionary, ptable.default_values(dictionary))
    assert err.value.reason == "INVALID_STATE"


def test_profile_plays_sample_exact(client, device, dictionary):
    blocks = []
    client.subscribe(blocks.append)
    client.connect()
    client.command("SET_MODE", mode="OPEN_LOOP")
    client.command("ARM")
    samples = (0.01 * np.sin(np.arange(300) / 20.0)).astype(">f4")
    raw = samples.tobytes()
    client.command("PROFILE_BEGIN", profile_id=9, target="CURRENT_COARSE", sample_count=len(samples))
    for off in range(0, len(samples), 100):
        client.command("PROFILE_WRITE", offset=off, samples=raw[4 * off:4 * (off + 100)])
    client.command("PROFILE_COMMIT", profile_crc=zlib.crc32(raw))
    client.command("PROFILE_START")
    device.run_ticks(310)
    wait_for(lambda: sum(len(b) for b in blocks if b.name == "HIGH_RATE") >= 310)
    hr = [b for b in blocks if b.name == "HIGH_RATE"]
    cur = np.concatenate([b["current_coarse"] for b in hr])
    idx = np.concatenate([b["profile_index"] for b in hr])
    active = np.concatenate([b["profile_active"] for b in hr])
    assert np.count_nonzero(active) == 300
    played = cur[:300]
    assert np.allclose(played, samples.astype(float), atol=1e-4)   # 0.1 mA telemetry counts
    assert list(idx[:3]) == [1, 2, 3] and idx[300] == 0


def test_mode_changes_only_while_disarmed(client):
    client.connect()
    client.command("SET_MODE", mode="RELATIVE")
    client.command("ARM")
    with pytest.raises(CommandRejected) as err:
        client.command("SET_MODE", mode="OPEN_LOOP")
    assert err.value.reason == "INVALID_STATE"
    with pytest.raises(CommandRejected) as err:
        client.command("SET_CURRENTS", current_coarse=0.1, current_fine=0.0)
    assert err.value.reason == "INVALID_STATE"
    client.command("SET_MODE", mode="IDLE")       # always allowed: disarms
    client.command("SET_MODE", mode="OPEN_LOOP")
    with pytest.raises(CommandRejected) as err:
        client.command("SET_CURRENTS", current_coarse=0.1, current_fine=0.0)
    assert err.value.reason == "NOT_ARMED"


def test_disconnect_disarms(client, device):
    client.connect()
    client.command("SET_MODE", mode="OPEN_LOOP")
    client.command("ARM")
    client.disconnect()
    assert not device.firmware.armed and device.firmware.session_token is None
