"""Command profiles: the generators' properties, the profile files (shipped and broken),
range checks before anything is sent, upload with CRC and sample-exact playback on the
simulated device, a corrupted block, Ctrl-C during playback, and the CLI."""

from __future__ import annotations

import contextlib
import threading
import zlib
from pathlib import Path

import numpy as np
import pytest

from groundstation.cli.main import main
from groundstation.profiles import waveforms as g
from groundstation.profiles.profile import WAVEFORMS_DIR, load_profile, profile_from_dict
from groundstation.profiles.samples import Profile, ProfileFileError
from groundstation.profiles.checks import check_profile
from groundstation.profiles.samples import ProfileRefused
from groundstation.profiles.summary import preview, summarise
from groundstation.profiles.upload import ProfilePlayer, ProfileUploadError, profile_id_for
from groundstation.sim import SimulatedDevice

from conftest import wait_for

RATE = 1200
SHIPPED = sorted(WAVEFORMS_DIR.glob("*.toml"))
ENC_LSB = 2 * np.pi / 2**32


def steady(x: np.ndarray, ramp_s: float) -> np.ndarray:
    n = int(round(ramp_s * RATE))
    return x[n:len(x) - n] if n else x


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def band_fraction(x: np.ndarray, lo: float, hi: float) -> float:
    """Share of the signal's power between lo and hi Hz."""
    p = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(len(x), 1 / RATE)
    return float(p[(f >= lo) & (f <= hi)].sum() / p.sum())


# ============================================================================ generators
def test_lengths_follow_the_duration():
    for x in (g.sine(2.5, 1.0, 3.0), g.swept_sine(2.5, 1.0, 1, 50), g.step(2.5, 1.0),
              g.band_limited_noise(2.5, 1.0, 1, 100)):
        assert len(x) == 3000
    assert len(g.ramp(1.0, 2.0, blend_s=0.1, duration_s=10.0)) == 12000
    assert len(g.triangle(1.0, 0.5, duration_s=10.0)) == 12000
    with pytest.raises(g.GeneratorError, match="too short"):
        g.triangle(1.0, 0.5, duration_s=5.0)


@pytest.mark.parametrize("method", ["fft", "butterworth"])
def test_noise_has_the_exact_rms_and_stays_in_its_band(method):
    x = g.band_limited_noise(20.0, 0.02, 5.0, 100.0, seed=7, ramp_s=1.0, method=method)
    assert len(x) == 24000
    assert rms(steady(x, 1.0)) == pytest.approx(0.02, rel=1e-12)
    if method == "fft":
        # brick wall before tapering; the 1 s tapers smear it by about 1 Hz
        assert band_fraction(x, 3.0, 102.0) > 0.9999
    else:
        assert band_fraction(x, 2.0, 200.0) > 0.999
    assert abs(np.mean(steady(x, 1.0))) < 0.02 * 0.05            # no DC to push the axis


def test_noise_is_reproducible_by_seed():
    a = g.band_limited_noise(2.0, 1.0, 1, 300, seed=3, ramp_s=0.5)
    assert np.array_equal(a, g.band_limited_noise(2.0, 1.0, 1, 300, seed=3, ramp_s=0.5))
    assert not np.allclose(a, g.band_limited_noise(2.0, 1.0, 1, 300, seed=4, ramp_s=0.5))


def test_noise_peaks_are_brought_under_a_limit_without_changing_rms_or_band():
    plain = g.band_limited_noise(20.0, 1.0, 5.0, 300.0, seed=3)
    assert np.abs(plain).max() > 3.0                              # Gaussian: crest factor ~4
    x = g.band_limited_noise(20.0, 1.0, 5.0, 300.0, seed=3, peak_limit=2.5)
    assert np.abs(x).max() <= 2.5
    assert rms(steady(x, 1.0)) == pytest.approx(1.0, rel=1e-12)
    assert band_fraction(x, 3.0, 302.0) > 0.9999
    with pytest.raises(g.GeneratorError, match="crest factor"):
        g.band_limited_noise(5.0, 1.0, 5.0, 300.0, peak_limit=1.1)


