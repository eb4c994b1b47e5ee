"""What the identification tests share: the open-loop excitation logs `identify` fits."""

from __future__ import annotations

from pathlib import Path

from groundstation import Testbed

WAVEFORMS = Path(__file__).resolve().parents[1] / "profiles/waveforms"
SYSID_PROFILES = ("sysid_coarse_noise_1A", "sysid_fine_noise_1A")


def record_sysid_logs(testbed: Path, folder: Path, seconds: float) -> list[Path]:
    """The shipped 1 A coarse and fine excitations, each shortened to `seconds`, recorded
    open loop on the fast simulator running `testbed`: one log each."""
    logs = []
    for profile in SYSID_PROFILES:
        with Testbed("sim", testbed=testbed, fast=True, generator=None, log_folder=folder / "logs",
                     history=folder / "history") as tb:
            tb.set_mode("OPEN_LOOP")
            logs.append(Path(tb.start_recording(profile)))
            tb.dwell(0.2)
            tb.play(WAVEFORMS / f"{profile}.toml", max_seconds=seconds)
            tb.stop_recording()
    return logs
