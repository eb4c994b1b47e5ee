"""A watching console whose CURVE keys do not match the publisher's is told what is the
case - a station is there, and which keys it wants - not "no station publishes"
(fanout/handshake.py reads the SUB socket's handshake events).  Real publishers on
loopback, watched through `groundstation monitor --watch` and `record --watch`."""

from __future__ import annotations

import pytest

from groundstation.cli.main import main
from groundstation.fanout.publisher import Publisher

#: the hidden --wait of a watch: generous, since the handshake's answer ends it early
WAIT = ["--wait", "20"]


@pytest.fixture
def lab(tmp_path, capsys):
    """The lab's keys (publisher pair, alice authorised) and a stranger's (eve, not)."""
    lab, stranger = tmp_path / "lab", tmp_path / "stranger"
    assert main(["fanout", "keys", str(lab), "--name", "alice"]) == 0
    assert main(["fanout", "keys", str(stranger), "--name", "eve"]) == 0
    capsys.readouterr()
    return lab, stranger


def watch(capsys, endpoint, *more):
    code = main(["monitor", "--watch", endpoint, "--duration", "1", *WAIT, *more])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_an_unkeyed_console_is_told_the_station_requires_keys(lab, tmp_path, capsys):
    keys, _ = lab
    with Publisher("tcp://127.0.0.1:*", curve_keys=str(keys), hello_period_s=0.05) as pub:
        code, out, err = watch(capsys, pub.endpoint)
        assert code == 2
        assert f"a station publishes on {pub.endpoint} but requires CURVE keys" in err
        assert "--curve-keys DIR --key-name NAME" in err
        assert "no station publishes" not in err
        # record --watch opens its watch the same way: no log is left behind
        code = main(["record", "--watch", pub.endpoint, "--folder", str(tmp_path / "logs"),
                     "--duration", "1", *WAIT])
        err = capsys.readouterr().err
        assert code == 2 and "requires CURVE keys" in err
        # with the lab's keys the same console watches
        code, out, err = watch(capsys, pub.endpoint, "--curve-keys", str(keys),
                               "--key-name", "alice")
        assert code in (0, 1), err            # up (1: no device behind this bare publisher)
        assert f"watching {pub.endpoint}" in out
        assert "requires CURVE keys" not in err + out


def test_a_keyed_console_is_told_the_station_needs_none(lab, capsys):
    keys, _ = lab
    with Publisher("tcp://127.0.0.1:*", hello_period_s=0.05) as pub:
        code, out, err = watch(capsys, pub.endpoint, "--curve-keys", str(keys),
                               "--key-name", "alice")
        assert code == 2
        assert f"a station publishes on {pub.endpoint} without CURVE keys" in err
        assert "watch it without --curve-keys" in err


def test_a_key_the_publisher_does_not_admit_is_named(lab, capsys):
    keys, stranger = lab
    # eve trusts the lab's publisher key, but the lab has not authorised eve's
    (stranger / "publisher.public").write_bytes((keys / "publisher.public").read_bytes())
    with Publisher("tcp://127.0.0.1:*", curve_keys=str(keys), hello_period_s=0.05) as pub:
        code, out, err = watch(capsys, pub.endpoint, "--curve-keys", str(stranger),
                               "--key-name", "eve")
        assert code == 2
        assert "refused this console's CURVE key eve.public" in err
        assert "authorized/" in err


def test_a_wrong_publisher_key_is_named(lab, capsys):
    keys, stranger = lab
    # eve's folder holds another publisher's key (its own lab's), not this one's
    with Publisher("tcp://127.0.0.1:*", curve_keys=str(keys), hello_period_s=0.05) as pub:
        code, out, err = watch(capsys, pub.endpoint, "--curve-keys", str(stranger),
                               "--key-name", "eve")
        assert code == 2
        assert f"{stranger}/publisher.public is not that publisher's key" in err


def test_the_probe_reads_the_publishers_mechanism_without_being_refused(lab):
    """What a handshake cut short (NO_DETAIL: the publisher closed while this side still
    wrote) is resolved with: the publisher's own greeting names its mechanism."""
    import socket

    from groundstation.fanout.handshake import probe_mechanism

    keys, _ = lab
    with Publisher("tcp://127.0.0.1:*", curve_keys=str(keys), hello_period_s=0.05) as pub:
        assert probe_mechanism(pub.endpoint) == "CURVE"
    with Publisher("tcp://127.0.0.1:*", hello_period_s=0.05) as pub:
        assert probe_mechanism(pub.endpoint) == "NULL"
    # a listener that is no ZeroMQ socket (it never greets): no mechanism, within the timeout
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        port = server.getsockname()[1]
        assert probe_mechanism(f"tcp://127.0.0.1:{port}", timeout=0.5) is None