def test_triangle_runs_at_its_velocity_and_returns_to_rest():
    a, v, turn = np.radians(0.01), np.radians(0.001), 0.5
    x = g.triangle(a, v, cycles=2, turnaround_s=turn)
    assert len(x) == int(np.ceil((8 * a / v + turn) * RATE)) + 1
    slope = np.diff(x) * RATE
    at_speed = np.abs(np.abs(slope) - v) < 1e-6 * v
    assert at_speed.mean() > 0.96                                # constant velocity but in the 5 blends
    assert np.abs(slope).max() <= v * (1 + 1e-9)
    # raised-cosine reversals round the tips by 0.18 v turn, no more
    assert x.max() == pytest.approx(a - 0.1817 * v * turn, rel=1e-3)
    assert x[0] == 0 and x[-1] == 0


def test_constant_velocity_passes_cover_the_stroke_both_ways():
    v, stroke = np.radians(10.0), np.radians(30.0)
    x = g.constant_velocity(v, stroke, accel_s=0.3, dwell_s=0.5)
    slope = np.diff(x) * RATE
    assert np.isclose(slope.max(), v, rtol=1e-6) and np.isclose(slope.min(), -v, rtol=1e-6)
    assert x.max() == pytest.approx(stroke / 2, rel=1e-9) and x.min() == pytest.approx(-stroke / 2, rel=1e-9)
    at_speed = np.abs(np.abs(slope) - v) < 1e-6 * v
    assert at_speed.sum() / RATE == pytest.approx(2 * (stroke / v) - 0.3 * 2 - 0.3 * 2 + 0.3, abs=0.05)
    assert x[-1] == 0.0


def test_ramp_has_the_asked_slope_and_level():
    x = g.ramp(0.5, 20.0, hold_s=2.0, blend_s=0.5)
    slope = np.diff(x) * RATE
    assert slope.max() == pytest.approx(0.5 / 20.0, rel=1e-9)
    assert x.max() == pytest.approx(0.5, rel=1e-12) and x[-1] == 0.0
    up = g.ramp(0.5, 20.0, back=False, blend_s=0.5)
    assert up[-1] == 0.5


@pytest.mark.parametrize("shape,bound", [("raised_cosine", np.pi / 2), ("minimum_jerk", 15 / 8)])
def test_a_step_is_smoothed_unless_asked_raw(shape, bound):
    level, rise = 1e-3, 0.02
    x = g.step(2.0, level, t_step_s=0.5, rise_s=rise, shape=shape, return_at_s=1.0)
    slope = np.abs(np.diff(x)) * RATE
    assert slope.max() <= bound * level / rise * (1 + 1e-9)
    assert x[0] == 0 and x[-1] == pytest.approx(0, abs=1e-18) and x.max() == pytest.approx(level)
    raw = g.step(2.0, level, t_step_s=0.5, shape="raw")
    jumps = np.flatnonzero(np.diff(raw))
    assert list(jumps) == [599] and raw[600] == level


def test_prbs_has_two_levels_and_its_period():
    a, bits, spb = 0.05, 7, 3
    x = g.prbs(a, bits, samples_per_bit=spb, periods=3, ramp_s=0.5)
    period = (2**bits - 1) * spb
    assert len(x) == 3 * period + 2 * 600
    s = steady(x, 0.5)
    assert set(np.unique(s)) == {-a, a}
    assert np.array_equal(s[:period], s[period:2 * period])
    # a maximum-length sequence has one more 1 than 0 per period
    assert (s[:period] > 0).sum() == 2**(bits - 1) * spb
    assert x[0] == 0 and x[-1] == 0


