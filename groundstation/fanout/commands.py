"""The command line's watching and publishing: `monitor --watch`, `record --watch`,
`monitor --publish` and `fanout keys` (cli.py parses, these run).

A watching command never commands the rig: it opens a WatchClient on the commander's
publisher, prints or records what it decodes, and ends on Ctrl-C, SIGTERM or
--duration.  Exit status as `monitor`/`record`: 0 ended as asked, 1 the recording
failed or the watch yielded nothing it should have (the reader stopped on an error; no
telemetry frame decoded or recorded in the whole watch), 2 nothing could start (no
publisher, bad keys).  What the console refused (schema.py) is counted live ("bad N
msg") and each reason printed, and the watch says "lost" when the stream stops making
sense (fanout/viewer.py): a hostile or broken publisher never ends it silently.
"""

from __future__ import annotations

import sys
import time
from ..core.kinds import LinkState

EXIT_OK, EXIT_FAILED, EXIT_REFUSED = 0, 1, 2


def open_viewer(args, dictionary):
    """A started WatchClient on --watch that has heard the publisher's hello."""
    from .viewer import WatchClient

    viewer = WatchClient(dictionary, args.watch, curve_keys=args.curve_keys,
                         key_name=args.key_name)
    viewer.start()
    try:
        viewer.wait_up(timeout=args.wait)
    except BaseException:
        viewer.close()
        raise
    return viewer


def describe(viewer) -> str:
    hello = viewer.hello
    device = (hello.get("device") or {}).get("address", "?")
    return (f"watching {viewer.endpoint} (read-only): device {device}, protocol "
            f"{hello.get('protocol', '?')}, the commander's link {hello.get('link_state', '?')}")


def status_line(viewer) -> str:
    """The live line: this console's statistics, what it missed or refused, and the
    commander's state - from its last hello only while the watch is up (a stale hello
    is not news)."""
    from ..link.stats import format_snapshot

    c = viewer.counters
    extra = "".join(f" | {label} {n} msg" for label, n in (
        ("missed", c.missed_messages), ("bad", c.bad_messages),
        ("resync", c.message_resyncs)) if n)
    if viewer.link_state == LinkState.UP and viewer.hello.get("link_state") is None:
        commander = "commander: no device link (its session ended)"
    elif viewer.link_state == LinkState.UP:
        commander = (f"commander: {viewer.hello.get('link_state', '?')}, "
                     f"drop={viewer.hello.get('dropped', '?')}")
    else:
        commander = f"commander: unknown (watch {viewer.link_state})"
    return f"{format_snapshot(viewer.stats.snapshot())}{extra} | {commander}"


class _NewErrors:
    """Each refusal or resynchronisation the viewer noted, printed once."""

    def __init__(self, viewer):
        self.viewer, self.seen = viewer, set()

    def print(self) -> None:
        for err in list(self.viewer.counters.recent_errors):
            if id(err) not in self.seen:
                self.seen.add(id(err))
                print(f"  watch: {err}", flush=True)
        if len(self.seen) > 1000:           # ids of errors gone from the deque
            self.seen = {id(e) for e in self.viewer.counters.recent_errors}


def _frames(viewer) -> int:
    return sum(p.frames for name, p in viewer.stats.snapshot().packets.items()
               if name != "RESPONSE")


def _ending(viewer) -> str:
    """What the watch came to, for the last line: refusals, and a watch not up."""
    c = viewer.counters
    notes = [f"{c.bad_messages} message(s) refused"] if c.bad_messages else []
    if c.message_resyncs:
        notes.append(f"{c.message_resyncs} resynchronisation(s) of the message sequence")
    if viewer.link_state not in (LinkState.UP, LinkState.CLOSED):
        notes.append(f"the watch was {viewer.link_state}: {viewer.link_error}")
    return "; ".join(notes)


