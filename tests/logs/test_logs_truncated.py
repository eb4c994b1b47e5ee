"""A truncated log answers every command, with its documented status, and never hangs
(issue 29, part 1).

HDF5 in SWMR read mode reads a metadata block whose checksum does not match again and
again, sleeping twice as long each time - by default 2^100 ns, inside one C call that
Ctrl-C cannot interrupt.  Past the cut of a truncated log HDF5 reads zeros, so `log
check` (and once `log export --salvage`) never returned on cuts at 5-10 % and 55-60 % of
a log.  The reader now bounds those attempts (logs/opening.py).

The log is cut at every 5 % of its size and each cut is given to `log info`, `log check`
and `log export --salvage`, through the product's own `main()`, in a child process with a
generous timeout: a hang fails the test instead of stopping the suite.  How long the
commands take is measured by hand and reported (docs/damaged_logs.md), not asserted.
"""

from __future__ import annotations

import ctypes
import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import h5py.defs
import pytest

import groundstation
from groundstation.logs import LogFile, LogReader
from groundstation.logs import opening
from groundstation.logs.check import check_log
from groundstation.logs.opening import LogDamagedError

from test_logs_reader import HOST0, _simulate

SECONDS = 8.0                 # the 8 s recording: 9600 HIGH_RATE frames
FLUSH_FRAMES = 300            # HIGH_RATE frames between flushes, as the writer at 1200 Hz
HANG_TIMEOUT_S = 60           # per cut, for all three commands: only a hang comes near it
CUTS = list(range(5, 100, 5))
ROOT = Path(groundstation.__file__).resolve().parent.parent

# the child runs the three commands one after the other and says which one it starts,
# so that a timeout names the command that hung
_CHILD = r"""
import contextlib, io, json, sys
from groundstation.cli.main import main
log, csv = sys.argv[1], sys.argv[2]
for name, argv in (("info", ["log", "info", log]), ("check", ["log", "check", log]),
                   ("export", ["log", "export", log, "--salvage", "-o", csv])):
    print(json.dumps({"start": name}), flush=True)
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    print(json.dumps({"name": name, "code": code, "out": out.getvalue(), "err": err.getvalue()}),
          flush=True)
"""


@pytest.fixture(scope="module")
def recorded(dictionary, tmp_path_factory) -> Path:
    """An 8 s recording of the simulated testbed, written by the LogFile the recorder's
    writer process drives, flushed as the writer does: the same layout on every run,
    so a given cut destroys the same structures every time."""
    path = tmp_path_factory.mktemp("truncated") / "session.h5"
    lf = LogFile(path, dictionary, test_name="truncated", notes="a log to cut")
    lf.journal([(HOST0, "note", {"text": "starting"}, b"")])
    pending: list = []
    count = [0]

    def sink(block) -> None:
        pending.append(block)
        count[0] += len(block) if block.name == "HIGH_RATE" else 0
        if count[0] >= FLUSH_FRAMES:
            lf.append(pending)
            lf.journal([(HOST0 + count[0] / 1200, "event", {"source": "test"}, b"")])
            lf.flush()
            pending.clear()
            count[0] = 0

    _simulate(dictionary, SECONDS, sink)
    lf.append(pending)
    lf.journal([(HOST0 + SECONDS, "recorder", {"action": "stopped"}, b"")])
    lf.flush()
    lf.close(clean=True)
    return path


def _cut(log: Path, folder: Path, percent: int) -> Path:
    out = folder / f"cut{percent}.h5"
    out.write_bytes(log.read_bytes()[:log.stat().st_size * percent // 100])
    return out


def _run_commands(log: Path, csv: Path) -> dict[str, dict]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT)] + ([os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else [])))
    try:
        done = subprocess.run([sys.executable, "-c", _CHILD, str(log), str(csv)],
                              capture_output=True, text=True, timeout=HANG_TIMEOUT_S, env=env)
    except subprocess.TimeoutExpired as exc:
        lines = (exc.stdout.decode() if isinstance(exc.stdout, bytes) else exc.stdout or "")
        started = [json.loads(x)["start"] for x in lines.splitlines() if '"start"' in x]
        pytest.fail(f"{log.name}: `log {started[-1] if started else '?'}` did not return "
                    f"within {HANG_TIMEOUT_S} s")
    assert done.returncode == 0, done.stderr
    results = {}
    for line in done.stdout.splitlines():
        rec = json.loads(line)
        if "name" in rec:
            results[rec["name"]] = rec
    assert set(results) == {"info", "check", "export"}, done.stdout
    return results