def test_swept_sine_runs_over_its_frequency_range():
    f0, f1, d = 2.0, 50.0, 20.0
    x = g.swept_sine(d, 1.0, f0, f1, ramp_s=1.0)
    t = np.arange(len(x)) / RATE
    # instantaneous frequency from the zero crossings (interpolated between samples),
    # against the chirp's law
    up = np.flatnonzero((x[:-1] <= 0) & (x[1:] > 0))
    tc = t[up] + (-x[up] / (x[up + 1] - x[up])) / RATE
    f_meas = 1.0 / np.diff(tc)
    f_law = g.sweep_frequency(tc[:-1] + np.diff(tc) / 2, d, f0, f1)
    assert np.allclose(f_meas[2:-2], f_law[2:-2], rtol=0.02)
    assert f_meas[0] == pytest.approx(f0, rel=0.1) and f_meas[-1] == pytest.approx(f1, rel=0.05)
    assert band_fraction(x, f0 * 0.5, f1 * 1.1) > 0.999


def test_multisine_is_in_band_on_its_grid_with_exact_rms():
    x = g.multisine(0.05, 2.0, 200.0, n_freqs=40, period_s=10.0, periods=2, ramp_s=1.0)
    s = steady(x, 1.0)
    assert len(s) == 2 * 12000
    assert rms(s) == pytest.approx(0.05, rel=1e-12)
    spec = np.abs(np.fft.rfft(s[:12000]))
    f = np.fft.rfftfreq(12000, 1 / RATE)
    lines = f[spec > 1e-6 * spec.max()]
    expected = g.multisine_frequencies(2.0, 200.0, 40, 10.0)
    assert np.allclose(lines, expected)                          # nothing between the grid lines
    assert lines.min() >= 2.0 and lines.max() <= 200.0
    schroeder = g.multisine(0.05, 2.0, 200.0, n_freqs=40, period_s=10.0, phases="schroeder", ramp_s=0)
    assert np.abs(s).max() < np.abs(schroeder).max()              # the phase iteration lowers the peaks


ALL_WAVEFORMS = {
    "step": lambda: g.step(3.0, 1.0, rise_s=0.1),
    "ramp": lambda: g.ramp(1.0, 1.0, hold_s=0.5, blend_s=0.2),
    "triangle": lambda: g.triangle(1.0, 2.0, turnaround_s=0.2),
    "constant_velocity": lambda: g.constant_velocity(2.0, 2.0, accel_s=0.2),
    "sine": lambda: g.sine(3.0, 1.0, 7.0),
    "swept_sine": lambda: g.swept_sine(3.0, 1.0, 1.0, 50.0),
    "noise": lambda: g.band_limited_noise(3.0, 1.0, 1.0, 100.0),
    "prbs": lambda: g.prbs(1.0, 6, samples_per_bit=4),
    "multisine": lambda: g.multisine(1.0, 1.0, 100.0, period_s=2.0),
}


@pytest.mark.parametrize("kind", sorted(ALL_WAVEFORMS))
def test_every_waveform_starts_at_rest_and_eases_in(kind):
    x = ALL_WAVEFORMS[kind]()
    d = np.abs(np.diff(x))
    assert x[0] == 0.0
    # zero slope at the start: the first step is a tiny fraction of the largest one
    # (steps and PRBS switch by design, but not in their first sample)
    assert d[0] <= 1e-3 * d.max()
    if kind != "step":                                           # a step ends at its level
        assert x[-1] == pytest.approx(0.0, abs=1e-12) and d[-1] <= 1e-3 * d.max()


def test_csv_data_are_resampled_onto_the_control_grid():
    t = np.arange(0, 1.001, 0.001)
    y = np.sin(2 * np.pi * 3 * t)
    x = g.resample_series(y, t)
    assert len(x) == 1201
    assert np.allclose(x, np.sin(2 * np.pi * 3 * np.arange(1201) / RATE), atol=2e-4)
    with pytest.raises(g.GeneratorError, match="increase"):
        g.resample_series(y[::-1], t[::-1])


# ============================================================================ files
@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_profiles_load_and_validate(path, dictionary):
    p = load_profile(path, dictionary)                           # validates, raises if refused
    check = check_profile(p, dictionary)
    assert check.ok and not check.warnings, check.warnings
    assert p.samples.dtype == np.float32 and p.samples[0] == 0
    assert p.source == str(path)
    doc = __import__("tomllib").loads(path.read_text())
    if "duration_s" in doc["profile"]:
        assert p.sample_count == round(doc["profile"]["duration_s"] * RATE)
    t, x, f, psd = preview(p)
    assert len(t) == len(x) == p.sample_count and f[-1] == pytest.approx(600.0, abs=0.5)
    assert psd.shape == f.shape and np.all(psd >= 0)


