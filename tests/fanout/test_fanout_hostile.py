"""A stranger on the same machine binds the address a read-only console watches (issue 29,
part 3): with no CURVE keys (loopback) it is "the publisher".  Whatever it sends - JSON
nested 100,000 deep, wrong types, a message numbered 2^64-1, random bytes, oversized
frames, then nothing - the console counts each refusal, says "lost" when the stream
stops making sense, never dies silently and never prints a traceback; `record --watch`
exits non-zero when it recorded nothing.

The hostile publisher is an XPUB socket: it learns when the console has subscribed, so
no message is sent into the void and nothing waits for a time.  Every wait is bounded
and waits for a condition (a counter, a state, a line the program prints)."""

from __future__ import annotations

import json
import logging
import os
import queue
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from groundstation.fanout import schema, wire
from groundstation.fanout.endpoints import FanoutError
from groundstation.fanout.viewer import BAD_IN_A_ROW, MAX_SEQUENCE_GAP, WatchClient
from groundstation.logs import LogReader
from groundstation.sim import SimulatedDevice

from conftest import wait_for

zmq = pytest.importorskip("zmq")

ROOT = Path(__file__).resolve().parents[2]


class Hostile:
    """Binds tcp://127.0.0.1:PORT as a publisher would and sends whatever it likes."""

    def __init__(self):
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.XPUB)
        self.sock.linger = 0
        self.sock.sndhwm = 0                    # nothing of ours dropped: counts are exact
        self.sock.bind("tcp://127.0.0.1:*")
        self.endpoint = self.sock.last_endpoint.decode()
        self.seq = 0

    def wait_subscriber(self, timeout_s: float = 60.0) -> None:
        assert self.sock.poll(int(timeout_s * 1000)), "no console subscribed"
        assert self.sock.recv()[:1] == b"\x01"  # a subscription

    def send(self, parts: list[bytes]) -> None:
        self.sock.send_multipart(parts)

    def next_seq(self) -> int:
        self.seq += 1
        return self.seq

    def valid_json(self, topic: bytes, record, seq: int | None = None) -> None:
        self.send(wire.json_message(topic, self.next_seq() if seq is None else seq, 1.0, record))

    def raw_json(self, topic: bytes, body: bytes) -> None:
        """A bad message numbered as the next valid one will be: refused messages must
        not count as missed ones."""
        parts = wire.json_message(topic, self.seq + 1, 1.0, None)
        self.send(parts[:2] + [body])

    def hello(self, dictionary) -> None:
        self.valid_json(wire.TOPIC_HELLO, {
            "publisher": self.endpoint, "instance": "0badc0de", "sent": 1, "send_errors": 0,
            "device": {"kind": "tcp", "host": "127.0.0.1", "port": 9, "address": "tcp://127.0.0.1:9"},
            "protocol": dictionary.version, "dictionary_hash": f"{dictionary.hash:08x}",
            "link_state": "up", "link_error": "", "health": "", "dropped": 0})

    def frames(self, chunks: list[bytes]) -> None:
        self.send(wire.frames_message(self.next_seq(), chunks, [1.0 + i for i in range(len(chunks))]))

    def close(self) -> None:
        self.sock.close(linger=0)
        self.ctx.term()


