"""`GeneratorDesk`: what a session does with its function generator - set a channel,
switch the outputs off, play a base-motion profile synthesised from a PSD table.

The Station owns one and its script verbs (`generator_set`, `generator_off`,
`play_base_motion`) hand the work to it.  The desk does not own the instrument: the
Station opens and closes it (its link, its attach(), its make_safe), so the desk reads
the current one through a getter each time it is asked to act."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from ..core.contracts import BaseMotionInstrument
    from ..plant.testbed import Testbed
    from .recording import RecordingSlot


class GeneratorDesk:
    """Drives the session's generator: configures channels and plays base motion."""

    def __init__(self, generator: Callable[[], "BaseMotionInstrument | None"], testbed: "Testbed",
                 recording: "RecordingSlot", echo: Callable[[str], None]):
        #: the session's open generator, or None (the Station opens and closes it)
        self._generator = generator
        #: the rig's model: the base-motion profile is fitted to its stage and drive
        self.testbed = testbed
        #: base motion switched on is marked in the session's log
        self.recording = recording
        self.echo = echo

    def set(self, channel: int = 1, *, waveform: str = "SINE", frequency_hz: float | None = None,
            amplitude_vpp: float | None = None, offset_v: float = 0.0,
            phase_deg: float = 0.0, output: bool = True) -> None:
        """Configure one channel and switch its output on (or off with `output=False`)."""
        gen = self._need("generator_set")
        gen.configure(channel, waveform=waveform, frequency_hz=frequency_hz,
                      amplitude_vpp=amplitude_vpp, offset_v=offset_v, phase_deg=phase_deg)
        gen.set_output(channel, output)
        self.echo(f"generator: {gen.describe(channel)}")

    def off(self) -> None:
        """Every output off; nothing to do without a generator."""
        gen = self._generator()
        if gen is not None:
            gen.abort()

    def play_base_motion(self, psd_file: str | Path, *, duration_s: float = 60.0, seed: int = 0,
                         rms_rad: float | None = None, channel: int = 1):
        """Synthesise a base-motion profile from a PSD table, upload it to the generator
        and switch the output on; returns the profile (for the achieved-vs-target check)."""
        from ..basemotion import load_profile

        gen = self._need("play_base_motion")
        profile = load_profile(psd_file, self.testbed, duration_s=duration_s, seed=seed,
                               target_rms_rad=rms_rad)
        gen.upload_arbitrary(channel, profile.volts, name=Path(psd_file).stem[:8].upper(),
                             frequency_hz=1.0 / profile.duration_s)
        gen.set_output(channel, True)
        self.echo(f"base motion {profile.name}: {profile.amplitude_vpp:.3f} Vpp, "
                  f"{profile.duration_s:g} s period")
        self.recording.mark("generator", f"base motion {profile.name} on",
                            amplitude_vpp=profile.amplitude_vpp)
        return profile

    def _need(self, what: str) -> "BaseMotionInstrument":
        # ScriptError lives with the Station, which imports this module
        from .station import ScriptError

        gen = self._generator()
        if gen is None:
            raise ScriptError(f"{what}: no function generator in this session "
                              f"(give generator='sim' or a VISA resource)")
        return gen


__all__ = ["GeneratorDesk"]
