"""The function generator's journal record (instruments/generator_journal.py): one schema
for what the window writes and what `fg check` reads back.  Records round-trip through
the JSON the journal keeps, a record off the schema is refused with the action and the
field named, and `fg check` reads a log whose journal holds records written through the
schema - leaving out, with a note, the ones that are not."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import wait_for
from groundstation.basemotion import load_profile
from groundstation.cli.main import main
from groundstation.instruments import open_generator
from groundstation.instruments.generator_journal import (ACTION_FIELDS, JOURNAL_KIND,
                                                         GeneratorJournalError,
                                                         GeneratorJournalRecord)
from groundstation.link import open_client
from groundstation.logs import LogReader, Recorder
from groundstation.logs.live import attach_recorder
from groundstation.logs.schema import JOURNAL_KINDS
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed
from groundstation.sim import SimulatedDevice
from groundstation.sim.scpi_server import attach_generator

ROOT = Path(__file__).resolve().parents[2]
BM2 = ROOT / "profiles" / "base_motion" / "BM2_stage4hz.csv"
INERTIAL = load_testbed(TESTBEDS_DIR / "inertial_2dof.toml")
PERIOD_S, SEED = 10.0, 3
SETTLE_S = 5.0                      # > the stage's 3.7 s settling time
RESOURCE = "TCPIP0::127.0.0.1::5025::SOCKET"

#: one record of every action, with the fields as the window's controller fills them
#: (numpy numbers where the driver and the check give them)
EXAMPLES = {
    "open": dict(identity="B&K Precision, 4053B, SIM, 1.0",
                 limits={"max_amplitude_vpp": 2.0, "max_frequency_hz": 10.0}),
    "close": dict(device_time=None),
    "apply": dict(channel=1, wave={"waveform": "SINE", "frequency_hz": 2.0}, load="HZ",
                  device_time=12.5),
    "output": dict(channel=2, on=np.True_, device_time=13.25),
    "upload": dict(channel=1, name="BM2", profile="BM2_stage4hz", psd_source=BM2,
                   duration_s=10, seed=3, target_rms_rad=np.float64(2.5e-3),
                   precompensated=True, band_hz=(0.5, 8.0), points=np.int64(16384),
                   frequency_hz=0.1, amplitude_vpp=1.25, device_time=4.0),
    "abort": dict(device_time=20.0),
    "check": dict(profile="BM2_stage4hz", target_rms_rad=2.5e-3,
                  achieved_rms_rad=np.float64(2.45e-3), window_s=[5.0, 15.0],
                  missing_frames=0, ok=np.bool_(True)),
}


def test_every_action_has_an_example_and_the_journal_knows_the_kind():
    assert set(EXAMPLES) == set(ACTION_FIELDS)
    assert all(set(fields) == set(ACTION_FIELDS[a]) for a, fields in EXAMPLES.items())
    assert JOURNAL_KIND in JOURNAL_KINDS


@pytest.mark.parametrize("action", sorted(EXAMPLES))
def test_a_record_round_trips_through_the_journal_json(action):
    record = GeneratorJournalRecord(action=action, resource=RESOURCE, **EXAMPLES[action])
    written = record.to_record()
    assert list(written)[:2] == ["action", "resource"]
    assert set(written) == {"action", "resource", *ACTION_FIELDS[action]}
    # plain JSON: what the journal keeps is what comes back
    kept = json.loads(json.dumps(written))
    assert kept == written
    back = GeneratorJournalRecord.from_record(kept)
    assert back == record
    assert back.carried() == {k: getattr(record, k) for k in ACTION_FIELDS[action]}


def test_numbers_are_made_plain_and_pairs_kept_as_pairs():
    up = GeneratorJournalRecord(action="upload", resource=RESOURCE, **EXAMPLES["upload"])
    assert type(up.points) is int and type(up.target_rms_rad) is float
    assert type(up.duration_s) is float and up.duration_s == 10.0
    assert up.psd_source == str(BM2) and up.band_hz == (0.5, 8.0)
    assert up.to_record()["band_hz"] == [0.5, 8.0]
    check = GeneratorJournalRecord(action="check", resource=RESOURCE, **EXAMPLES["check"])
    assert check.ok is True and check.window_s == (5.0, 15.0)
    # what the action does not carry stays None
    assert check.channel is None and check.device_time is None


@pytest.mark.parametrize("data, named", [
    (["upload"], "list instead of a table of fields"),
    ({"resource": RESOURCE}, "action None is not one of open, close"),
    ({"action": "calibrate", "resource": RESOURCE}, "action 'calibrate' is not one of"),
    ({"action": "close"}, "'close': no resource"),
    ({"action": "close", "resource": 5}, "'close': resource = 5 must be text"),
    ({"action": "output", "resource": RESOURCE, "on": True}, "'output': no channel"),
    ({"action": "output", "resource": RESOURCE, "channel": "1", "on": True},
     "'output': channel = '1' must be an integer channel number"),
    ({"action": "output", "resource": RESOURCE, "channel": True, "on": True},
     "'output': channel = True must be an integer"),
    ({"action": "output", "resource": RESOURCE, "channel": 1, "on": "yes"},
     "'output': on = 'yes' must be true or false"),
    ({"action": "close", "resource": RESOURCE, "device_time": "soon"},
     "'close': device_time = 'soon' must be a number of seconds or null"),
    ({"action": "close", "resource": RESOURCE, "channel": 1},
     "'close': unknown field(s) channel (it carries device_time)"),
    ({**GeneratorJournalRecord(action="upload", resource=RESOURCE,
                               **EXAMPLES["upload"]).to_record(), "band_hz": [0.5]},
     "'upload': band_hz = [0.5] must be two numbers (Hz)"),
    ({**GeneratorJournalRecord(action="upload", resource=RESOURCE,
                               **EXAMPLES["upload"]).to_record(), "seed": 3.5},
     "'upload': seed = 3.5 must be an integer"),
])
def test_a_record_off_the_schema_is_named(data, named):
    with pytest.raises(GeneratorJournalError) as err:
        GeneratorJournalRecord.from_record(data)
    assert named in str(err.value)
    assert str(err.value).startswith("function_generator record")


def test_a_nullable_field_may_be_absent_but_a_required_one_may_not():
    """A record written before device_time was journaled reads with device_time None;
    an upload without its period cannot say what was played."""
    old = GeneratorJournalRecord.from_record({"action": "output", "resource": RESOURCE,
                                              "channel": 1, "on": False})
    assert old.device_time is None and old.on is False
    upload = GeneratorJournalRecord(action="upload", resource=RESOURCE,
                                    **EXAMPLES["upload"]).to_record()
    del upload["duration_s"]
    with pytest.raises(GeneratorJournalError, match="'upload': no duration_s"):
        GeneratorJournalRecord.from_record(upload)


def test_the_writer_cannot_build_a_record_off_the_schema():
    with pytest.raises(GeneratorJournalError, match="'abort': has channel = 1, which this "
                                                    "action does not carry"):
        GeneratorJournalRecord(action="abort", resource=RESOURCE, channel=1)
    with pytest.raises(GeneratorJournalError, match="'output': on = None must be true or false"):
        GeneratorJournalRecord(action="output", resource=RESOURCE, channel=1)


# ---------------------------------------------------------------------- fg check reads it
@pytest.fixture(scope="module")
def journaled_log(dictionary, tmp_path_factory):
    """BM2_stage4hz (10 s period, seed 3) played for 5 s of settling and one period, then
    switched off and recorded 2 s more; the journal says so in records written through
    the schema, as the window writes them, with a foreign and a damaged record among
    them."""
    folder = tmp_path_factory.mktemp("fg_journal")
    dev = SimulatedDevice(dictionary, pacing="manual", seed=1, testbed=INERTIAL).start()
    server = attach_generator(dev)
    client = open_client(dictionary, f"tcp://127.0.0.1:{dev.tcp_port}?telemetry=stream",
                         heartbeat=False)
    seen = {"frames": 0, "tick": None}

    def count(block):
        if block.name == "HIGH_RATE" and len(block):
            seen["frames"] += len(block)
            seen["tick"] = int(block["tick"][-1])

    client.subscribe(count)
    rec = Recorder(dictionary, folder, test_name="bm2_journal", testbed_path=str(INERTIAL.path))
    path = rec.start()

    def journal(action: str, **fields) -> None:
        record = GeneratorJournalRecord(action=action, resource=server.resource, **fields)
        rec.record(JOURNAL_KIND, record.to_record())

    def now() -> float | None:          # the newest device time, as the window takes it
        tick = seen["tick"]
        return None if tick is None else tick / dictionary.control_rate_hz

    def run(ticks: int) -> None:
        target = seen["frames"] + ticks
        for step in [6000] * (ticks // 6000) + ([ticks % 6000] if ticks % 6000 else []):
            dev.run_ticks(step)
        wait_for(lambda: seen["frames"] >= target, timeout=20)

    try:
        attach_recorder(client, rec)
        client.connect()
        run(1200)                        # telemetry before anything moves
        profile = load_profile(BM2, INERTIAL, duration_s=PERIOD_S, seed=SEED)
        with open_generator(server.resource, testbed=INERTIAL) as fg:
            up = fg.upload_arbitrary(1, profile.volts, name="BM2",
                                     frequency_hz=profile.frequency_hz)
            journal("upload", channel=1, name="BM2", profile=profile.name,
                    psd_source=profile.psd.source, duration_s=profile.duration_s,
                    seed=profile.seed, target_rms_rad=profile.target_rms_rad,
                    precompensated=profile.precompensated, band_hz=profile.psd.band_hz,
                    points=up.points, frequency_hz=up.frequency_hz,
                    amplitude_vpp=up.amplitude_vpp, device_time=now())
            # an action this reader does not know, and an upload whose seed is not a number
            rec.record(JOURNAL_KIND, {"action": "calibrate", "resource": server.resource})
            rec.record(JOURNAL_KIND, {**GeneratorJournalRecord(
                action="upload", resource=server.resource, channel=2, name="X", profile="X",
                psd_source="X.csv", duration_s=99.0, seed=0, target_rms_rad=1.0,
                precompensated=False, band_hz=(1.0, 2.0), points=8, frequency_hz=1.0,
                amplitude_vpp=1.0).to_record(), "seed": "seven"})
            fg.set_output(1, True)
            journal("output", channel=1, on=True, device_time=now())
            run(int((SETTLE_S + PERIOD_S) * dictionary.control_rate_hz))
            before = now()
            fg.set_output(1, False)
            journal("output", channel=1, on=False, device_time=before)
            run(2 * 1200)                # the stage coasting to rest after the output went off
    finally:
        rec.stop()
        client.close()
        server.stop()
        dev.stop()
    return path


def test_fg_check_reads_the_journal_written_through_the_schema(journaled_log, capsys):
    with LogReader(journaled_log) as log:
        actions = [r.data["action"] for r in log.journal(JOURNAL_KIND)]
    assert actions == ["upload", "calibrate", "upload", "output", "output"]
    # no --duration / --seed: the journal's upload says what was played
    rc = main(["fg", "check", str(journaled_log), "--profile", str(BM2)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "where the output went off (journal)" in out and "result: PASS" in out
    assert "12000 samples, none missing" in out             # one 10 s period at 1200 Hz
    # the two records off the schema are left out, each named, and nothing else
    notes = [line for line in out.splitlines() if line.startswith("note: journal record")]
    assert len(notes) == 2, out
    assert "record 2 of 5 left out" in notes[0] and "action 'calibrate'" in notes[0]
    assert "record 3 of 5 left out" in notes[1] and "seed = 'seven' must be an integer" in notes[1]