def malformed(h: Hostile) -> list[tuple[list[bytes], str]]:
    """The issue's malformed messages and worse, each with (part of) the reason a
    console gives for refusing it.  Numbered as the next valid message will be: refused
    messages must not count as missed ones."""
    def j(topic: bytes, body: bytes) -> list[bytes]:
        return wire.json_message(topic, h.seq + 1, 1.0, None)[:2] + [body]

    deep = f"nested deeper than {schema.MAX_JSON_DEPTH} levels"
    return [
        (j(wire.TOPIC_HELLO, b"[" * 100_000 + b"]" * 100_000), deep),       # 100,000 deep
        (j(wire.TOPIC_HELLO, b'{"a":' * 40_000 + b"1" + b"}" * 40_000), deep),
        (j(wire.TOPIC_HELLO, b"[1, 2, 3]"), "a hello is list, not an object"),
        (j(wire.TOPIC_HELLO, b'{"instance": 5, "device": {}}'), "'instance' is int, not text"),
        (j(wire.TOPIC_HELLO, b'{"instance": "x", "device": {"kind": "tcp", "host": "h", '
                             b'"port": "80"}}'), "'port' is str, not a whole number"),
        (j(wire.TOPIC_HELLO, b"\xff\xfe not utf-8"), "not JSON"),
        (j(wire.TOPIC_HELLO, b'{"instance": "x", "n": ' + b"9" * 5000 + b"}"), "not JSON"),
        (j(wire.TOPIC_HELLO, b'{"instance": "' + b"x" * (schema.MAX_JSON_BYTES + 1) + b'"}'),
         f"above {schema.MAX_JSON_BYTES}"),
        (j(wire.TOPIC_COMMAND, json.dumps({"name": "ARM", "sequence": 1, "arguments": {},
                                           "stages": 5, "reply": {}}).encode()),
         "'stages' is int, not a list"),
        (j(wire.TOPIC_COMMAND, b'{"name": "ARM", "sequence": true}'),
         "'sequence' is bool, not a whole number"),
        (j(wire.TOPIC_LINK, b"5"), "a link record is int, not an object"),
        (j(wire.TOPIC_LINK, b'{"state": ["up"]}'), "'state' is list, not text"),
        (j(wire.TOPIC_LINK, b'{"state": "up", "message": "x"}')[:1] + [b"\0" * 26, b"{}"],
         "without the fan-out magic"),
        ([os.urandom(37)], "1 part(s)"),                                    # random bytes
        ([b"hello", os.urandom(wire.HEADER.size), os.urandom(300)], "fan-out"),
        ([os.urandom(8) for _ in range(7)], "7 part(s)"),
        (wire.frames_message(h.seq + 1, [b"\0" * (schema.MAX_MESSAGE_BYTES + 1)], [1.0]),
         f"above the {schema.MAX_MESSAGE_BYTES} a console accepts"),     # oversized
        (wire.frames_message(h.seq + 1, [b"x", b"y"], [1.0, float("nan")]), "arrival time nan"),
    ]


def hostile_messages(h: Hostile) -> int:
    """Every malformed message at once, then well-formed frames of noise (the decoder's
    to count as junk); returns how many a console must refuse."""
    messages = malformed(h)
    for parts, _ in messages:
        h.send(parts)
    h.frames([os.urandom(200), os.urandom(1500)])
    return len(messages)


def telemetry_chunks(dictionary, seconds: float = 0.1) -> list[bytes]:
    dev = SimulatedDevice(dictionary, pacing="manual", seed=3)
    out: list[bytes] = []
    dev.run_fast(seconds, out.append, batch=12)
    return out


@pytest.fixture
def hostile():
    h = Hostile()
    yield h
    h.close()


