"""`groundstation conformance` against the simulated device: a conforming device passes
every check, the rig is left as found, and each deliberate deviation of the simulated
device (sim/deviations.py) is caught as a FAIL in the SPEC section it breaks."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
import zlib

import numpy as np
import pytest

from conftest import collect, wait_for
from groundstation.cli.main import main
from groundstation.core.dictionary import load_dictionary
from groundstation.link import open_client
from groundstation.params import table as ptable
from groundstation.sim.process import SimulatorProcess
from groundstation.sim.deviations import BREAKS

LINE = re.compile(r"^(PASS|FAIL|SKIP)  (§[\d.]+) (.+?)  \(\d+\.\d+ s\)$", re.M)
MOTION = {"silent host disarmed within watchdog_timeout (device ticks)", "profile upload with CRC",
          "profile plays sample-exact", "abort mid-profile"}


def results(out: str) -> list[tuple[str, str, str]]:
    """(status, section, title) of every check line printed."""
    return LINE.findall(out)


@pytest.fixture
def device():
    sim = SimulatorProcess(pacing="realtime")
    address = sim.start()
    yield address
    sim.stop()


def test_the_simulated_device_passes_every_check(tmp_path, capsys):
    junit = tmp_path / "out.xml"
    code = main(["conformance", "--device", "sim", "--allow-motion", "--junit", str(junit)])
    out = capsys.readouterr().out
    printed = results(out)
    assert code == 0, out
    assert printed and all(status == "PASS" for status, _, _ in printed), out
    titles = {title for _, _, title in printed}
    assert MOTION <= titles
    cases = ET.parse(junit).getroot().findall(".//testcase")
    assert len(cases) == len(printed)
    assert [(c.get("classname"), c.get("name")) for c in cases] == \
        [(section, f"{section} {title}") for _, section, title in printed]
    assert not ET.parse(junit).getroot().findall(".//failure")


def test_without_motion_the_motion_checks_skip_and_the_device_is_left_as_found(device, capsys):
    code = main(["conformance", "--device", device])
    out = capsys.readouterr().out
    printed = results(out)
    assert code == 0, out
    skipped = {title for status, _, title in printed if status == "SKIP"}
    assert skipped == MOTION, out
    assert all(status == "PASS" for status, _, title in printed if title not in MOTION), out
    d = load_dictionary()
    _assert_state(d, device, ptable.pack(d, ptable.default_values(d)), 0)


def test_a_table_of_the_operator_is_restored_after_the_run(device, tmp_path, capsys):
    """A device holding its own table (not the defaults) gets it back, version included."""
    d = load_dictionary()
    values = ptable.default_values(d)
    values["saturation_coarse"] = 60.0
    values["outer_loop_gain"] = 12.5
    blob = ptable.pack(d, values)
    client = open_client(d, device)
    try:
        client.connect()
        client.command("PARAM_BEGIN", table_version=7, table_length=len(blob))
        for off in range(0, len(blob), 1000):
            client.command("PARAM_WRITE", offset=off, data=blob[off:off + 1000])
        client.command("PARAM_COMMIT", table_crc=zlib.crc32(blob))
        client.disconnect()
    finally:
        client.close()
    junit = tmp_path / "r.xml"
    code = main(["conformance", "--device", device, "--allow-motion", "--junit", str(junit)])
    out = capsys.readouterr().out
    assert code == 0, out
    _assert_state(d, device, blob, 7)


def _assert_state(d, address, blob, version):
    """The device's active table is `blob` with `version`, and its drives are off."""
    client = open_client(d, address)
    blocks = collect(client)
    try:
        client.connect()
        read = b""
        while len(read) < len(blob):
            reply = client.command("PARAM_READ", offset=len(read),
                                   count=min(1000, len(blob) - len(read))).reply
            read += reply["data"]
        assert read == blob
        hk = wait_for(lambda: [b for b in blocks if b.name == "HOUSEKEEPING"], timeout=10.0)[-1]
        assert int(hk["param_table_crc"][-1]) == zlib.crc32(blob)
        assert int(hk["param_table_version"][-1]) == version
        hr = wait_for(lambda: [b for b in blocks if b.name == "HIGH_RATE"], timeout=10.0)[-1]
        assert not np.any(hr["armed"])
    finally:
        client.close()


@pytest.mark.parametrize("deviation, section", list(BREAKS.items()))
def test_each_deviation_is_caught_in_its_section(deviation, section, tmp_path, capsys):
    only = section.lstrip("§")             # --only takes the number
    sim = SimulatorProcess(pacing="realtime", deviations=(deviation,))
    address = sim.start()
    try:
        junit = tmp_path / "dev.xml"
        code = main(["conformance", "--device", address, "--allow-motion", "--only", only,
                     "--junit", str(junit)])
    finally:
        sim.stop()
    out = capsys.readouterr().out
    failed = {s for status, s, _ in results(out) if status == "FAIL"}
    assert code == 1, out
    assert section in failed, out
    if deviation != "crc-range":    # bad telemetry also keeps the final restore check blind
        assert failed == {section}, out
    failures = ET.parse(junit).getroot().findall(".//testcase[failure]")
    assert section in {c.get("classname") for c in failures}


def test_an_unreachable_device_is_exit_2_with_a_message(capsys):
    import socket

    with socket.socket() as s:             # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    code = main(["conformance", "--device", f"tcp://127.0.0.1:{port}"])
    err = capsys.readouterr().err
    assert code == 2
    assert "connection refused" in err and "Traceback" not in err


def test_an_only_that_selects_nothing_is_exit_2(capsys):
    assert main(["conformance", "--device", "tcp://127.0.0.1:9", "--only", "42"]) == 2
    assert "selects no check" in capsys.readouterr().err


def test_a_bad_address_is_exit_2(capsys):
    assert main(["conformance", "--device", "ftp://nowhere"]) == 2
    assert "unknown scheme" in capsys.readouterr().err


def test_the_sim_option_names_every_deviation():
    from groundstation.cli.main import build_parser
    from groundstation.sim.deviations import NAMES

    sim = build_parser()._subparsers._group_actions[0].choices["sim"]
    option = next(a for a in sim._actions if "--deviate" in a.option_strings)
    assert tuple(option.choices) == NAMES


def test_over_a_serial_line_the_checks_of_other_hosts_skip(capsys):
    """One serial line is one host: take-over and foreign hosts cannot be tried there
    (SKIP), everything else runs, telemetry and all, on the one stream."""
    from groundstation.sim.device import SimulatedDevice
    from groundstation.sim.pty import PtyMasterStream

    device = SimulatedDevice(pacing="realtime").start()
    try:
        pty = PtyMasterStream()
        device.attach_stream(pty)
        code = main(["conformance", "--serial", pty.slave_name, "--allow-motion"])
    finally:
        device.stop()
    out = capsys.readouterr().out
    printed = results(out)
    assert code == 0, out
    skipped = {title for status, _, title in printed if status == "SKIP"}
    assert skipped == {"foreign host refused, token and ownership", "take-over",
                       "a replay is only for the connection that sent the command",
                       "telemetry from the command port"}, out
    assert "§8" in {section for status, section, _ in printed if status == "PASS"}