def watch_monitor(args, dictionary) -> int:
    from ..core.stop_request import StopRequest

    with StopRequest() as stop:
        viewer = open_viewer(args, dictionary)
        try:
            print(describe(viewer), flush=True)
            viewer.add_remote_listener(
                lambda state, message: print(f"commander's link {state}: {message}", flush=True))
            viewer.add_link_listener(
                lambda state, message: print(f"watch {state}: {message}", flush=True))
            errors = _NewErrors(viewer)
            t_end = time.monotonic() + args.duration if args.duration else None
            while not stop.event.wait(args.interval):
                print(status_line(viewer), flush=True)
                errors.print()
                if viewer.failure is not None or viewer.ended:
                    break
                if t_end is not None and time.monotonic() >= t_end:
                    break
            errors.print()
            if stop.reason:
                print(f"stopped: {stop.reason}", flush=True)
            if ending := _ending(viewer):
                print(f"watch: {ending}", flush=True)
            if viewer.failure is not None:
                print(f"error: {viewer.failure}", file=sys.stderr, flush=True)
                return EXIT_FAILED
            if _frames(viewer) == 0:
                print(f"error: no telemetry frame decoded from {viewer.endpoint} in the whole "
                      f"watch" + (f" ({ending})" if ending else ""), file=sys.stderr, flush=True)
                return EXIT_FAILED
            return EXIT_OK
        finally:
            viewer.close()


def watch_record(args, dictionary) -> int:
    """A normal log of what the viewer decodes, with the commander's command journal
    and link events, and this console's own link statistics (its own gaps, and the
    messages it refused: `framing` of the log's link records)."""
    from ..logs.live import attach_recorder, recorder_from_args
    from ..plant.testbed import load_testbed
    from ..core.stop_request import StopRequest

    testbed = load_testbed(args.testbed) if args.testbed else None
    failures: list[str] = []
    with StopRequest() as stop:
        viewer = open_viewer(args, dictionary)
        rec = recorder_from_args(dictionary, args, testbed, failures.append)
        try:
            path = rec.start()
            print(f"recording to {path}\n{describe(viewer)}", flush=True)
            detach = attach_recorder(viewer, rec)
            viewer.add_remote_listener(lambda state, message: rec.record(
                "event", {"source": "commander link", "state": state, "message": message}))
            viewer.add_link_listener(
                lambda state, message: print(f"watch {state}: {message}", flush=True))
            rec.record("note", {"text": f"{describe(viewer)}"
                                + (f"; {args.notes}" if args.notes else "")})
            code, reason = _record_loop(args, viewer, rec, stop, failures)
            detach()
        finally:
            viewer.close()
        ending = _ending(viewer)
        if ending:
            reason = f"{reason}; {ending}"
        # the watch's final counts, in the log: its link records come once a second and
        # the last one may predate the last refusals
        rec.record("event", {"source": "watch", "text": ending or "nothing refused",
                             **viewer.counters.as_dict()})
        st = rec.stop(reason=reason)
        print(f"recorded {st.frames} frames in {len(st.files)} file(s): "
              + ", ".join(str(p) for p in st.files) + f" - {reason}", flush=True)
        if code == EXIT_OK and st.frames == 0:
            print(f"error: recorded nothing: no telemetry frame from {viewer.endpoint} in the "
                  f"whole watch" + (f" ({ending})" if ending else ""), file=sys.stderr, flush=True)
            return EXIT_FAILED
        return code


def _record_loop(args, viewer, rec, stop, failures) -> tuple[int, str]:
    t_end = time.monotonic() + args.duration if args.duration else None
    errors = _NewErrors(viewer)
    while True:
        errors.print()
        if failures:
            print(f"error: {failures[0]}", flush=True)
            return EXIT_FAILED, failures[0]
        if viewer.failure is not None:
            print(f"error: {viewer.failure}", file=sys.stderr, flush=True)
            return EXIT_FAILED, viewer.failure
        if (reason := stop.ending(t_end, args.duration)) is not None:
            return EXIT_OK, reason
        if not stop.status_due(t_end):
            continue
        st = rec.status()
        print(f"{st.path.name if st.path else ''}: {st.frames} frames | {status_line(viewer)}",
              flush=True)


def make_keys(args) -> int:
    from .keys import make_keys as make

    for path in make(args.folder, args.name):
        print(f"wrote {path}")
    print(f"publisher: --publish tcp://0.0.0.0:PORT --curve-keys {args.folder}; a viewer "
          f"machine needs publisher.public, {args.name}.public and {args.name}.secret "
          f"(--watch tcp://HOST:PORT --curve-keys DIR --key-name {args.name})")
    return EXIT_OK


def start_publisher(args):
    """The Publisher for --publish (None without it); attach() it to each new client."""
    if not getattr(args, "publish", None):
        return None
    from .publisher import Publisher

    pub = Publisher(args.publish, curve_keys=args.curve_keys)
    print(f"publishing on {pub.endpoint} (read-only consoles: groundstation gui --watch "
          f"{pub.endpoint})", flush=True)
    return pub
