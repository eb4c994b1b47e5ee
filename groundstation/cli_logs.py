"""`groundstation record | log ... | replay`: the logging commands of the CLI."""

from __future__ import annotations

import argparse
import signal
import threading
import time
from pathlib import Path

from .dictionary import load_dictionary
from .errors import GroundStationError


def _cmd_record(args) -> int:
    from .link import format_snapshot, open_client
    from .logs import Recorder
    from .logs.live import attach_recorder
    from .sim.process import SimulatorProcess
    from .sim.testbed import load_testbed

    d = load_dictionary(args.protocol_dir)
    testbed = load_testbed(args.testbed) if args.testbed else None
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    sim = None
    address = args.device
    if address == "sim":
        sim = SimulatorProcess(pacing="realtime", testbed=args.testbed)
        address = sim.start()
        print(f"started the simulated testbed on {address}", flush=True)
    failures: list[str] = []
    try:
        client = open_client(d, address)
        try:
            rec = Recorder(d, args.folder, test_name=args.name, notes=args.notes,
                           testbed_text=testbed.text if testbed else "",
                           testbed_name=testbed.name if testbed else "",
                           testbed_path=str(testbed.path) if testbed else "",
                           rollover_bytes=int(args.rollover_mb * 1e6) if args.rollover_mb else None,
                           rollover_seconds=args.rollover_min * 60 if args.rollover_min else None,
                           on_failure=failures.append)
            path = rec.start()
            attach_recorder(client, rec)
            print(f"recording to {path}", flush=True)
            client.connect(take_over=args.take_over)
            if args.notes:
                rec.note(args.notes)
            t_end = time.monotonic() + args.duration if args.duration else None
            try:
                while not stop.wait(1.0):
                    st = rec.status()
                    print(f"{st.path.name if st.path else ''}: {st.frames} frames, "
                          f"{st.bytes / 1e6:.1f} MB | {format_snapshot(client.stats.snapshot())}",
                          flush=True)
                    if failures or client.link_state != "up":
                        break
                    if t_end is not None and time.monotonic() >= t_end:
                        break
            except KeyboardInterrupt:
                pass
            st = rec.stop()
            if client.link_state != "up":
                print(f"link {client.link_state}: {client.link_error}", flush=True)
            if failures:
                print(f"error: {failures[0]}", flush=True)
                return 1
            print(f"recorded {st.frames} frames in {len(st.files)} file(s): "
                  + ", ".join(str(p) for p in st.files), flush=True)
            return 0 if client.link_state == "up" else 1
        finally:
            client.close()
    finally:
        if sim is not None:
            sim.stop()


def add_parsers(sub) -> None:
    s = sub.add_parser("record", help="record a session to HDF5 (from the simulator or a rig)")
    s.add_argument("--device", default="sim",
                   help="sim | tcp://HOST:PORT | serial://PORT?baud=N (default: sim)")
    s.add_argument("--testbed", default=None, help="testbed file (recorded in the log; for sim: the one to run)")
    s.add_argument("--folder", default="logs", help="folder for the log files (default: logs/)")
    s.add_argument("--name", default="test", help="test name, part of the file name")
    s.add_argument("--notes", default="", help="operator notes stored in the log")
    s.add_argument("--duration", type=float, default=0.0, help="seconds (0: until Ctrl-C)")
    s.add_argument("--rollover-mb", type=float, default=0.0, help="start a new file after this size")
    s.add_argument("--rollover-min", type=float, default=0.0, help="start a new file after this time")
    s.add_argument("--take-over", action="store_true", help="take the session from another host")
    s.set_defaults(func=_cmd_record)
