"""The Analysis dock on what the window shows: the "Live window" row (the telemetry the
window's store holds, analysed like a log) and the logs the session has just recorded.

A store fed with made-up frames (a hole in the ticks, samples at the A/D rail) gives
the figures the array functions give on the same arrays; in the real window (offscreen)
against the in-process simulated device, the Live row's Metrics equal the array
functions on the very copy the job analysed, and equal analyze_log on the recording of
the same frames; a recording the session starts and stops is listed, not ticked."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from PySide6.QtCore import Qt

from groundstation.analysis import AnalysisError, analyze_log, control_energy, los_jitter, psd
from groundstation.analysis.jitter import sensor_valid
from groundstation.analysis.frame_gaps import frame_steps, missing_before
from groundstation.codec import FrameCodec, StreamDeframer
from groundstation.live.display_buffers import TelemetryStore
from groundstation.gui.analysis.live import LiveSnapshot, live_metrics, take_snapshot
from groundstation.gui.analysis.tables import METRIC_COLUMNS, VALUE_ROLE
from groundstation.plant.testbed import load_testbed
from groundstation.sim import SimulatedDevice

ROOT = Path(__file__).resolve().parents[2]
INERTIAL = ROOT / "profiles/testbeds/inertial_2dof.toml"
WAIT_MS = 30000
PERIOD_S = 0.25
ARRAY_FIGURES = ("mean_rad", "rms_rad", "std_rad", "highpass_rms_rad", "smear_rms_rad")


def press(qtbot, button) -> None:
    qtbot.mouseClick(button, Qt.MouseButton.LeftButton)


def table_rows(panel) -> list[dict]:
    t = panel.metrics_table
    return [{key: t.item(r, c).data(VALUE_ROLE) for c, (_, key, _) in enumerate(METRIC_COLUMNS)}
            for r in range(t.rowCount())]


def hr_frames(session) -> int:
    return session.store.ring("HIGH_RATE").total_frames


def expected_from_arrays(snap: LiveSnapshot, sensor: str, resistances, *, range_rad=None,
                         counts=None, segment_s=10.0):
    """The figures of the array functions on the snapshot's own arrays."""
    angle = snap.columns[sensor]
    gap, missing, _ = frame_steps(snap.columns["tick"].astype(np.uint32))
    ok = sensor_valid(angle, range_rad=range_rad, raw_counts=counts)
    jitter = los_jitter(angle, snap.rate_hz, integration_period_s=PERIOD_S, valid=ok,
                        gap_before=gap, missing_frames=missing,
                        missing_before=missing_before(snap.columns["tick"].astype(np.uint32)))
    energy = control_energy(snap.columns["current_coarse"], snap.columns["current_fine"],
                            snap.rate_hz, *resistances,
                            coarse_saturated=snap.columns["coarse_saturated"],
                            fine_saturated=snap.columns["fine_saturated"], missing_frames=missing)
    spectrum = psd(angle, snap.rate_hz, segment_s=segment_s, valid=ok, gap_before=gap)
    return jitter, energy, spectrum, missing


def assert_same(m, jitter, energy, spectrum) -> None:
    for name in ARRAY_FIGURES:
        assert getattr(m.jitter, name) == pytest.approx(getattr(jitter, name), rel=1e-9), name
    for name in ("samples_used", "samples_excluded", "segments", "missing_frames"):
        assert getattr(m.jitter, name) == getattr(jitter, name), name
    for name in ("energy_coarse_j", "energy_fine_j", "rms_current_coarse_a",
                 "rms_current_fine_a", "saturated_coarse_fraction", "saturated_fine_fraction"):
        assert getattr(m.energy, name) == pytest.approx(getattr(energy, name), rel=1e-9), name
    assert m.spectrum.segments == spectrum.segments
    # the accumulator's batched FFT and scipy's welch agree to rounding of the largest bin
    np.testing.assert_allclose(m.spectrum.density, spectrum.density, rtol=1e-9,
                               atol=1e-12 * spectrum.density.max())


