"""The Station's function-generator verbs: set a channel, switch the outputs off, play a
base-motion profile synthesised from a PSD table; and closing the generator the
Station opened.  A mixin of station.Station, kept apart because driving the generator
is a job of its own: it uses the Station's generator, testbed, echo and recording."""

from __future__ import annotations

from pathlib import Path


class GeneratorVerbs:
    def generator_set(self, channel: int = 1, *, waveform: str = "SINE", frequency_hz: float | None = None,
                      amplitude_vpp: float | None = None, offset_v: float = 0.0,
                      phase_deg: float = 0.0, output: bool = True) -> None:
        gen = self._need_generator("generator_set")
        gen.configure(channel, waveform=waveform, frequency_hz=frequency_hz,
                      amplitude_vpp=amplitude_vpp, offset_v=offset_v, phase_deg=phase_deg)
        gen.set_output(channel, output)
        self.echo(f"generator: {gen.describe(channel)}")

    def generator_off(self) -> None:
        if self.generator is not None:
            self.generator.abort()

    def play_base_motion(self, psd_file: str | Path, *, duration_s: float = 60.0, seed: int = 0,
                         rms_rad: float | None = None, channel: int = 1):
        """Synthesise a base-motion profile from a PSD table, upload it to the generator
        and switch the output on; returns the profile (for the achieved-vs-target check)."""
        from ..basemotion import load_profile

        gen = self._need_generator("play_base_motion")
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

    def _close_generator(self) -> None:
        gen, self.generator = self.generator, None
        if gen is not None and self._owns_generator:
            gen.close()
        server, self._fg_server = self._fg_server, None
        if server is not None:
            server.stop()


__all__ = ["GeneratorVerbs"]
