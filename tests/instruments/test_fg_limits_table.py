"""The generator's limits table (`spec4050.LIMITS`) and its three consumers agree.

For every row of the table, into either load and at every end of its range: a value just
inside is taken and a value just outside is refused - by the driver before anything is
sent (the simulated generator's command log shows only read-back queries), and by the
simulated instrument itself (-222, the row's field named, nothing changed).  The GUI's
limit texts show the row's numbers for every waveform the row applies to.

The driver runs without testbed limits here, so only the instrument's limits decide."""

from __future__ import annotations

from dataclasses import astuple

import numpy as np
import pytest

from groundstation.instruments import InstrumentLimitError, open_generator
from groundstation.instruments import spec4050 as spec
from groundstation.sim.scpi_server import ScpiServer
from groundstation.sim.fg_instrument import SimulatedGenerator

CH = 1
#: a basic wave inside every row at either load: the state each case starts from
SAFE = dict(waveform="SINE", frequency_hz=1.0, amplitude_vpp=0.5, offset_v=0.0, phase_deg=0.0)


def _ends(row: spec.Limit, load: str) -> list[tuple[str, float, float]]:
    """(which end, a value just inside, a value just outside) for each reachable end of
    the row's range.  An `at_most` quantity cannot go below 0, so it has one end."""
    low, high = row.bounds(load)

    def beyond(bound: float, outward: float) -> float:
        if row.unit == "points":
            return bound + outward                           # a count moves by one
        return bound + outward * (abs(bound) * 1e-3 if bound else 1e-3)

    ends = [("high", high, beyond(high, +1))]
    if row.form != "at_most":
        ends.append(("low", low, beyond(low, -1)))
    return ends


CASES = [pytest.param(i, load, end, inside, outside,
                      id=f"{row.key}-{'+'.join(row.waveforms)}-{load}-{end}")
         for i, row in enumerate(spec.LIMITS) for load in spec.LOADS
         for end, inside, outside in _ends(row, load)]


def _wave_for(row: spec.Limit, value: float, load: str) -> dict:
    """A basic wave in which `value` is the only quantity near a limit of `row`."""
    if row.key == "offset":
        # a waveform without an amplitude, so the envelope does not decide first
        waveform = next(w for w in row.waveforms if spec.limit_for("envelope", w) is None)
        return dict(waveform=waveform, offset_v=value)
    waveform = row.waveforms[0]
    wave = dict(SAFE, waveform=waveform)
    if row.key == "envelope":
        # half the largest amplitude, the offset making up the rest: both inside their rows
        amplitude = spec.limit_for("amplitude", waveform).bounds(load)[1] / 2
        return dict(wave, amplitude_vpp=amplitude, offset_v=value - amplitude / 2)
    names = {"frequency": "frequency_hz", "amplitude": "amplitude_vpp", "phase": "phase_deg"}
    return dict(wave, **{names[row.key]: value})


def _samples(points: int) -> np.ndarray:
    return 0.1 * np.where(np.arange(points) % 2, -1.0, 1.0)


# ------------------------------------------------------------------ the driver
@pytest.fixture(scope="module")
def drivers():
    """One simulated generator and one driver per load, no testbed limits."""
    out = {}
    for load in spec.LOADS:
        srv = ScpiServer(SimulatedGenerator()).start()
        fg = open_generator(srv.resource, timeout_s=5.0)
        fg.configure(CH, **SAFE)
        fg.set_load(CH, load)
        out[load] = (fg, srv)
    yield out
    for fg, srv in out.values():
        fg.close()
        srv.stop()


def _driver_applies(fg, row: spec.Limit, value: float, load: str) -> None:
    if row.key == "points":
        fg.upload_arbitrary(CH, _samples(int(value)), name="EDGE", frequency_hz=1.0)
    else:
        fg.configure(CH, **_wave_for(row, value, load))


@pytest.mark.parametrize("index, load, end, inside, outside", CASES)
def test_the_driver_takes_inside_and_refuses_outside_sending_nothing(drivers, index, load, end,
                                                                     inside, outside):
    row = spec.LIMITS[index]
    fg, srv = drivers[load]
    g = srv.generator
    fg.configure(CH, **SAFE)

    _driver_applies(fg, row, inside, load)                     # just inside: taken
    c = g.channels[CH]
    if row.key == "points":
        assert len(g.user_waves["EDGE"].codes) == inside
    else:
        wave = _wave_for(row, inside, load)
        assert c.waveform == wave["waveform"] and c.load == load
        assert c.offset_v == pytest.approx(wave["offset_v"])
        if row.key in ("frequency", "amplitude", "phase"):
            held = {"frequency": c.frequency_hz, "amplitude": c.amplitude_vpp,
                    "phase": c.phase_deg}[row.key]
            assert held == inside

    fg.configure(CH, **SAFE)
    before = astuple(g.channels[CH])[:8]
    sent = len(g.command_log)
    with pytest.raises(InstrumentLimitError) as err:           # just outside: refused
        _driver_applies(fg, row, outside, load)
    text = str(err.value)
    assert err.value.setting == row.key and err.value.value == pytest.approx(outside)
    assert err.value.limit == (inside if row.form != "plus_minus" else abs(inside))
    assert row.range_text(load, plus_minus="+-", at_most="") in text
    assert f"{outside:g}" in text and "nothing was sent" in text
    if row.depends_on_load:
        assert f"into a {spec.LOAD_NAMES[load]} load" in text
    if spec.varies_by_waveform(row.key):
        assert f"for {row.waveforms[0]}" in text
    assert all(cmd.endswith("?") for cmd in list(g.command_log)[sent:])   # reads only
    assert astuple(g.channels[CH])[:8] == before