# ---------------------------------------------------------------------- a store, no window
def test_a_store_with_lost_frames_and_rail_samples_gives_the_array_functions_figures(dictionary):
    codec = FrameCodec(dictionary)
    store = TelemetryStore(dictionary, seconds=10.0)
    item = dictionary.packet("HIGH_RATE").item_by_name["autocollimator"]
    rail = float(np.iinfo(item.wire_dtype).max) * item.scale
    rng = np.random.default_rng(7)
    n = 4000
    ticks = np.concatenate([np.arange(100, 2100), np.arange(2110, 4110)])   # 10 frames lost
    t = ticks / dictionary.control_rate_hz
    angle = 2e-4 * np.sin(2 * np.pi * 3.0 * t) + 2e-6 * rng.standard_normal(n)
    angle[[500, 501, 3000]] = rail                    # clipped by the A/D: excluded
    values = {"autocollimator": angle, "encoder_inner": angle,
              "current_coarse": 0.3 + 0.01 * rng.standard_normal(n),
              "current_fine": -0.1 + 0.01 * rng.standard_normal(n),
              "coarse_saturated": (np.arange(n) % 10 == 0).astype(int)}
    data = codec.encode("HIGH_RATE", values, ticks, ticks)
    for block in StreamDeframer(codec).feed(data, 5.0):
        store(block)
    session = SimpleNamespace(store=store, client=object(), replay=None, station=None,
                              testbed=str(INERTIAL))
    snap = take_snapshot(session, None)
    assert snap.frames == n and snap.name == "live window (all it holds)"

    m = live_metrics(snap, sensor="autocollimator", integration_period_s=PERIOD_S,
                     psd_segment_s=0.5)
    tb = load_testbed(INERTIAL)
    counts = item.to_raw(snap.columns["autocollimator"]).astype(np.int16)
    jitter, energy, spectrum, missing = expected_from_arrays(
        snap, "autocollimator", (tb.motor_coarse["resistance"], tb.motor_fine["resistance"]),
        range_rad=np.radians(tb.sensors["autocollimator_range"]), counts=counts, segment_s=0.5)
    assert missing == 10 and m.missing_frames == 10 and m.jitter.missing_frames == 10
    assert m.jitter.samples_excluded == 3 and "A/D rail" in m.jitter.exclusion_rule
    assert m.jitter.segments == 4                    # cut by the hole and by the rail samples
    assert_same(m, jitter, energy, spectrum)
    assert m.energy.saturated_coarse_fraction == pytest.approx(0.1)
    assert m.row()["log"] == m.label == "live window (all it holds)"
    rate = dictionary.control_rate_hz
    assert (m.window_from_s, m.window_to_s) == (100 / rate, 4109 / rate)
    assert "inertial_2dof.toml" in m.testbed_source

    # the last 1.0 s only; the testbed the operator chose wins over the session's
    last = take_snapshot(session, 1.0)
    assert last.name == "live window (last 1.0 s)"
    assert last.device_time[-1] - last.device_time[0] <= 1.0
    relative = ROOT / "profiles/testbeds/relative_2dof.toml"
    m1 = live_metrics(last, sensor="encoder_inner", integration_period_s=PERIOD_S,
                      testbed=str(relative))
    assert m1.frames == last.frames and m1.missing_frames == 0
    assert "relative_2dof.toml" in m1.testbed_source


def test_an_empty_store_is_said_not_analysed(dictionary):
    session = SimpleNamespace(store=TelemetryStore(dictionary, seconds=1.0), client=object(),
                              replay=None, station=None, testbed=None)
    with pytest.raises(AnalysisError, match="no HIGH_RATE frames yet"):
        live_metrics(take_snapshot(session, 30.0))


# ---------------------------------------------------------------------- the window
@pytest.fixture
def device(dictionary):
    """The simulated device in this process, in real time, on loopback."""
    dev = SimulatedDevice(dictionary, pacing="realtime", seed=3).start()
    yield dev
    dev.stop()


def connect(qtbot, window, device):
    session = window.session
    session.connect_address(f"tcp://127.0.0.1:{device.tcp_port}")
    qtbot.waitUntil(lambda: session.client is not None and session.client.link_state == "up"
                    and window.analysis.runs.has_live(), timeout=WAIT_MS)
    return session


def drive(qtbot, session) -> None:
    """Open loop with a little current on both motors: the inner axis moves, energy flows."""
    client = session.client
    for name, args in (("SET_MODE", {"mode": "OPEN_LOOP"}), ("ARM", {}),
                       ("SET_CURRENTS", {"current_coarse": 0.1, "current_fine": 0.05})):
        client.command(name, **args)
    start = hr_frames(session)
    qtbot.waitUntil(lambda: hr_frames(session) > start + 1500, timeout=WAIT_MS)