def test_the_thesis_building_blocks_are_shipped(dictionary):
    names = {p.stem for p in SHIPPED}
    assert {"friction_triangle_0p01deg", "friction_triangle_0p05deg", "step_relative_1mrad",
            "sweep_reference_1_100hz", "prbs_fine_current", "multisine_coarse_current",
            "pluck_fine_csv"} <= names
    for v in ("0p01", "0p1", "1", "10", "50"):
        p = load_profile(WAVEFORMS_DIR / f"velocity_ramp_{v}dps.toml", dictionary)
        speed = float(v.replace("p", "."))
        assert np.abs(np.diff(p.samples.astype(float))).max() * RATE == pytest.approx(np.radians(speed), rel=1e-3)
    tri = load_profile(WAVEFORMS_DIR / "friction_triangle_0p05deg.toml", dictionary)
    assert np.median(np.abs(np.diff(tri.samples.astype(float)))) * RATE == pytest.approx(np.radians(0.001), rel=1e-3)
    for act, target in (("coarse", "CURRENT_COARSE"), ("fine", "CURRENT_FINE")):
        low = load_profile(WAVEFORMS_DIR / f"sysid_{act}_noise_0p02A.toml", dictionary)
        high = load_profile(WAVEFORMS_DIR / f"sysid_{act}_noise_1A.toml", dictionary)
        assert low.target == high.target == target
        assert rms(steady(low.samples.astype(float), 1.0)) == pytest.approx(0.02, rel=1e-6)
    assert np.abs(high.samples).max() <= 1.0                     # the fine actuator's range


