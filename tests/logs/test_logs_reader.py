"""LogReader and export against real logs: the simulator's frames, decoded by the codec,
recorded by the Recorder (or a LogFile driven directly), read back and compared with
the blocks that went in."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io

from groundstation.codec import StreamDeframer, TelemetryBlock
from groundstation.core.errors import GroundStationError
from groundstation.logs import LogFile, Recorder
from groundstation.logs.export import export_csv, export_mat, matlab_name
from groundstation.logs.reader import LogReader
from groundstation.logs.opening import LogFormatError, LogQueryError
from groundstation.logs.rows import search_sorted as _search
from groundstation.logs.opening import EmptyRangeError, LogError
from groundstation.sim import SimulatedDevice

REPO = Path(__file__).resolve().parents[2]
HOST0 = 1.7e9            # host clock of the recordings (s since the epoch)
PIECE = 4096             # bytes per "datagram" fed to the deframer: one host time each
HOST_STEP = 0.0371       # host seconds between pieces (strictly increasing, with ties inside)
DROPPED = set(range(1000, 1010)) | set(range(7195, 7205))    # HIGH_RATE sequences never recorded
SECONDS = 12.0           # 14400 HIGH_RATE rows: two chunks of 8192, so searches cross chunks


def _keep(block: TelemetryBlock, dropped: set[int]) -> TelemetryBlock:
    """The block without the HIGH_RATE frames whose sequence is in `dropped`."""
    if block.name != "HIGH_RATE":
        return block
    mask = ~np.isin(block.columns["sequence"], list(dropped))
    return TelemetryBlock(block.packet, {k: v[mask] for k, v in block.columns.items()},
                          np.asarray(block.host_time)[mask], raw=block.raw[mask])


def _simulate(dictionary, seconds: float, sink, dropped=frozenset(), seed: int = 1) -> list[TelemetryBlock]:
    """Run the simulator fast, deframe its bytes in PIECE-sized pieces with a synthetic
    host clock, hand each (filtered) block to `sink`; returns the blocks handed over."""
    dev = SimulatedDevice(dictionary, pacing="manual", seed=seed)
    dfr = StreamDeframer(dev.codec)
    fed: list[TelemetryBlock] = []
    clock = [HOST0]

    def consume(data: bytes) -> None:
        for k in range(0, len(data), PIECE):
            clock[0] += HOST_STEP
            for b in dfr.feed(data[k:k + PIECE], clock[0]):
                b = _keep(b, dropped)
                if len(b):
                    fed.append(b)
                    sink(b)

    dev.run_fast(seconds, consume)
    return fed


def _expected(fed: list[TelemetryBlock], packet: str) -> dict[str, np.ndarray]:
    blocks = [b for b in fed if b.name == packet]
    out = {k: np.concatenate([b.columns[k] for b in blocks]) for k in blocks[0].columns}
    out["host_time"] = np.concatenate([np.broadcast_to(b.host_time, (len(b),)) for b in blocks])
    out["device_time"] = out["tick"].astype(np.int64) / 1200.0     # no wrap in a short run
    if blocks[0].raw is not None:
        # field values (numpy converts the records to native order when concatenating)
        out["__raw__"] = np.concatenate([b.raw for b in blocks])
        # the frames as received, in wire byte order
        out["__wire__"] = np.frombuffer(b"".join(b.raw.tobytes() for b in blocks),
                                        np.uint8).reshape(len(out["__raw__"]), -1)
    else:
        out["__frames__"] = [f for b in blocks for f in b.frames]
    return out


@pytest.fixture(scope="module")
def session(dictionary, tmp_path_factory):
    """A recorded session with two sequence gaps, a note, a parameter-table record."""
    folder = tmp_path_factory.mktemp("logs")
    rec = Recorder(dictionary, folder, test_name="reader test", notes="round trip",
                   testbed_text="[testbed]\nname = 'bench'\n", testbed_name="bench",
                   testbed_path="profiles/testbeds/bench.toml")
    path = rec.start()
    rec.note("operator note: starting")
    rec.record("parameter_table", {"crc": 0x1234, "version": 3}, blob=b"\x00\x01\x02\xff")
    fed = _simulate(dictionary, SECONDS, rec, DROPPED)
    status = rec.stop()
    assert status.state == "stopped", status.error
    return path, fed


@pytest.fixture
def reader(session):
    with LogReader(session[0]) as r:
        yield r


# ---------------------------------------------------------------------- round trip
def test_every_column_reads_back_as_decoded(session, reader):
    _, fed = session
    assert reader.packets() == ["HIGH_RATE", "HOUSEKEEPING", "EVENT", "RESPONSE"]
    for packet in ("HIGH_RATE", "HOUSEKEEPING", "EVENT"):
        exp = _expected(fed, packet)
        got = reader.read(packet)                       # every non-raw channel + both times
        block_cols = set(fed[[b.name for b in fed].index(packet)].columns)
        assert set(got) == block_cols | {"device_time", "host_time"}
        for name, values in got.items():
            if values.dtype == object:
                assert list(values) == list(exp[name]), name
            else:
                assert values.dtype == exp[name].dtype or name.endswith("_time"), name
                np.testing.assert_array_equal(values, exp[name], err_msg=f"{packet}.{name}")
    assert reader.read("RESPONSE", with_time=True)["sequence"].size == 0


def test_raw_counts_and_frames_are_the_wire_values(session, reader):
    _, fed = session
    exp = _expected(fed, "HIGH_RATE")
    raw = exp["__raw__"]
    converted = [c.name for c in reader.channels("HIGH_RATE") if c.has_raw]
    assert "encoder_outer" in converted and "gyro_rate" in converted
    got = reader.read("HIGH_RATE", converted, raw=True, with_time=False)
    for name in converted:
        assert got[name].dtype.kind == "i"
        np.testing.assert_array_equal(got[name], raw[name], err_msg=name)
        np.testing.assert_array_equal(reader.read("HIGH_RATE", f"raw/{name}")[f"raw/{name}"], raw[name])
    frames = reader.frames("HIGH_RATE")
    assert frames.shape == (len(raw), raw.dtype.itemsize) and frames.dtype == np.uint8
    np.testing.assert_array_equal(frames, exp["__wire__"])
    assert bytes(frames[0, :2]) == b"\xeb\x90"             # wire byte order: sync first
    np.testing.assert_array_equal(reader.frames("HIGH_RATE", 100, 103), frames[100:103])
    assert reader.frames("EVENT") == _expected(fed, "EVENT")["__frames__"]
    assert reader.is_variable("EVENT") and not reader.is_variable("HIGH_RATE")


def test_sequence_gaps_are_kept_and_counted(session, reader):
    _, fed = session
    seq = reader.read("HIGH_RATE", "sequence", with_time=False)["sequence"].astype(np.int64)
    fed_seq = _expected(fed, "HIGH_RATE")["sequence"].astype(np.int64)
    np.testing.assert_array_equal(seq, fed_seq)
    jumps = np.flatnonzero(np.diff(seq) != 1)
    assert [(int(seq[j]), int(seq[j + 1])) for j in jumps] == [(999, 1010), (7194, 7205)]
    gaps = reader.gaps("HIGH_RATE")
    assert gaps["missing"].tolist() == [10, 10]
    assert gaps["index"].tolist() == (jumps + 1).tolist()
    exp_dev = _expected(fed, "HIGH_RATE")["device_time"]
    np.testing.assert_array_equal(gaps["device_time"], exp_dev[jumps + 1])
    s = reader.summary()
    hr = s.packets["HIGH_RATE"]
    assert (hr.drops, hr.gaps, hr.duplicates) == (len(DROPPED), 2, 0)
    assert hr.frames == int(SECONDS * 1200) - len(DROPPED)
    assert s.packets["HOUSEKEEPING"].drops == 0 and s.drops == len(DROPPED)


def test_summary_describes_the_session(dictionary, session, reader):
    path, fed = session
    info = reader.info
    assert info is reader.info                           # computed once
    assert (info.test_name, info.run, info.notes) == ("reader test", 1, "round trip")
    assert info.clean_close and info.stop >= info.created and info.duration_s < 60
    assert info.protocol_version == dictionary.version
    assert info.dictionary_hash == f"{dictionary.hash:08x}"
    hr = info.packets["HIGH_RATE"]
    exp = _expected(fed, "HIGH_RATE")
    assert hr.first_device_time == exp["device_time"][0] and hr.last_device_time == exp["device_time"][-1]
    assert hr.first_host_time == exp["host_time"][0] and hr.last_host_time == exp["host_time"][-1]
    assert hr.nominal_rate_hz == 1200 and abs(hr.rate_hz - 1200) < 5      # 20 of 14400 lost
    assert info.packets["HOUSEKEEPING"].frames == int(SECONDS * 10)
    assert info.packets["RESPONSE"].frames == 0 and info.packets["RESPONSE"].first_device_time is None
    assert "HIGH_RATE" in info.format() and "drops 20" in info.format()


def test_channel_descriptors(reader):
    chans = {c.name: c for c in reader.channels("HIGH_RATE")}
    enc = chans["encoder_outer"]
    assert (enc.units, enc.kind, enc.dtype, enc.has_raw) == ("rad", "eng", np.float64, True)
    assert enc.conversion == {"scale": 1.4629180792671596e-09, "offset": 0.0}
    assert "Outer-axis" in enc.description and enc.limits["red"][1] > 0.34
    assert chans["armed"].kind == "flag" and chans["armed"].dtype == np.bool_
    assert chans["mode"].states == {"IDLE": 0, "OPEN_LOOP": 1, "RELATIVE": 2, "INERTIAL": 3}
    assert chans["error_angle"].dtype == np.float32 and not chans["error_angle"].has_raw
    assert chans["autocollimator"].dtype == np.float64        # as decoded live, whatever is stored
    assert chans["raw/encoder_outer"].kind == "raw" and chans["raw/encoder_outer"].units == "counts"
    assert [c.name for c in reader.channels("HIGH_RATE")][:6] == [
        "sequence", "tick", "device_time", "host_time", "mode", "status"]
    assert {c.kind for c in reader.channels("HIGH_RATE")} == {"header", "eng", "flag", "raw"}
    text = {c.name: c for c in reader.channels("EVENT")}["text"]
    assert (text.kind, text.encoding, text.dtype) == ("text", "utf-8", np.dtype(object))
    data = {c.name: c for c in reader.channels("RESPONSE")}["data"]
    assert (data.kind, data.encoding) == ("text", "binary")


def test_journal_protocol_and_testbed(dictionary, reader):
    kinds = [r.kind for r in reader.journal()]
    assert kinds[0] == "recorder" and kinds[-1] == "recorder"
    assert {"note", "parameter_table"} <= set(kinds)
    (note,) = reader.journal("note")
    assert note.data == {"text": "operator note: starting"} and note.blob == b""
    (table,) = reader.journal(["parameter_table"])
    assert table.data == {"crc": 0x1234, "version": 3} and table.blob == b"\x00\x01\x02\xff"
    assert abs(table.time - time.time()) < 600           # host clock of the recorder
    assert reader.protocol_files() == dictionary.source_texts
    assert reader.testbed() == ("bench", "profiles/testbeds/bench.toml", "[testbed]\nname = 'bench'\n")
    with pytest.raises(LogQueryError, match="parameter_table"):
        reader.journal("nonsense")


# ---------------------------------------------------------------------- ranges
def _assert_rows(got: dict, exp: dict, mask: np.ndarray, names: list[str]) -> None:
    rows = np.flatnonzero(mask)
    assert len(rows), "the test range must hold rows"
    assert np.all(np.diff(rows) == 1)                     # one contiguous slice
    for name in names + ["device_time", "host_time"]:
        np.testing.assert_array_equal(got[name], exp[name][rows], err_msg=name)


def test_device_time_ranges_are_inclusive_and_exact(session, reader):
    _, fed = session
    exp = _expected(fed, "HIGH_RATE")
    dev = exp["device_time"]
    names = ["encoder_outer", "gyro_rate", "armed"]
    for start, stop in [(1.0, 2.0), (dev[100], dev[9000]), (0.5335, 0.5349), (6.5, 6.5),
                        (dev[8191], dev[8192]), (dev[0], dev[-1]), (-5.0, 0.01), (11.99, 99.0)]:
        got = reader.read("HIGH_RATE", names, start=start, stop=stop)
        _assert_rows(got, exp, (dev >= start) & (dev <= stop), names)
    # open ends
    got = reader.read("HIGH_RATE", "tick", start=11.5)
    np.testing.assert_array_equal(got["tick"], exp["tick"][dev >= 11.5])
    got = reader.read("HIGH_RATE", "tick", stop=0.5)
    np.testing.assert_array_equal(got["tick"], exp["tick"][dev <= 0.5])
    # a window inside the gap of sequences 1000..1009 (ticks 1001..1010) and beyond the end
    assert reader.read("HIGH_RATE", "tick", start=1001 / 1200, stop=1010 / 1200)["tick"].size == 0
    assert reader.read("HIGH_RATE", "tick", start=100.0, stop=200.0)["tick"].size == 0
    # relative to the first frame of the log (EVENT at device time 0)
    assert reader.origin("device") == 0.0
    got = reader.read("HIGH_RATE", "tick", start=2.0, stop=3.0, relative=True)
    np.testing.assert_array_equal(got["tick"], exp["tick"][(dev >= 2.0) & (dev <= 3.0)])
    with pytest.raises(LogQueryError, match="after its stop"):
        reader.read("HIGH_RATE", "tick", start=3.0, stop=2.0)


def test_host_time_ranges(session, reader):
    _, fed = session
    exp = _expected(fed, "HIGH_RATE")
    host = exp["host_time"]
    assert np.all(np.diff(host) >= 0) and len(np.unique(host)) < len(host) / 10   # ties
    names = ["encoder_inner", "tick"]
    for start, stop in [(host[1500], host[3000]), (host[1500] + 1e-3, host[3000] - 1e-3),
                        (host[0] - 10, host[20]), (host[14000], host[-1] + 10),
                        (host[8191], host[8191])]:
        got = reader.read("HIGH_RATE", names, start=start, stop=stop, timebase="host")
        _assert_rows(got, exp, (host >= start) & (host <= stop), names)
    t0 = reader.origin("host")
    assert t0 == min(host[0], _expected(fed, "EVENT")["host_time"][0])
    got = reader.read("HIGH_RATE", "tick", start=1.0, stop=2.0, timebase="host", relative=True)
    np.testing.assert_array_equal(got["tick"], exp["tick"][(host >= t0 + 1) & (host <= t0 + 2)])
    with pytest.raises(LogQueryError, match="'device' or 'host'"):
        reader.read("HIGH_RATE", "tick", start=1, stop=2, timebase="wall")


def test_tick_ranges_are_half_open(session, reader):
    _, fed = session
    exp = _expected(fed, "HIGH_RATE")
    ticks = exp["tick"].astype(np.int64)
    for a, b in [(1200, 2400), (1, 2), (995, 1015), (8190, 8200), (0, 10 ** 9), (14400, 14401)]:
        got = reader.read_ticks("HIGH_RATE", ["encoder_outer", "tick"], a, b, raw=True)
        mask = (ticks >= a) & (ticks < b)
        np.testing.assert_array_equal(got["tick"], ticks[mask])
        np.testing.assert_array_equal(got["encoder_outer"], exp["__raw__"]["encoder_outer"][mask])
        np.testing.assert_array_equal(got["device_time"], ticks[mask] / 1200.0)
    assert len(reader.read_ticks("HIGH_RATE", "tick", 1200, 2400)["tick"]) == 1200
    assert len(reader.read_ticks("HIGH_RATE", "tick", 995, 1015)["tick"]) == 10      # 10 lost


def test_search_bisects_over_chunks(tmp_path):
    """The range search against np.searchsorted on a many-chunk dataset with ties."""
    rng = np.random.default_rng(3)
    values = np.cumsum(rng.integers(0, 3, 5000)).astype(np.float64)
    with h5py.File(tmp_path / "s.h5", "w") as f:
        ds = f.create_dataset("t", data=values, chunks=(64,))
        for n in (0, 1, 63, 64, 65, 4999, 5000):
            for v in (-1.0, values[0], values[n // 2] if n else 0.0, values[-1], values[-1] + 1, 17.5):
                for side in ("left", "right"):
                    assert _search(ds, n, v, side) == np.searchsorted(values[:n], v, side), (n, v, side)


def test_tick_wrap_is_unwrapped(dictionary, tmp_path):
    """A LogFile driven directly with ticks that wrap at 2^32: device_time and tick
    ranges continue across the wrap."""
    offset = (1 << 32) - 600
    lf = LogFile(tmp_path / "wrap.h5", dictionary, test_name="wrap")

    def sink(b: TelemetryBlock) -> None:
        b.columns["tick"] = ((b.columns["tick"].astype(np.int64) + offset) & 0xFFFFFFFF).astype(np.uint32)
        lf.append([b])

    _simulate(dictionary, 1.0, sink)
    lf.close(clean=True)
    with LogReader(tmp_path / "wrap.h5") as r:
        got = r.read_ticks("HIGH_RATE", "tick", (1 << 32) - 100, (1 << 32) + 100)
        assert len(got["tick"]) == 200
        assert got["tick"][99] == 0xFFFFFFFF and got["tick"][100] == 0
        assert np.all(np.diff(got["device_time"]) > 0)
        assert r.info.packets["HIGH_RATE"].drops == 0


def test_crashed_log_stops_at_its_last_frame(dictionary, tmp_path):
    lf = LogFile(tmp_path / "crash.h5", dictionary, test_name="crash")
    fed = _simulate(dictionary, 1.0, lambda b: lf.append([b]))
    lf.flush()
    lf.close(clean=False)               # what a killed recorder leaves: no stop attributes
    with LogReader(tmp_path / "crash.h5") as r:
        info = r.info
        assert not info.clean_close
        last = max(float(np.max(b.host_time)) for b in fed)
        assert info.stop == last and info.frames == sum(len(b) for b in fed)


# ---------------------------------------------------------------------- a live file
READER_SCRIPT = textwrap.dedent("""
    import sys, time
    import numpy as np
    from groundstation.logs.reader import LogReader
    deadline = time.monotonic() + 15.0
    with LogReader(sys.argv[1]) as r:
        first = n = r.n_frames("HIGH_RATE")
        while n < first + 2400 and time.monotonic() < deadline:
            time.sleep(0.02)
            r.refresh()
            n = r.n_frames("HIGH_RATE")
        seq = r.read("HIGH_RATE", "sequence")["sequence"]
        print(first, n, len(seq), int(np.array_equal(seq, np.arange(len(seq)))), flush=True)
        sys.stdin.readline()          # keep the file open until the test has stopped recording
