"""The C reference device (firmware/reference_device) builds clean, its kit is the one
the dictionary exports today, and its command line does what README.md says."""

from __future__ import annotations

import subprocess

import pytest

from groundstation.core.dictionary import load_dictionary
from groundstation.firmware_kit.c_export import export_c
from groundstation.sim.deviations import NAMES
from reference_device_helpers import (FIRMWARE_DIR, _read_line, build_reference_device,
                                      running_reference_device)

DEVIATIONS = NAMES                       # the C device takes the simulated device's names


def test_kit_committed_is_a_fresh_export(tmp_path):
    """A change of protocol/*.toml must come with a new export of the kit (and a look at
    what the device needs to change): `groundstation protocol export-c
    firmware/reference_device/kit`."""
    written = export_c(load_dictionary(), tmp_path)
    assert sorted(p.name for p in written) == ["hfb_protocol.c", "hfb_protocol.h"]
    for path in written:
        committed = FIRMWARE_DIR / "kit" / path.name
        assert committed.read_bytes() == path.read_bytes(), (
            f"{committed} differs from a fresh export: run `groundstation protocol export-c "
            f"firmware/reference_device/kit`")


def test_builds_with_werror_and_no_warning(tmp_path):
    sources = sorted((FIRMWARE_DIR / "src").glob("*.c")) + [FIRMWARE_DIR / "kit" / "hfb_protocol.c"]
    out = subprocess.run(
        ["gcc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-O2", f"-I{FIRMWARE_DIR / 'kit'}",
         "-o", str(tmp_path / "dev"), *map(str, sources), "-lm"],
        capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stderr == ""
    # and `make firmware`, which the tests and `make test` use, produces the binary
    assert build_reference_device().is_file()


def test_help_and_unknown_deviation():
    binary = build_reference_device()
    out = subprocess.run([str(binary), "--help"], capture_output=True, text=True, timeout=10)
    assert out.returncode == 0 and all(name in out.stdout for name in DEVIATIONS)
    out = subprocess.run([str(binary), "--deviate", "no-such-thing"], capture_output=True,
                         text=True, timeout=10)
    assert out.returncode == 2 and "no-such-thing" in out.stderr
    assert out.stdout == ""


@pytest.mark.parametrize("name", DEVIATIONS)
def test_each_deviation_starts_and_stops(name):
    with running_reference_device(name) as address:
        assert address.startswith("tcp://127.0.0.1:")


def test_sigterm_exits_cleanly():
    binary = build_reference_device()
    proc = subprocess.Popen([str(binary)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        line = _read_line(proc, 10.0) + "\n"
        assert line.startswith("listening tcp://127.0.0.1:")
        proc.terminate()
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        proc.stdout.close()
        proc.stderr.close()