def test_the_live_row_gives_the_array_functions_figures_of_the_copy_it_took(
        qtbot, gui_window, device, tmp_path):
    window = gui_window(30.0)
    panel = window.analysis
    assert not panel.runs.has_live()                 # nothing feeds the charts yet
    session = connect(qtbot, window, device)
    assert not panel.runs.live_checked()             # listed, not ticked
    path = session.start_recording(str(tmp_path / "logs"), "live window")
    drive(qtbot, session)

    # FRF on the live window alone: said, nothing started
    panel.runs.set_live_checked(True)
    assert "Metrics only" in panel.status.text()
    press(qtbot, panel.frf_button)
    assert "Metrics only" in panel.status.text() and panel.jobs.idle()

    panel.sensor.setCurrentText("encoder_inner")     # the relative rig: no autocollimator
    panel.period.setValue(PERIOD_S)
    panel.options.live_seconds.setValue(1.0)
    with qtbot.waitSignal(panel.jobs.sig_metrics_done, timeout=WAIT_MS) as done:
        press(qtbot, panel.metrics_button)
    qtbot.waitUntil(lambda: panel.metrics_button.isEnabled(), timeout=WAIT_MS)
    batch = done.args[0]
    assert not batch.failures
    snap, m = batch.requested[0], batch.results[0]
    assert isinstance(snap, LiveSnapshot) and snap.seconds == 1.0
    assert 1000 < snap.frames and snap.device_time[-1] - snap.device_time[0] <= 1.0

    tb = load_testbed(ROOT / "profiles/testbeds/relative_2dof.toml")   # the Station's default
    jitter, energy, spectrum, missing = expected_from_arrays(
        snap, "encoder_inner", (tb.motor_coarse["resistance"], tb.motor_fine["resistance"]))
    assert_same(m, jitter, energy, spectrum)
    assert m.frames == snap.frames and m.missing_frames == missing
    assert jitter.std_rad > 0 and energy.energy_total_j > 0
    [row] = table_rows(panel)
    assert row["log"] == "live window (last 1.0 s)"
    assert row["std_urad"] == pytest.approx(jitter.std_rad * 1e6, rel=1e-9)
    assert row["energy_total_j"] == pytest.approx(energy.energy_total_j, rel=1e-9)
    assert (row["from_s"], row["to_s"]) == (snap.device_time[0], snap.device_time[-1])
    assert list(panel.spectra.psd_curves) == ["live window (last 1.0 s)"]

    # the recording holds the same frames: analyze_log over them gives the same figures
    session.stop_recording()
    assert Path(path).resolve() in panel.runs.paths()
    from groundstation.logs import LogReader
    with LogReader(path) as r:
        origin = r.origin("device")
    half = 0.5 / snap.rate_hz
    # (connected by address with no testbed chosen, the session records none: name it)
    logged = analyze_log(path, sensor="encoder_inner", integration_period_s=PERIOD_S, testbed=tb,
                         start_s=snap.device_time[0] - origin - half,
                         stop_s=snap.device_time[-1] - origin + half)
    assert logged.frames == m.frames and logged.missing_frames == m.missing_frames
    live_row = m.row()
    for key, value in logged.row().items():
        if key in ("log", "test_name", "from_s", "to_s"):      # the names and time bases
            continue
        if isinstance(value, float):
            assert live_row[key] == pytest.approx(value, rel=1e-12), key
        else:
            assert live_row[key] == value, key

    session.disconnect_link()
    qtbot.waitUntil(lambda: not panel.runs.has_live(), timeout=WAIT_MS)


def test_a_recording_started_and_stopped_is_listed_not_ticked(qtbot, gui_window, device,
                                                               tmp_path):
    window = gui_window(30.0)
    panel = window.analysis
    session = connect(qtbot, window, device)
    path = session.start_recording(str(tmp_path / "logs"), "just recorded")
    assert path is not None and Path(path).resolve() not in panel.runs.paths()
    qtbot.waitUntil(lambda: session.recorder.status().frames > 600, timeout=WAIT_MS)
    session.stop_recording()
    path = Path(path).resolve()
    assert path in panel.runs.paths()
    assert path not in panel.runs.checked_paths()     # listed, not ticked
    row = panel.runs.paths().index(path)
    rows = [r for r in range(panel.runs.rowCount()) if not panel.runs.is_live_row(r)]
    assert panel.runs.item(rows[row], 1).text() == "recorded"
    assert "listed" in panel.status.text() and path.name in panel.status.text()
    assert panel.runs.has_live()                      # the link still feeds the charts
    # Remove leaves the Live row: it follows the session
    panel.runs.selectAll()
    panel.runs.remove_selected()
    assert panel.runs.paths() == [] and panel.runs.has_live()
    # a replay feeds the charts too: the Live row stays while it is open, its tick kept
    panel.runs.set_live_checked(True)
    session.open_log(str(path))
    qtbot.waitUntil(lambda: panel.runs.paths() == [path] and panel.runs.has_live(),
                    timeout=WAIT_MS)
    assert panel.runs.live_checked() and panel.runs.checked_paths() == [path]
    session.close_replay()
    qtbot.waitUntil(lambda: not panel.runs.has_live(), timeout=WAIT_MS)
