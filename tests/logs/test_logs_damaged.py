"""Damaged logs: every command says in one line what is damaged and what to do, `log
check` says what is readable, `log export --salvage` exports it, and no command leaves a
partial output file behind.

The logs are real recordings of the simulated testbed, written by the same LogFile the
recorder's writer process drives, with a flush every 300 HIGH_RATE frames (what the
writer does every 0.25 s at 1200 Hz) - driven directly so that the file's layout, and
with it what a given cut destroys, is the same on every run.  They are then damaged the
ways files get damaged: cut short (a copy interrupted, a full disk), bytes overwritten,
the superblock zeroed, nothing written at all.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io

from groundstation.cli.main import main
from groundstation.core.errors import GroundStationError
from groundstation.logs import LogFile, LogReader, ReplayError, iter_blocks
from groundstation.logs.check import check_log
from groundstation.logs.export import ExportError, export_csv, export_mat
from groundstation.logs.opening import LogDamagedError, LogFormatError
from groundstation.logs.redecode import redecode
from groundstation.logs.blocks import ReplayDamagedError

from test_logs_reader import HOST0, _simulate

SECONDS = 6.0                 # 7200 HIGH_RATE frames, 60 HOUSEKEEPING
FLUSH_FRAMES = 300            # HIGH_RATE frames between flushes, as the writer at 1200 Hz
CHUNK = 256                   # schema.CHUNK_ROWS


# ---------------------------------------------------------------------- the logs
@pytest.fixture(scope="module")
def intact(dictionary, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("intact") / "session.h5"
    lf = LogFile(path, dictionary, test_name="damage", notes="a log to damage")
    lf.journal([(HOST0, "note", {"text": "starting"}, b"")])
    pending: list = []
    count = [0]

    def sink(block) -> None:
        pending.append(block)
        count[0] += len(block) if block.name == "HIGH_RATE" else 0
        if count[0] >= FLUSH_FRAMES:
            lf.append(pending)
            lf.flush()
            pending.clear()
            count[0] = 0

    _simulate(dictionary, SECONDS, sink)
    lf.append(pending)
    lf.journal([(HOST0 + 10, "recorder", {"action": "stopped"}, b"")])
    lf.flush()
    lf.close(clean=True)
    return path


def _copy(intact: Path, folder: Path, name: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / name
    shutil.copyfile(intact, out)
    return out


def truncated(intact: Path, folder: Path, fraction: float) -> Path:
    out = _copy(intact, folder, f"cut{int(fraction * 100)}.h5")
    with open(out, "r+b") as fh:
        fh.truncate(int(intact.stat().st_size * fraction))
    return out


def overwritten_chunk(intact: Path, folder: Path, dataset: str, row: int) -> Path:
    """A copy with the compressed bytes of the chunk holding `row` of `dataset` overwritten."""
    with h5py.File(intact, "r") as f:
        info = f[dataset].id.get_chunk_info_by_coord((row,) + (0,) * (f[dataset].ndim - 1))
    out = _copy(intact, folder, "overwritten.h5")
    with open(out, "r+b") as fh:
        fh.seek(info.byte_offset)
        fh.write(b"\xff" * info.size)
    return out


def _outputs(folder: Path) -> list[str]:
    """Every file in `folder` but the damaged logs themselves (temporaries included)."""
    return sorted(p.name for p in folder.iterdir() if p.suffix != ".h5" or "out" in p.name)


def run(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def _one_line_error(err: str, path: Path, *needles: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err and str(path) in lines[0]
    for n in needles:
        assert n in lines[0], (n, lines[0])


# ---------------------------------------------------------------------- intact
def test_an_intact_log_checks_clean(intact, capsys):
    rc, out, _ = run(capsys, "log", "check", intact)
    assert rc == 0, out
    assert "intact" in out and "7200 of 7200 frames readable" in out
    assert check_log(intact).status == "intact"


# ---------------------------------------------------------------------- truncated
@pytest.mark.parametrize("fraction", [0.6, 0.9])
def test_a_truncated_log_is_one_line_for_every_command(intact, tmp_path, capsys, fraction):
    log = truncated(intact, tmp_path, fraction)
    cut = f"truncated: file ends at byte {log.stat().st_size}, HDF5 expects {intact.stat().st_size}"
    for argv in (["log", "info", log], ["replay", "--headless", log],
                 ["log", "redecode", log, tmp_path / "out-redecoded.h5"],
                 ["log", "export", log, "-o", tmp_path / "out.csv"],
                 ["log", "export", log, "--format", "mat", "-o", tmp_path / "out.mat"]):
        rc, _, err = run(capsys, *argv)
        assert rc == 2, argv
        _one_line_error(err, log, cut, f"groundstation log check {log}", "--salvage")
    assert _outputs(tmp_path) == []                   # nothing half-written, no temporaries

    with pytest.raises(LogDamagedError, match="truncated: file ends at byte") as exc:
        LogReader(log)
    assert isinstance(exc.value, GroundStationError) and exc.value.salvageable
    with pytest.raises(ReplayDamagedError, match="truncated") as rexc:
        next(iter_blocks(log))
    assert isinstance(rexc.value, ReplayError)


@pytest.mark.parametrize("fraction", [0.6, 0.9])
def test_check_says_what_of_a_truncated_log_is_readable(intact, tmp_path, capsys, fraction):
    log = truncated(intact, tmp_path, fraction)
    result = check_log(log)
    assert result.status == "damaged" and result.exit_code == 1
    assert result.problems[0].startswith(f"truncated: file ends at byte {log.stat().st_size}")
    hr = {p.name: p for p in result.packets}["HIGH_RATE"]
    assert hr.frames == 7200 and 0 < hr.readable < 7200
    assert hr.readable % CHUNK == 0                   # whole chunks are lost, never a part
    assert hr.damage and all(d.first_bad >= hr.readable for d in hr.damage)
    assert hr.first_time == pytest.approx(1 / 1200) and hr.last_time == pytest.approx(hr.readable / 1200)

    rc, out, _ = run(capsys, "log", "check", log)
    assert rc == 1
    assert "DAMAGED" in out and f"{hr.readable} of 7200 frames readable" in out
    assert f"groundstation log export {log} --salvage" in out


@pytest.mark.parametrize("fmt", ["csv", "mat"])
def test_salvage_exports_the_readable_rows_of_a_truncated_log(intact, tmp_path, capsys, fmt):
    log = truncated(intact, tmp_path, 0.9)
    hr = {p.name: p for p in check_log(log).packets}["HIGH_RATE"]
    # the rows every dataset these two channels are read from gives (check says per dataset)
    with LogReader(intact) as r:
        read_from = {"/telemetry/HIGH_RATE/device_time", "/telemetry/HIGH_RATE/host_time"} | {
            f"/telemetry/HIGH_RATE/{'raw/' if c.from_raw else ''}{c.name}"
            for c in r.resolve_channels("HIGH_RATE", ["encoder_outer", "gyro_rate"])}
    readable = min([d.first_bad for d in hr.damage if d.path in read_from], default=7200)
    assert hr.readable <= readable < 7200
    out = tmp_path / f"out.{fmt}"
    rc, stdout, _ = run(capsys, "log", "export", log, "--format", fmt, "--channels",
                        "encoder_outer,gyro_rate", "--salvage", "-o", out)
    assert rc == 1
    assert f"salvaged {readable} rows of HIGH_RATE to {out}" in stdout
    assert f"damaged after HIGH_RATE frame {readable} of 7200" in stdout
    with LogReader(intact) as r:
        want = r.read_rows("HIGH_RATE", ["encoder_outer", "gyro_rate"], 0, readable)
    if fmt == "csv":
        table = np.loadtxt(out, delimiter=",", skiprows=1)
        got = {"device_time": table[:, 0], "encoder_outer": table[:, 2], "gyro_rate": table[:, 3]}
    else:
        s = scipy.io.loadmat(out, squeeze_me=True, struct_as_record=False)["HIGH_RATE"]
        got = {"device_time": s.device_time, "encoder_outer": s.encoder_outer, "gyro_rate": s.gyro_rate}
    for name, values in got.items():
        np.testing.assert_array_equal(values, want[name], err_msg=name)
    assert _outputs(tmp_path) == [out.name]

    # a range that ends before the damage exports whole, and says nothing of it
    rc, stdout, _ = run(capsys, "log", "export", log, "--to", "1.0", "--salvage", "-o", out)
    assert rc == 0 and stdout.startswith(f"wrote 1200 rows of HIGH_RATE to {out}")
    # the library: the same rows through export_csv(salvage=True)
    with LogReader(log, salvage=True) as r:
        assert export_csv(r, tmp_path / "lib.csv", "HIGH_RATE", ["encoder_outer", "gyro_rate"],
                          salvage=True) == readable


# ---------------------------------------------------------------------- overwritten
def test_an_overwritten_chunk_names_the_dataset_and_frame(intact, tmp_path, capsys):
    log = overwritten_chunk(intact, tmp_path, "telemetry/HIGH_RATE/encoder_outer", 2100)
    with LogReader(log) as r:                         # opens: the damage is in the data
        r.read("HIGH_RATE", "gyro_rate")              # other columns still read
        with pytest.raises(LogDamagedError) as exc:
            r.read("HIGH_RATE", "encoder_outer")
    assert "dataset /telemetry/HIGH_RATE/encoder_outer unreadable after frame 2048" in exc.value.what

    # export: a read error of the input, not "cannot write"; an earlier output survives
    out = tmp_path / "out.csv"
    out.write_text("an earlier export\n")
    rc, _, err = run(capsys, "log", "export", log, "--channels", "encoder_outer", "-o", out)
    assert rc == 2
    _one_line_error(err, log, "dataset /telemetry/HIGH_RATE/encoder_outer unreadable after frame 2048",
                    f"groundstation log check {log}")
    assert "cannot write" not in err
    assert out.read_text() == "an earlier export\n"
    assert _outputs(tmp_path) == ["out.csv"]          # and no temporary file

    with LogReader(log, salvage=True) as r:
        assert export_mat(r, tmp_path / "out.mat", "HIGH_RATE", ["encoder_outer"], salvage=True) == 2048

    result = check_log(log)
    assert result.status == "damaged"
    hr = {p.name: p for p in result.packets}["HIGH_RATE"]
    assert hr.readable == 2048 and [d.path for d in hr.damage] == ["/telemetry/HIGH_RATE/encoder_outer"]


def test_overwritten_frames_stop_replay_and_redecode_with_one_line(intact, tmp_path, capsys):
    log = overwritten_chunk(intact, tmp_path, "frames/HIGH_RATE/data", 3000)
    rc, _, err = run(capsys, "replay", "--headless", log)
    assert rc == 2
    _one_line_error(err, log, "dataset /frames/HIGH_RATE/data unreadable after frame 2816")
    with pytest.raises(ReplayDamagedError, match="/frames/HIGH_RATE/data unreadable after frame 2816"):
        for _ in iter_blocks(log):
            pass

    target = tmp_path / "out-redecoded.h5"
    rc, _, err = run(capsys, "log", "redecode", log, target)
    assert rc == 2
    _one_line_error(err, log, "dataset /frames/HIGH_RATE/data unreadable after frame 2816")
    assert not target.exists() and _outputs(tmp_path) == []


def test_bytes_overwritten_in_the_middle(intact, tmp_path, capsys):
    log = _copy(intact, tmp_path, "middle.h5")
    size = log.stat().st_size
    with open(log, "r+b") as fh:
        fh.seek(size // 2)
        fh.write(bytes(range(256)) * 16)              # 4 KiB of something else
    result = check_log(log)
    assert result.status == "damaged"
    assert any(p.damage for p in result.packets) or result.journal_damage or result.problems
    rc, out, _ = run(capsys, "log", "check", log)
    assert rc == 1 and "DAMAGED" in out


# ---------------------------------------------------------------------- nothing readable
def test_zeroed_superblock_empty_and_foreign_files_are_unreadable(intact, tmp_path, capsys):
    zeroed = _copy(intact, tmp_path, "zeroed.h5")
    with open(zeroed, "r+b") as fh:
        fh.write(b"\0" * 48)                          # the superblock (version 3: 48 bytes)
    empty = tmp_path / "empty.h5"
    empty.write_bytes(b"")
    foreign = tmp_path / "notes.h5"
    foreign.write_text("not a log at all")
    for log, what in ((zeroed, "superblock at its start is destroyed"),
                      (empty, "empty (0 bytes)"), (foreign, "not an HDF5 file")):
        result = check_log(log)
        assert result.status == "unreadable" and result.exit_code == 2
        rc, out, _ = run(capsys, "log", "check", log)
        assert rc == 2 and "UNREADABLE" in out and what in out
        for argv in (["log", "info", log], ["replay", "--headless", log],
                     ["log", "export", log, "--salvage", "-o", tmp_path / "out.csv"]):
            rc, _, err = run(capsys, *argv)
            assert rc == 2, argv
            _one_line_error(err, log, what)
    with pytest.raises(LogDamagedError) as exc:
        LogReader(zeroed)
    assert not exc.value.salvageable and "nothing in it can be read" in str(exc.value)
    with pytest.raises(LogFormatError, match="not an HDF5 file"):
        LogReader(foreign)
    assert _outputs(tmp_path) == []


# ---------------------------------------------------------------------- outputs
def test_a_write_error_is_reported_as_one(intact, tmp_path):
    with LogReader(intact) as r:
        with pytest.raises(ExportError, match="cannot write"):
            export_csv(r, tmp_path / "no-such-folder" / "out.csv", "HIGH_RATE", "encoder_outer")


def test_redecode_keeps_the_session_length(intact, dictionary, tmp_path, capsys):
    """A 60 s session stays 60 s long when decoded again (it used to become the time
    the re-decoding took, a few tenths of a second)."""
    source = _copy(intact, tmp_path, "sixty.h5")
    with h5py.File(source, "r+") as f:                # make the recorded session 60 s long
        f.attrs["created_utc"] = "2026-11-20T10:00:00+00:00"
        f.attrs["stop_utc"] = "2026-11-20T10:01:00+00:00"
    target = tmp_path / "sixty-v2.h5"
    redecode(source, target, dictionary)
    with LogReader(source) as a, LogReader(target) as b:
        ia, ib = a.summary(), b.summary()
    assert ia.duration_s == 60.0
    assert ib.duration_s == 60.0
    assert (ib.created_utc, ib.stop_utc) == (ia.created_utc, ia.stop_utc)
    assert ib.frames == ia.frames and ib.clean_close

    again = tmp_path / "sixty-v3.h5"
    rc, out, _ = run(capsys, "log", "redecode", source, again)
    assert rc == 0
    rc, out, _ = run(capsys, "log", "info", again)
    assert rc == 0 and "(60.0 s), closed cleanly" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sixty-v2.h5", "sixty-v3.h5", "sixty.h5"]