# ------------------------------------------------------------------ the simulated instrument
def _bswv(wave: dict) -> str:
    fields = {"frequency_hz": "FRQ", "amplitude_vpp": "AMP", "offset_v": "OFST",
              "phase_deg": "PHSE"}
    pairs = [f"WVTP,{wave['waveform']}"]
    pairs += [f"{fields[k]},{spec.format_number(v)}" for k, v in wave.items() if k in fields]
    return f"C{CH}:BSWV " + ",".join(pairs)


def _simulator_applies(g: SimulatedGenerator, row: spec.Limit, value: float, load: str
                       ) -> list[str]:
    """Send the setting straight to the instrument; return *ESR? and SYST:ERR? replies."""
    if row.key == "points":
        codes = np.zeros(int(value), dtype="<i2")
        g.handle_upload(f"C{CH}:WVDT WVNM,EDGE,LENGTH,{codes.nbytes}B,", codes.tobytes())
    else:
        g.handle_line(_bswv(_wave_for(row, value, load)))
    return g.handle_line("*ESR?;SYST:ERR?")


@pytest.mark.parametrize("index, load, end, inside, outside", CASES)
def test_the_simulated_instrument_takes_inside_and_refuses_outside(index, load, end, inside,
                                                                   outside):
    row = spec.LIMITS[index]
    g = SimulatedGenerator()
    g.handle_line(f"C{CH}:OUTP OFF,LOAD,{load};{_bswv(SAFE)}")
    assert g.handle_line("*ESR?") == ["0"]

    assert _simulator_applies(g, row, inside, load) == ["0", '0,"No error"']

    g.handle_line(_bswv(SAFE))
    before = astuple(g.channels[CH])[:8]
    esr, error = _simulator_applies(g, row, outside, load)
    assert int(esr) & 16                                         # execution error
    assert error.startswith('-222,"Data out of range; ')
    assert f"{row.field} " in error and f"{abs(inside):g}" in error
    if row.key != "points":                           # a count is named by its bytes
        assert f"{outside:g}" in error
    assert astuple(g.channels[CH])[:8] == before
    if row.key == "points":
        assert set(g.user_waves) <= {"EDGE"} and (
            "EDGE" not in g.user_waves or len(g.user_waves["EDGE"].codes) == inside)


# ------------------------------------------------------------------ the GUI
@pytest.mark.parametrize("load", spec.LOADS)
def test_the_gui_limit_texts_show_the_tables_numbers(load):
    from groundstation.gui.generator.limits_text import limit_texts

    for row in spec.LIMITS:
        low, high = row.bounds(load)
        for waveform in row.waveforms:
            texts = limit_texts(waveform, load, None)
            text = texts["offset" if row.key == "envelope" else row.key]
            numbers = [f"{high:g}"] if row.form != "between" else [f"{low:g}", f"{high:g}"]
            assert row.range_text(load) in text and all(n in text for n in numbers), \
                (row, waveform, text)
            assert spec.MODEL in text
            if row.depends_on_load:
                assert ("high-Z" if load == "HZ" else "50 ohm") in text
        for waveform in spec.WAVEFORMS:
            if row.key != "envelope" and spec.limit_for(row.key, waveform) is None:
                assert limit_texts(waveform, load, None)[row.key] == f"not used by {waveform}"


def test_the_panel_shows_the_texts_next_to_its_fields(qtbot, dictionary, tmp_path):
    from groundstation.gui.generator.panel import GeneratorPanel
    from groundstation.gui.generator.limits_text import limit_texts
    from groundstation.gui.session.session import Session

    session = Session(dictionary, store_seconds=10.0, param_history=tmp_path / "params")
    try:
        panel = GeneratorPanel(session)
        qtbot.addWidget(panel)
        assert [panel.channel.waveform.itemText(i) for i in range(panel.channel.waveform.count())] == \
            list(spec.WAVEFORMS)
        for waveform in spec.WAVEFORMS:
            for load in spec.LOADS:
                panel.channel.waveform.setCurrentText(waveform)
                panel.channel.load.setCurrentIndex(panel.channel.load.findData(load))
                limits = session.generator.safety_limits()
                texts = limit_texts(waveform, load, limits)
                for name, label in panel.channel.ranges.items():
                    assert label.text() == texts[name]
    finally:
        session.shutdown()


def test_the_named_figures_are_the_tables():
    """The figures other modules read by name (campaign checks, profile synthesis) are
    the table's, not copies."""
    sine = {row.key: row for row in spec.LIMITS if "SINE" in row.waveforms}
    assert spec.AMPLITUDE_MAX_VPP == {load: sine["amplitude"].bounds(load)[1] for load in spec.LOADS}
    assert spec.AMPLITUDE_MIN_VPP == {load: sine["amplitude"].bounds(load)[0] for load in spec.LOADS}
    assert spec.ENVELOPE_MAX_V == {load: sine["envelope"].bounds(load)[1] for load in spec.LOADS}
    assert spec.OFFSET_MAX_V == {load: sine["offset"].bounds(load)[1] for load in spec.LOADS}
    assert spec.FREQUENCY_MAX_HZ == {w: spec.limit_for("frequency", w).high_z[1]
                                     for w in spec.WAVEFORMS if w != "DC"}
    assert (spec.ARB_POINTS_MIN, spec.ARB_POINTS_MAX) == spec.limit_for("points", "ARB").high_z
    for waveform, fields in spec.WAVE_PARAMETERS.items():
        assert set(fields) == {row.field for row in spec.LIMITS
                               if waveform in row.waveforms and row.field in
                               ("FRQ", "AMP", "OFST", "PHSE")}