""")


def test_second_process_reads_the_file_while_it_is_written(dictionary, tmp_path):
    rec = Recorder(dictionary, tmp_path, test_name="live", flush_interval_s=0.1)
    path = rec.start()
    dev = SimulatedDevice(dictionary, pacing="manual", seed=2)
    dfr = StreamDeframer(dev.codec)
    feed = lambda data: [rec(b) for b in dfr.feed(data, time.time())]   # noqa: E731
    dev.run_fast(0.5, feed)
    proc = subprocess.Popen([sys.executable, "-c", READER_SCRIPT, str(path)], cwd=REPO,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    lines: list[str] = []
    threading.Thread(target=lambda: lines.append(proc.stdout.readline()), daemon=True).start()
    deadline = time.monotonic() + 20.0
    fed_seconds = 0.5
    try:
        while not lines and time.monotonic() < deadline:
            dev.run_fast(0.25, feed)          # 300 frames, then let the writer flush
            fed_seconds += 0.25
            time.sleep(0.02)
        assert rec.state == "recording"       # the reader finished while the file was growing
        status = rec.stop()                   # ... and still has it open: the close is clean
        out, err = proc.communicate(input="\n", timeout=max(1.0, deadline - time.monotonic()))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        rec.stop()
    assert proc.returncode == 0, err
    assert status.state == "stopped", status.error
    first, n, rows, contiguous = map(int, lines[0].split())
    assert n >= first + 2400 and rows >= n and contiguous == 1
    assert rows <= fed_seconds * 1200
    with LogReader(path) as r:                # and the closed file holds everything fed
        assert r.n_frames("HIGH_RATE") == round(fed_seconds * 1200) and r.info.clean_close


# ---------------------------------------------------------------------- export
def test_csv_export_round_trips(session, reader, tmp_path):
    names = ["encoder_outer", "error_angle", "gyro_rate", "mode", "armed", "profile_index",
             "sequence", "raw/encoder_outer"]
    out = tmp_path / "hr.csv"
    rows = export_csv(reader, out, "HIGH_RATE", names, 1.0, 9.0, "device", chunk_rows=1000)
    with open(out, encoding="utf-8") as fh:
        header = fh.readline().rstrip("\n").split(",")
    assert header[:4] == ["device_time [s]", "host_time [s]", "encoder_outer [rad]", "error_angle [rad]"]
    assert "raw/encoder_outer [counts]" in header and "mode" in header
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    exp = reader.read("HIGH_RATE", names, start=1.0, stop=9.0)
    assert table.shape == (rows, len(names) + 2) and rows == len(exp["device_time"])
    for k, name in enumerate(["device_time", "host_time"] + names):
        np.testing.assert_array_equal(table[:, k], exp[name].astype(np.float64), err_msg=name)
    # host-time range, and events with their text
    host = reader.read("HIGH_RATE", "tick")["host_time"]
    n = export_csv(reader, tmp_path / "h.csv", "HIGH_RATE", ["tick"], host[10], host[500], "host")
    assert n == np.count_nonzero((host >= host[10]) & (host <= host[500]))
    export_csv(reader, tmp_path / "ev.csv", "EVENT")
    text = (tmp_path / "ev.csv").read_text(encoding="utf-8")
    assert text.startswith("device_time [s],host_time [s],sequence [counts],tick [ticks],level,code,text\n")
    assert '"firmware' in text


def test_mat_export_round_trips(session, reader, tmp_path):
    names = ["encoder_outer", "error_angle", "armed", "mode", "raw/encoder_outer"]
    out = tmp_path / "hr.mat"
    rows = export_mat(reader, out, "HIGH_RATE", names, 2.0, 4.0)
    m = scipy.io.loadmat(out, simplify_cells=True)
    s = m["HIGH_RATE"]
    exp = reader.read("HIGH_RATE", names, start=2.0, stop=4.0)
    assert rows == len(exp["device_time"]) == 2401
    for name in ["device_time", "host_time"] + names:
        np.testing.assert_array_equal(np.ravel(s[matlab_name(name)]), exp[name], err_msg=name)
    assert s["units"]["encoder_outer"] == "rad" and s["units"]["raw_encoder_outer"] == "counts"
    assert s["units"]["device_time"] == "s"
    assert m["log_info"]["test_name"] == "reader test" and m["log_info"]["packet"] == "HIGH_RATE"
    export_mat(reader, tmp_path / "ev.mat", "EVENT")
    ev = scipy.io.loadmat(tmp_path / "ev.mat", simplify_cells=True)["EVENT"]
    assert str(ev["text"]).startswith("firmware")
    assert matlab_name("raw/encoder.outer") == "raw_encoder_outer" and matlab_name("1x") == "x1x"


def test_export_refuses_bad_input(reader, tmp_path):
    with pytest.raises(LogQueryError, match="HOUSEKEEPING"):
        export_csv(reader, tmp_path / "x.csv", "NOPE")
    with pytest.raises(LogQueryError, match="encoder_outer") as exc:
        export_mat(reader, tmp_path / "x.mat", "HIGH_RATE", ["encoder_outr"])
    assert "'encoder_outr'" in str(exc.value)
    with pytest.raises(EmptyRangeError, match=r"no HIGH_RATE frames in device time 50\.0 \.\. 60\.0 s \(the log holds "):
        export_csv(reader, tmp_path / "x.csv", "HIGH_RATE", ["tick"], 50.0, 60.0)
    with pytest.raises(EmptyRangeError, match="the log holds no RESPONSE frames"):
        export_mat(reader, tmp_path / "x.mat", "RESPONSE")
    with pytest.raises(GroundStationError, match="cannot write"):
        export_csv(reader, tmp_path / "missing" / "x.csv", "HIGH_RATE", ["tick"], 1.0, 2.0)


# ---------------------------------------------------------------------- not our files
def test_not_hdf5_is_a_format_error(tmp_path):
    bad = tmp_path / "notes.h5"
    bad.write_text("these are notes, not a log\n")
    with pytest.raises(LogFormatError, match="not an HDF5 file") as exc:
        LogReader(bad)
    assert str(bad) in str(exc.value) and "these are" in str(exc.value)
    assert isinstance(exc.value, GroundStationError)
    with pytest.raises(LogError, match="no such file"):
        LogReader(tmp_path / "absent.h5")


def test_other_schema_and_newer_version_are_format_errors(tmp_path):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.create_dataset("signal", data=np.arange(3))
    with pytest.raises(LogFormatError, match="no 'schema' attribute.*signal") as exc:
        LogReader(other)
    assert str(other) in str(exc.value)
    with h5py.File(other, "a") as f:
        f.attrs["schema"] = "someone-elses-format"
    with pytest.raises(LogFormatError, match="schema 'someone-elses-format'"):
        LogReader(other)
    newer = tmp_path / "newer.h5"
    with h5py.File(newer, "w", libver="latest") as f:
        f.attrs["schema"] = "groundstation-log"
        f.attrs["schema_version"] = 7
    with pytest.raises(LogFormatError, match="schema_version 7 is newer") as exc:
        LogReader(newer)
    assert str(newer) in str(exc.value)