def write(tmp_path: Path, text: str, name: str = "p.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


GOOD = """
[profile]
name = "t"
target = "CURRENT_COARSE"
units = "A"
duration_s = 2.0
ramp_s = 0.5
[generator]
type = "sine"
amplitude_ma = 20
frequency_hz = 5
"""

BROKEN = [
    ("[generator]\ntype='sine'\n", "no [profile] table"),
    (GOOD.replace('"CURRENT_COARSE"', '"TORQUE"'), "target 'TORQUE' is not one of"),
    (GOOD.replace('units = "A"', 'units = "mA"'), "CURRENT_COARSE samples are in 'A'"),
    (GOOD.replace("amplitude_ma", "amplitude"), "amplitude is missing: give it with its unit, e.g. amplitude_a"),
    (GOOD.replace("amplitude_ma = 20", "amplitude_ma = 20\namplitude_a = 0.02"), "both give amplitude"),
    (GOOD.replace("amplitude_ma", "amplitude_deg"), "amplitude_deg: 'deg' is not a unit of a CURRENT_COARSE profile's amplitude (a, ma)"),
    (GOOD.replace("frequency_hz = 5", "frequency_hz = 5\nphase_deg = 3"), "unknown key phase_deg for a sine generator on CURRENT_COARSE"),
    (GOOD.replace("frequency_hz = 5", "frequency_hz = 'fast'"), "frequency_hz must be a number"),
    (GOOD.replace("frequency_hz = 5", "frequency_hz = 700"), "not below the Nyquist frequency"),
    (GOOD.replace("duration_s = 2.0\n", ""), "duration_s is missing (a sine profile needs it)"),
    (GOOD.replace('type = "sine"', 'type = "square"'), "type = 'square' is not one of"),
    (GOOD.replace("ramp_s = 0.5", "ramp_s = 1.5"), "do not fit"),
    (GOOD + "\n[extra]\n", "unknown table [extra]"),
    (GOOD.replace('units = "A"', 'units = "A"\norigin = "relative"'), "applies to REFERENCE profiles only"),
    (GOOD.replace("name = ", "name = = "), "malformed TOML"),
]


@pytest.mark.parametrize("text,message", BROKEN, ids=[m[:30] for _, m in BROKEN])
def test_malformed_files_name_file_and_field(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(ProfileFileError) as exc:
        load_profile(path)
    assert message in str(exc.value) and str(path) in str(exc.value)


def test_csv_problems_name_the_csv(tmp_path):
    (tmp_path / "d.csv").write_text("time_s,current_a\n0,0\n0.5,0.1\n1.0,0\n")
    text = """
[profile]
name = "c"
target = "CURRENT_FINE"
units = "A"
[generator]
type = "csv"
file = "d.csv"
time_column = "time_s"
column = "%s"
"""
    p = load_profile(write(tmp_path, text % "current_a"))
    assert p.sample_count == 1201 and p.samples.max() == pytest.approx(0.1)
    with pytest.raises(ProfileFileError, match="'voltage' is not in d.csv's header"):
        load_profile(write(tmp_path, text % "voltage"))
    (tmp_path / "d.csv").write_text("time_s,current_a\n0,0.1\n1,0\n")
    with pytest.raises(ProfileRefused, match="first sample is 0.1 A, not the rest value"):
        load_profile(write(tmp_path, text % "current_a"))


def test_out_of_range_profiles_are_refused(tmp_path, dictionary):
    with pytest.raises(ProfileRefused, match=r"outside the CURRENT_FINE range -1 … 1 A"):
        load_profile(write(tmp_path, GOOD.replace("CURRENT_COARSE", "CURRENT_FINE")
                           .replace("amplitude_ma = 20", "amplitude_a = 1.2")), dictionary)
    with pytest.raises(ProfileRefused, match=r"outside the REFERENCE range"):
        load_profile(write(tmp_path, GOOD.replace('"CURRENT_COARSE"', '"REFERENCE"').replace('"A"', '"rad"')
                           .replace("amplitude_ma = 20", "amplitude_deg = 21")), dictionary)
    long = Profile("long", "CURRENT_FINE", "A", np.zeros(2_400_001))
    assert "sample_count range 1 … 2400000" in check_profile(long, dictionary).problems[0]
    assert check_profile(Profile("max", "CURRENT_FINE", "A", np.zeros(2_400_000)), dictionary).ok
    # the bound itself passes, compared as the device does (f32)
    assert check_profile(Profile("edge", "CURRENT_COARSE", "A", [0.0, 2.53, 0.0]), dictionary).ok


def test_summary_and_preview_of_a_sine(dictionary):
    p = profile_from_dict({"profile": {"name": "s", "target": "CURRENT_FINE", "units": "A",
                                       "duration_s": 20.0, "ramp_s": 0.1},
                           "generator": {"type": "sine", "amplitude_a": 0.5, "frequency_hz": 12.5}})
    s = summarise(p)
    assert s.peak_frequency_hz == pytest.approx(12.5, abs=0.1)
    assert s.maximum == pytest.approx(0.5, rel=1e-6) and s.sample_count == 24000
    assert s.max_slope == pytest.approx(2 * np.pi * 12.5 * 0.5, rel=1e-3)
    t, x, f, psd = preview(p)
    assert np.trapezoid(psd, f) == pytest.approx(np.mean(x ** 2), rel=0.02)
    assert s.crc == zlib.crc32(p.samples.astype(">f4").tobytes())


# ============================================================================ device
class Rig:
    """A connected client on a manually clocked device, and every HIGH_RATE frame it sees."""

    def __init__(self, device, client):
        self.device = device
        self.client = client
        client.connect()
        self.frames: dict[str, list[np.ndarray]] = {k: [] for k in
                                                    ("tick", "profile_index", "profile_active",
                                                     "current_coarse", "current_fine", "reference")}
        self.lock = threading.Lock()
        client.subscribe(self._on_block)

    def _on_block(self, block) -> None:
        if block.name == "HIGH_RATE":
            with self.lock:
                for k, v in self.frames.items():
                    v.append(np.array(block[k]))

    @contextlib.contextmanager
    def clock(self, ticks: int = 24):
        """Ticks (and heartbeats) in the background, for steps that wait on telemetry."""
        stop = threading.Event()

        def run():
            n = 0
            while not stop.wait(0.003):
                self.device.run_ticks(ticks)
                n += ticks
                if n >= 240:
                    self.client.command("HEARTBEAT")
                    n = 0
        t = threading.Thread(target=run, daemon=True)
        t.start()
        try:
            yield
        finally:
            stop.set()
            t.join()

    def run(self, n: int) -> None:
        """n ticks from this thread, heartbeats between chunks (the watchdog is 1200 ticks)."""
        for _ in range(n // 300):
            self.device.run_ticks(300)
            self.client.command("HEARTBEAT")
        self.device.run_ticks(n % 300)
        last = self.device.firmware.tick
        wait_for(lambda: self.latest_tick() >= last)

    def latest_tick(self) -> int:
        with self.lock:
            return int(self.frames["tick"][-1][-1]) if self.frames["tick"] else -1

    def table(self, first: int, last: int) -> dict[str, np.ndarray]:
        """Columns for ticks first … last, one row per tick (no frame may be missing)."""
        with self.lock:
            cols = {k: np.concatenate(v) for k, v in self.frames.items()}
        ticks = cols["tick"].astype(np.int64)
        sel = (ticks >= first) & (ticks <= last)
        order = np.argsort(ticks[sel], kind="stable")
        out = {k: v[sel][order] for k, v in cols.items()}
        assert np.array_equal(out["tick"], np.arange(first, last + 1)), "telemetry lost on loopback"
        return out


@pytest.fixture
def rig(device, client):
    return Rig(device, client)


def noise_profile(seconds: float = 2.0, target: str = "CURRENT_COARSE") -> Profile:
    x = g.band_limited_noise(seconds, 0.02, 1.0, 300.0, seed=11, ramp_s=min(0.25, seconds / 4))
    return Profile("noise", target, "A", x, source="test")


def test_current_profile_plays_sample_exact_in_open_loop(rig, dictionary):
    device, client = rig.device, rig.client
    journal = []
    p = noise_profile(2.0)                              # 2400 samples: 10 blocks, the last partial
    with ProfilePlayer(client, dictionary, journal=lambda *a: journal.append(a)) as player:
        with rig.clock():
            rec = player.load(p)
        assert rec.crc == zlib.crc32(p.samples.astype(">f4").tobytes())
        assert rec.profile_id == profile_id_for(rec.crc)
        assert device.firmware.housekeeping()["active_profile"] == rec.profile_id
        assert np.array_equal(device.firmware.profile["samples"], p.samples.astype(np.float64))
        kind, record, blob = journal[0]
        assert kind == "profile" and record["action"] == "uploaded"
        assert (record["name"], record["target"], record["crc"], record["sample_count"],
                record["source"]) == ("noise", "CURRENT_COARSE", rec.crc, 2400, "test")
        assert blob == p.wire_bytes()
        client.command("SET_MODE", mode="OPEN_LOOP")
        client.command("ARM")
        start = player.start()
        rig.run(2400 + 60)
        result = player.wait_finished(timeout=5.0)
    assert result.completed and result.reason == "finished" and result.end_tick == start + 2401
    hr = rig.table(start + 1, start + 2460)
    k = np.arange(1, 2401)
    assert np.array_equal(hr["profile_index"][:2400], k)       # sample k-1 in the k-th period
    assert hr["profile_active"][:2400].all() and not hr["profile_active"][2400:].any()
    assert not hr["profile_index"][2400:].any()
    # each period's current command is that period's sample, to the 0.1 mA telemetry step
    assert np.abs(hr["current_coarse"][:2400] - p.samples).max() <= 0.5e-4 + 1e-9
    assert np.all(hr["current_coarse"][2400:] == hr["current_coarse"][2399])   # holds the last
    assert journal[-1][1]["action"] == "played" and journal[-1][1]["completed"]


def test_relative_reference_profile_plays_sample_exact(rig, dictionary):
    client = rig.client
    x = g.sine(1.0, 2e-4, 5.0, ramp_s=0.2)
    p = Profile("sine", "REFERENCE", "rad", x, origin="relative")
    with ProfilePlayer(client, dictionary) as player:
        client.command("SET_MODE", mode="RELATIVE")
        with rig.clock():
            arm = client.command("ARM")
            held = player.held_reference(arm.stages[-1].device_tick)
            rec = player.load(p, offset=held)
        assert rec.offset == held and rec.origin == "relative"
        start = player.start()
        rig.run(1200 + 12)
        assert player.wait_finished(timeout=5.0).completed
    hr = rig.table(start + 1, start + 1200)
    sent = p.wire_samples(held).astype(np.float64)
    assert sent[0] == np.float32(held)                  # starts where the axis is held
    assert np.abs(hr["reference"] - sent).max() <= ENC_LSB / 2 + 1e-15
    assert np.array_equal(hr["profile_index"], np.arange(1, 1201))


def test_out_of_range_profile_is_refused_before_anything_is_sent(rig, dictionary):
    bad = Profile("too much", "CURRENT_FINE", "A", g.sine(1.0, 1.5, 5.0, ramp_s=0.2))
    before = rig.device.firmware.accepted
    with ProfilePlayer(rig.client, dictionary) as player:
        with pytest.raises(ProfileRefused, match="nothing was sent"):
            player.load(bad)
        with pytest.raises(ProfileRefused, match="plays in OPEN_LOOP, not RELATIVE"):
            player.play(noise_profile(0.5), "RELATIVE")
    assert rig.device.firmware.accepted == before and "profile" not in rig.device.firmware._staging


class CorruptingClient:
    """Passes commands to the real client, flipping one bit in one PROFILE_WRITE block:
    a transfer error the frame CRC did not catch (e.g. in the host's memory)."""

    def __init__(self, client, block: int):
        self._client, self._block, self._n = client, block, 0

    def command(self, name, **args):
        if name == "PROFILE_WRITE":
            if self._n == self._block:
                data = bytearray(args["samples"])
                data[5] ^= 0x01
                args["samples"] = bytes(data)
            self._n += 1
        return self._client.command(name, **args)

    def __getattr__(self, name):
        return getattr(self._client, name)


def test_a_corrupted_block_fails_the_commit_and_keeps_the_loaded_profile(rig, dictionary):
    device = rig.device
    first = noise_profile(1.0)
    with rig.clock():
        with ProfilePlayer(rig.client, dictionary) as player:
            good = player.load(first)
        second = noise_profile(1.5, "CURRENT_FINE")
        with ProfilePlayer(CorruptingClient(rig.client, block=3), dictionary) as player:
            with pytest.raises(ProfileUploadError, match="CRC_MISMATCH.*previously loaded profile stays loaded"):
                player.load(second)
    fw = device.firmware
    assert fw.profile["profile_id"] == good.profile_id and fw.profile["target"] == 2
    assert np.array_equal(fw.profile["samples"], first.samples.astype(np.float64))
    assert fw.housekeeping()["active_profile"] == good.profile_id


def test_interrupted_playback_leaves_the_device_safe(rig, dictionary):
    device = rig.device
    p = noise_profile(10.0)

    def interrupt(index, count):
        if index > 0:
            raise KeyboardInterrupt

    with rig.clock():
        with ProfilePlayer(rig.client, dictionary) as player:
            with pytest.raises(KeyboardInterrupt):
                player.play(p, progress=interrupt)
    fw = device.firmware
    assert not fw.armed and not fw.profile_active and fw.mode == 0   # PROFILE_STOP + ABORT: idle
    assert fw.fault == 0
    assert player.made_safe and player.safe_failures == []


def test_a_stopped_playback_is_reported_as_such(rig, dictionary):
    with ProfilePlayer(rig.client, dictionary) as player:
        with rig.clock():
            player.load(noise_profile(2.0))
        rig.client.command("SET_MODE", mode="OPEN_LOOP")
        rig.client.command("ARM")
        start = player.start()
        rig.run(100)
        player.stop()
        rig.run(20)
        result = player.wait_finished(timeout=5.0)
    assert not result.completed and result.reason == "stopped"
    assert result.samples_played == 100 and result.end_tick == start + 101
    assert "ended early (stopped) after 100 of 2400 samples" in result.text()


# ============================================================================ CLI
def run_cli(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_show(tmp_path, capsys):
    out_csv = tmp_path / "samples.csv"
    code, out, err = run_cli(capsys, "profile", "show", str(WAVEFORMS_DIR / "sine_reference_1hz.toml"),
                             "--csv", str(out_csv))
    assert code == 0, err
    assert "target:   REFERENCE (rad, origin relative)" in out and "12000 samples" in out
    assert "spectrum: peak at 1 Hz" in out and "OK: the profile may be played" in out
    rows = out_csv.read_text().splitlines()
    assert rows[1] == "time_s,reference_rad" and len(rows) == 2 + 12000
    values = np.array([float(r.split(",")[1]) for r in rows[2:]], dtype=np.float32)
    assert np.array_equal(values, load_profile(WAVEFORMS_DIR / "sine_reference_1hz.toml").samples)
    code, out, err = run_cli(capsys, "profile", "show",
                             str(write(tmp_path, GOOD.replace("amplitude_ma = 20", "amplitude_a = 3"))))
    assert code == 1 and "REFUSED" in out and "outside the CURRENT_COARSE range" in out
    code, out, err = run_cli(capsys, "profile", "show", str(write(tmp_path, "[profile]\n", "bad.toml")))
    assert code == 2 and "bad.toml" in err
    code, out, err = run_cli(capsys, "profile", "show", str(tmp_path / "missing.toml"))
    assert code == 2 and "profile file not found" in err


@pytest.fixture
def live_device(dictionary):
    # speed 2: the client's 0.2 s heartbeat is then 480 ticks, well inside the 1200-tick
    # watchdog even on a busy machine (at 5 it would be exactly 1200)
    dev = SimulatedDevice(dictionary, pacing="realtime", speed=2.0, seed=2).start()
    yield dev
    dev.stop()


def test_cli_play(live_device, tmp_path, capsys):
    dev = live_device
    path = write(tmp_path, GOOD.replace("duration_s = 2.0", "duration_s = 1.0").replace("ramp_s = 0.5", "ramp_s = 0.25"))
    address = f"127.0.0.1:{dev.tcp_port}"
    code, out, err = run_cli(capsys, "profile", "play", str(path), "--device", address)
    assert code == 0, err
    assert "played all 1200 samples" in out and "done: disarmed" in out
    fw = dev.firmware
    assert not fw.armed and not fw.profile_active and fw.mode == 1      # disarmed, mode kept
    assert np.array_equal(fw.profile["samples"],
                          load_profile(path).samples.astype(np.float64))
    accepted = fw.accepted
    code, out, err = run_cli(capsys, "profile", "play", str(path), "--device", address,
                             "--mode", "INERTIAL")
    assert code == 1 and "plays in OPEN_LOOP, not INERTIAL; nothing was sent" in err
    code, out, err = run_cli(capsys, "profile", "play", str(write(tmp_path, GOOD.replace(
        "amplitude_ma = 20", "amplitude_a = 3"))), "--device", address)
    assert code == 1 and "refused, nothing was sent" in err
    code, out, err = run_cli(capsys, "profile", "play", str(tmp_path / "none.toml"), "--device", address)
    assert code == 2
    assert fw.accepted == accepted                                      # none of them sent anything


def test_an_abort_is_named_as_the_cause_not_the_disarm_it_brings(client):
    """The device reports DISARMED before ABORTED in the period of an ABORT; the reason a
    playback ended is the abort."""
    from groundstation.profiles.upload import _Monitor
    monitor = _Monitor(client)
    try:
        monitor.since = 100
        monitor.events = [(90, "FAULT"), (150, "DISARMED"), (150, "ABORTED"), (151, "MODE_CHANGED")]
        assert monitor.end_event() == "ABORTED"
        monitor.events = [(150, "DISARMED"), (160, "ABORTED")]
        assert monitor.end_event() == "DISARMED"           # a disarm first is a disarm
    finally:
        monitor.close()
