"""What the function-generator controller reports, as plain records (no Qt, no I/O):
the resources found, one channel's state as the instrument reports it, the profile last
uploaded, and a check of the achieved base motion against its target - each with the
text the panel shows.  Also the name an upload is given on the instrument.
"""

from __future__ import annotations

from dataclasses import dataclass

from ...basemotion import BandRms, BaseMotionCheck, BaseMotionProfile, RecordWindow
from ...instruments import ArbSelection, ArbUpload, BasicWave, OutputState

SIMULATOR = "simulator"              # what the resource picker calls the simulated generator
DEFAULT_TOLERANCE = 0.10             # achieved RMS within 10 % of the target


@dataclass(frozen=True)
class ResourceChoice:
    resource: str                    # the VISA address
    label: str                       # what the picker shows
    simulated: bool = False


@dataclass(frozen=True)
class GeneratorState:
    """One channel as the instrument reports it."""

    resource: str
    channel: int
    wave: BasicWave
    output: OutputState
    arb: ArbSelection | None
    #: why switching the output on would be refused with these settings ("" if allowed)
    refusal: str = ""

    def text(self) -> str:
        w, o = self.wave, self.output
        parts = [w.waveform]
        for label, value, unit in (("f", w.frequency_hz, "Hz"), ("amp", w.amplitude_vpp, "Vpp"),
                                   ("offset", w.offset_v, "V"), ("phase", w.phase_deg, "deg")):
            if value is not None:
                parts.append(f"{label} {value:g} {unit}")
        if w.waveform == "ARB" and self.arb is not None:
            parts.append(f"arb {self.arb.name or self.arb.index}")
        load = {"HZ": "high-Z", "50": "50 ohm", None: "load ?"}[o.load]
        return f"C{self.channel}: {', '.join(parts)}; output {'ON' if o.on else 'off'} ({load})"


@dataclass(frozen=True)
class UploadedProfile:
    channel: int
    profile: BaseMotionProfile
    upload: ArbUpload


@dataclass(frozen=True)
class CheckResult:
    """Achieved vs target for the last uploaded profile."""

    check: BaseMotionCheck
    window: RecordWindow
    bands: list[BandRms]
    tolerance: float

    @property
    def ok(self) -> bool:
        return self.check.within(self.tolerance)

    def headline(self) -> str:
        c = self.check
        return (f"{c.name}: {c.achieved_rms_rad * 1e3:.3f} mrad achieved vs {c.target_rms_rad * 1e3:.3f} "
                f"target ({c.rms_error * 100:+.1f} %) - "
                f"{'within' if self.ok else 'NOT within'} {self.tolerance * 100:g} %")

    def text(self) -> str:
        c = self.check
        verdict = (f"within {self.tolerance * 100:g} %" if self.ok
                   else f"NOT within {self.tolerance * 100:g} %")
        dmax, fmax = c.max_cumulative_rms_difference_rad
        bands = ", ".join(f"{b.low_hz:g}-{b.high_hz:g} Hz {b.achieved_rms_rad * 1e3:.2f}/"
                          f"{b.target_rms_rad * 1e3:.2f}" for b in self.bands)
        missing = (f"; {self.window.missing_frames} telemetry frames missing"
                   if self.window.missing_frames else "")
        return (f"{c.name}: base RMS achieved {c.achieved_rms_rad * 1e3:.3f} mrad vs target "
                f"{c.target_rms_rad * 1e3:.3f} mrad ({c.rms_error * 100:+.1f} %, {verdict}); "
                f"{c.in_band_fraction * 100:.1f} % of the power in {c.band_hz[0]:g}-"
                f"{c.band_hz[1]:g} Hz; largest cumulative-RMS difference {dmax * 1e3:.3f} mrad at "
                f"{fmax:.3g} Hz; per band achieved/target mrad: {bands}; device time "
                f"{self.window.start_s:.2f}-{self.window.end_s:.2f} s{missing}")