def test_a_hostile_publisher_is_counted_and_said_never_fatal(dictionary, hostile, caplog):
    caplog.set_level(logging.DEBUG, logger="groundstation.fanout")
    states: list[tuple[str, str]] = []
    viewer = WatchClient(dictionary, hostile.endpoint, silence_s=0.5)
    viewer.add_link_listener(lambda s, m: states.append((s, m)))
    frames = []
    viewer.subscribe(lambda b: frames.append(len(b)) if b.name == "HIGH_RATE" else None)
    viewer.start()
    try:
        hostile.wait_subscriber()
        hostile.hello(dictionary)
        viewer.wait_up(30.0)
        for n, (parts, reason) in enumerate(malformed(hostile), 1):    # each refused, said why
            hostile.send(parts)
            wait_for(lambda: viewer.counters.bad_messages == n, timeout=60.0)
            assert reason in str(viewer.counters.recent_errors[-1])
        bad = n + hostile_messages(hostile)      # and all at once
        # a valid message numbered 2^64-1: a resynchronisation, not 1.8e19 missed
        hostile.valid_json(wire.TOPIC_LINK, {"state": "up", "message": ""}, seq=2**64 - 1)
        for chunk in telemetry_chunks(dictionary):
            hostile.frames([chunk])
        wait_for(lambda: viewer.counters.bad_messages == bad and sum(frames) >= 100, timeout=60.0)
        c = viewer.counters
        assert c.missed_messages == 0
        assert c.message_resyncs == 2          # to 2^64-1, and back to the stranger's own
        reasons = [str(e) for e in c.recent_errors]
        assert any(f"more than the {MAX_SEQUENCE_GAP}" in r for r in reasons)
        assert viewer.stats.snapshot().framing["junk_bytes"] >= 1700     # the noise frames
        assert viewer.link_state == "up" and viewer.hello["instance"] == "0badc0de"

        # noise only: the stream no longer makes sense - 'lost', said with the reason
        for _ in range(BAD_IN_A_ROW):
            hostile.send([os.urandom(16), os.urandom(26), os.urandom(16)])
        wait_for(lambda: viewer.link_state == "lost", timeout=60.0)
        assert "messages in a row" in viewer.link_error and "refused" in viewer.link_error
        assert viewer.counters.bad_messages == bad + BAD_IN_A_ROW

        before = len(states)
        hostile.hello(dictionary)              # a valid message: up again ...
        wait_for(lambda: "up" in [s for s, _ in states[before:]], timeout=60.0)
        # ... then a stalled stream: 'lost' by the watchdog
        wait_for(lambda: viewer.link_state == "lost" and "nothing valid" in viewer.link_error,
                 timeout=60.0)
        assert viewer.failure is None and not viewer.ended      # still watching
    finally:
        viewer.close()
    assert not [r for r in caplog.records if r.exc_info], "a traceback was logged"


def test_the_reader_never_dies_silently(dictionary, hostile, monkeypatch):
    """An error nothing foresaw stops the watch with its reason, for every listener."""
    states = []
    viewer = WatchClient(dictionary, hostile.endpoint)
    viewer.add_link_listener(lambda s, m: states.append((s, m)))

    def broken():
        raise MemoryError("out of memory in the watchdog")
    monkeypatch.setattr(viewer, "_watchdog", broken)
    viewer.start()
    try:
        wait_for(lambda: viewer.ended, timeout=30.0)
        assert states[-1][0] == "failed" and "MemoryError: out of memory" in states[-1][1]
        assert "start it again" in states[-1][1]
        with pytest.raises(FanoutError, match="stopped watching .*MemoryError"):
            viewer.wait_up(1.0)
    finally:
        viewer.close()


def test_json_depth_is_counted_flat():
    assert schema.json_depth(b'{"a": [1, {"b": "[[[[{{{"}], "c": "\\"]]"}') == 3
    assert schema.json_depth(b"[" * 1_000_000, limit=32) == 33
    assert schema.json_depth(b'"\\\\"[[]]') == 2