def _readable(check_out: str, packet: str) -> int:
    """Frames of `packet` that `log check` says are readable."""
    for line in check_out.splitlines():
        words = line.split()
        if words[:1] == [packet] and "readable" in words:
            return int(words[1])
    return 0


@pytest.mark.parametrize("percent", CUTS)
def test_every_command_answers_a_truncated_log_with_its_documented_status(recorded, tmp_path,
                                                                          percent):
    log = _cut(recorded, tmp_path, percent)
    csv = tmp_path / "salvaged.csv"
    res = _run_commands(log, csv)
    for rec in res.values():
        assert "Traceback" not in rec["err"] + rec["out"]

    # log info: exit 2, the one line says truncated and what to do
    info = res["info"]
    assert info["code"] == 2
    assert info["err"].startswith(f"error: {log}: damaged log, truncated: file ends at byte "
                                  f"{log.stat().st_size}, HDF5 expects {recorded.stat().st_size}")
    assert f"groundstation log check {log}" in info["err"]

    # log check: 1 damaged but partly readable, 2 unreadable - as its verdict line says
    check = res["check"]
    verdict = check["out"].splitlines()[0]
    assert check["code"] in (1, 2), check["out"] + check["err"]
    assert verdict == (f"{log}: DAMAGED, partly readable" if check["code"] == 1
                       else f"{log}: UNREADABLE"), check["out"]
    assert "truncated: file ends at byte" in check["out"]
    if check["code"] == 2:          # nothing to salvage: say where the rest must come from
        assert "copy the log again from where it came from" in check["out"]

    # log export --salvage: 1 and the rows before the damage, or 2 when no HIGH_RATE
    # frame reads - never a partial file
    export = res["export"]
    readable = _readable(check["out"], "HIGH_RATE")
    if readable:
        assert export["code"] == 1, export["err"]
        assert export["out"].startswith("salvaged ")
        rows = int(export["out"].split()[1])
        assert rows >= readable
        assert len(csv.read_text().splitlines()) == rows + 1        # header + rows
    else:
        assert export["code"] == 2, export["out"]
        assert export["err"].startswith(f"error: {log}: damaged log, ")
        assert ("--packet NAME" in export["err"]
                or "copy the log again from where it came from" in export["err"])
        assert not csv.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]   # no temp files


def test_the_whole_log_still_answers_0(recorded, tmp_path):
    res = _run_commands(recorded, tmp_path / "all.csv")
    assert {k: v["code"] for k, v in res.items()} == {"info": 0, "check": 0, "export": 0}
    assert res["check"]["out"].splitlines()[0] == f"{recorded}: intact: every frame and record reads"


def test_log_check_keeps_its_status_when_its_output_pipe_is_closed(recorded, tmp_path):
    """`log check F | head -1` (or any reader that leaves early): the status is still the
    verdict, not the 0 a closed pipe used to turn it into."""
    log = _cut(recorded, tmp_path, 60)
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from groundstation.cli.main import "
                             "main; sys.exit(main(sys.argv[1:]))", "log", "check", str(log)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    proc.stdout.close()                       # the reader is gone before anything is written
    with proc.stderr:
        err = proc.stderr.read().decode()
    assert proc.wait(timeout=HANG_TIMEOUT_S) == 1, err
    assert "Traceback" not in err and "Exception ignored" not in err


# ---------------------------------------------------------------------- the cause
def _read_attempts(r: LogReader) -> int:
    lib = ctypes.CDLL(h5py.defs.__file__)      # the HDF5 h5py is linked to (opening.py)
    value = ctypes.c_uint()
    assert lib.H5Pget_metadata_read_attempts(ctypes.c_int64(r.h5.id.get_access_plist().id),
                                             ctypes.byref(value)) >= 0
    return value.value


def test_a_swmr_read_gives_up_on_a_bad_metadata_block_after_bounded_attempts(recorded):
    with LogReader(recorded) as r:
        assert r.h5.swmr_mode
        assert _read_attempts(r) == opening.SWMR_METADATA_READ_ATTEMPTS < 100


def test_without_the_bound_a_log_no_writer_has_open_is_read_without_swmr(recorded, tmp_path,
                                                                          monkeypatch):
    """Where HDF5's setter cannot be found, a finished log is opened without SWMR: HDF5
    then reads every metadata block once, and refuses a truncated file at once."""
    monkeypatch.setattr(opening, "_set_metadata_read_attempts", lambda: None)
    with LogReader(recorded) as r:
        assert not r.h5.swmr_mode and r.n_frames("HIGH_RATE") > 0
    log = _cut(recorded, tmp_path, 55)
    with pytest.raises(LogDamagedError, match="truncated: file ends at byte .* copy the log again"):
        LogReader(log)
    assert check_log(log).status == "unreadable"
