"""The suite against the C reference device (firmware/reference_device), when it builds:
a second, independent implementation of the SPEC passes, and its deliberate deviations
(the same names as the simulated device's) are caught in their sections."""

from __future__ import annotations

import re

import pytest

from groundstation.cli.main import main
from groundstation.sim.deviations import BREAKS

reference = pytest.importorskip("reference_device_helpers")

LINE = re.compile(r"^(PASS|FAIL|SKIP)  (§[\d.]+) ", re.M)


@pytest.fixture(scope="module")
def built():
    try:
        reference.build_reference_device()
    except (RuntimeError, OSError) as exc:
        pytest.skip(f"the C reference device does not build here: {exc}")


def test_the_reference_device_passes_every_check(built, capsys):
    with reference.running_reference_device() as address:
        code = main(["conformance", "--device", address, "--allow-motion"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert LINE.findall(out) and all(s == "PASS" for s, _ in LINE.findall(out)), out


@pytest.mark.parametrize("deviation, section", list(BREAKS.items()))
def test_its_deviations_are_caught_in_their_sections(built, deviation, section, capsys):
    only = section.lstrip("§")             # --only takes the number
    with reference.running_reference_device(deviation) as address:
        code = main(["conformance", "--device", address, "--allow-motion", "--only", only])
    out = capsys.readouterr().out
    assert code == 1, out
    assert section in {s for status, s in LINE.findall(out) if status == "FAIL"}, out
