"""Shared fixtures: the real dictionary, a simulated device on loopback, a client."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import time

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
# the numerics cache (core/numerics_cache.py) is this run's own, inherited by every
# process a test starts: the tests neither read a user's cache nor leave files in it
_NUMERICS_CACHE = tempfile.mkdtemp(prefix="gs-test-numerics-")
os.environ["GROUNDSTATION_CACHE_DIR"] = _NUMERICS_CACHE
atexit.register(shutil.rmtree, _NUMERICS_CACHE, True)

import numpy as np
import pytest

from groundstation.core.dictionary import load_dictionary
from groundstation.link import open_client
from groundstation.sim import SimulatedDevice


def wait_for(predicate, timeout: float = 30.0, interval: float = 0.005):
    """Poll until predicate() is true; bounded, so a broken link fails instead of hanging.
    The bound is a hang guard, not a speed requirement: generous, because a machine with
    both cores saturated by other work (make test-stressed) can hold a receiving thread
    off the CPU for seconds (5 s was too short for a loopback event at load 8)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(interval)
    raise AssertionError(f"condition not met within {timeout} s")


def process_alive(pid: int) -> bool:
    """A process that exists and is not a zombie (Linux /proc)."""
    from pathlib import Path

    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def collect(client):
    """Every telemetry block the client hands on, in a list (the test reads it)."""
    blocks = []
    client.subscribe(blocks.append)
    return blocks


def frames_of(blocks, name):
    return sum(len(b) for b in blocks if b.name == name)


class HighRateFeeder:
    """HIGH_RATE frames through encode -> StreamDeframer -> store(block), as a live link
    delivers them: feed(seq, **columns) with seq the sequence numbers (also the ticks)."""

    def __init__(self, dictionary, store):
        from groundstation.codec import FrameCodec, StreamDeframer

        self.codec = FrameCodec(dictionary)
        self.deframer = StreamDeframer(self.codec)
        self.store = store

    def __call__(self, seq, host_time: float = 1.7e9, **values):
        seq = np.asarray(seq)
        data = self.codec.encode("HIGH_RATE", values, seq, seq)
        for block in self.deframer.feed(data, host_time):
            self.store(block)

    high_rate = __call__


@pytest.fixture(autouse=True)
def _private_data_home(tmp_path_factory, monkeypatch):
    """Parameter history and other per-user files go to a temporary folder, never to the
    home directory of whoever runs the tests."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path_factory.mktemp("data_home")))


@pytest.fixture(scope="session")
def dictionary():
    return load_dictionary()


@pytest.fixture
def strip_chart(qtbot, dictionary):
    """Make a strip-chart panel on (offscreen) screen with its refresh timer stopped, so
    the test refreshes by hand: strip_chart(store_seconds, (width, height))."""
    from groundstation.live.display_buffers import TelemetryStore
    from groundstation.gui.charts.panel import StripChartPanel

    def make(seconds: float, size: tuple[int, int]):
        panel = StripChartPanel(TelemetryStore(dictionary, seconds=seconds), dictionary)
        qtbot.addWidget(panel)
        panel.resize(*size)
        panel.show()
        qtbot.waitExposed(panel)
        panel._timer.stop()
        return panel
    return make


@pytest.fixture
def device(dictionary):
    """A simulated device whose clock the test advances (pacing='manual')."""
    dev = SimulatedDevice(dictionary, pacing="manual", seed=1).start()
    yield dev
    dev.stop()


@pytest.fixture
def client(dictionary, device):
    """A started client on the device, not yet connected; heartbeat off (tests drive time)."""
    c = open_client(dictionary, f"127.0.0.1:{device.tcp_port}", heartbeat=False)
    yield c
    c.close()


@pytest.fixture
def gui_window(qtbot, dictionary, tmp_path):
    """A factory for the main window on a fresh Session, shown (offscreen), its settings in
    tmp_path: gui_window(store_seconds, confirm=("commands", ...), history=True,
    sim_speed=None).  `confirm`: the panels whose confirmation dialogs answer "Yes"
    (their confirm_override); `history`: the parameter history in tmp_path (False: the
    Session's default folder); `sim_speed`: the simulator's speed, set before the window
    is built.  Every Session made is shut down at teardown."""
    from PySide6.QtCore import QSettings

    from groundstation.gui.main_window import MainWindow
    from groundstation.gui.session.session import Session

    sessions = []

    def make(store_seconds: float, *, confirm: tuple[str, ...] = (), history: bool = True,
             sim_speed: float | None = None):
        kwargs = {"param_history": tmp_path / "history"} if history else {}
        session = Session(dictionary, store_seconds=store_seconds, **kwargs)
        sessions.append(session)
        if sim_speed is not None:
            session.sim_speed = sim_speed
        settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
        win = MainWindow(session, settings)
        qtbot.addWidget(win)
        win.show()
        for panel in confirm:
            getattr(win, panel).confirm_override = True
        return win

    yield make
    for session in sessions:
        session.shutdown()


@pytest.fixture
def numerics_cache(tmp_path, monkeypatch):
    """An empty numerics cache of the test's own (core/numerics_cache.py), the plant's
    sampled model forgotten in memory too, so that what the test computes is written
    here; the folder (not created yet)."""
    from groundstation.core.numerics_cache import CACHE_ENV
    from groundstation.plant import model as plant_model

    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "numerics-cache"))
    plant_model._discretised.cache_clear()
    return tmp_path / "numerics-cache"


def in_fresh_interpreter(code: str, **env: str):
    """What a fresh interpreter running `code` (with `env` added to this one's) prints as
    JSON on its last line."""
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         timeout=120, env={**os.environ, **env}).stdout
    return json.loads(out.splitlines()[-1])