class Cli:
    """`groundstation ARGS` as a child process; stdout and stderr read in threads so a
    test waits for a line with a bound."""

    def __init__(self, *args: str):
        self.proc = subprocess.Popen([sys.executable, "-m", "groundstation", *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     cwd=ROOT, start_new_session=True,
                                     env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self.lines: queue.Queue = queue.Queue()
        self.seen: list[str] = []
        self.err: list[str] = []
        self._threads = [threading.Thread(target=self._pump, args=(self.proc.stdout, self.lines.put),
                                          daemon=True),
                         threading.Thread(target=self._pump, args=(self.proc.stderr, self.err.append),
                                          daemon=True)]
        for t in self._threads:
            t.start()

    @staticmethod
    def _pump(stream, put) -> None:
        for line in stream:
            put(line.rstrip("\n"))
        put(None)

    def wait_for_line(self, *texts: str, timeout: float = 90.0) -> str:
        while True:
            try:
                line = self.lines.get(timeout=timeout)
            except queue.Empty:
                raise AssertionError(f"no line with {texts} within {timeout} s; seen: "
                                     f"{self.seen[-5:]}; stderr: {self.err[-5:]}") from None
            if line is None:
                raise AssertionError(f"the program ended (status {self.proc.wait()}) without a "
                                     f"line with {texts}; seen: {self.seen[-5:]}; stderr: "
                                     f"{self.err[-5:]}")
            self.seen.append(line)
            if all(t in line for t in texts):
                return line

    def interrupt_and_finish(self, timeout: float = 90.0) -> tuple[int, str, str]:
        os.kill(self.proc.pid, signal.SIGINT)
        code = self.proc.wait(timeout)
        for t in self._threads:
            t.join(timeout)
        while not self.lines.empty():
            line = self.lines.get()
            if line is not None:
                self.seen.append(line)
        return code, "\n".join(self.seen), "\n".join(e for e in self.err if e is not None)

    def kill(self) -> None:
        """Make sure the child is gone and its pipes are closed (every test's finally)."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        for t in self._threads:
            t.join(30.0)
        self.proc.stdout.close()
        self.proc.stderr.close()


def test_record_watch_on_a_hostile_publisher_exits_non_zero_having_recorded_nothing(
        dictionary, hostile, tmp_path):
    cli = Cli("record", "--watch", hostile.endpoint, "--folder", str(tmp_path), "--name",
              "hostile", "--wait", "60")
    try:
        hostile.wait_subscriber()
        hostile.hello(dictionary)
        cli.wait_for_line("recording to")
        bad = hostile_messages(hostile)
        hostile.valid_json(wire.TOPIC_LINK, {"state": "up", "message": ""}, seq=2**64 - 1)
        cli.wait_for_line(f"bad {bad} msg", "resync 1 msg", "commander: up")
        for _ in range(BAD_IN_A_ROW):
            hostile.send([os.urandom(26)])
        cli.wait_for_line("watch lost", f"{BAD_IN_A_ROW} messages in a row")
        hostile.hello(dictionary)
        cli.wait_for_line("watch up")
        # then nothing at all: the watchdog says so (3 s of silence)
        cli.wait_for_line("watch lost", "nothing valid from the publisher")
        cli.wait_for_line("commander: unknown (watch lost)")
        code, out, err = cli.interrupt_and_finish()
    finally:
        cli.kill()
    assert code == 1, (out, err)
    assert "error: recorded nothing: no telemetry frame" in err
    assert f"{bad + BAD_IN_A_ROW} message(s) refused" in err
    assert "| missed" not in out                            # no 1.8e19 missed messages
    assert "Traceback" not in out + err


def test_record_watch_logs_what_it_refused(dictionary, hostile, tmp_path):
    """Telemetry among the hostile messages: recorded, exit 0, and the log's link
    statistics hold the refusals and the resynchronisations (not 1.8e19 missed)."""
    cli = Cli("record", "--watch", hostile.endpoint, "--folder", str(tmp_path), "--name",
              "mixed", "--wait", "60")
    try:
        hostile.wait_subscriber()
        hostile.hello(dictionary)
        cli.wait_for_line("recording to")
        bad = hostile_messages(hostile)
        hostile.valid_json(wire.TOPIC_LINK, {"state": "up", "message": ""}, seq=2**64 - 1)
        for chunk in telemetry_chunks(dictionary, 0.5):
            hostile.frames([chunk])
        line = cli.wait_for_line(f"bad {bad} msg", "resync 2 msg", "HIGH_RATE")
        code, out, err = cli.interrupt_and_finish()
    finally:
        cli.kill()
    assert code == 0, (out, err)
    assert "Traceback" not in out + err and "| missed" not in line
    (path,) = sorted(tmp_path.glob("*.h5"))
    with LogReader(path) as log:
        assert log.n_frames("HIGH_RATE") >= 500
        (counts,) = [r.data for r in log.journal(["event"]) if r.data.get("source") == "watch"]
    assert counts["bad_messages"] == bad and counts["message_resyncs"] == 2
    assert counts["missed_messages"] == 0 and counts["messages"] > 0
    assert f"{bad} message(s) refused" in counts["text"]
