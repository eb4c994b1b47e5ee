"""How close the base came to the target of the profile uploaded from the GUI: which of
the session's telemetry shows the base moving under it, checked against its target
(no Qt, no I/O: reads the session's telemetry store).
"""

from __future__ import annotations

from ...basemotion import BaseMotionError, band_rms, check_record
from .records import CheckResult, UploadedProfile


def newest_device_time(session) -> float | None:
    """Device time of the newest HIGH_RATE sample in the session's store (None: none)."""
    try:
        snap = session.store.ring("HIGH_RATE").snapshot([], seconds=0.0)
    except (AttributeError, KeyError):
        return None
    return float(snap.device_time[-1]) if len(snap.device_time) else None


def check_uploaded_motion(session, up: UploadedProfile | None, motion_start_s: float | None,
                          motion_end_s: float | None, plays_upload: bool, running: bool,
                          tolerance: float, periods: int) -> CheckResult:
    """The base encoder's last whole period(s) of settled motion under `up` (from the
    session's telemetry store) against its target.  `motion_start_s`, `motion_end_s`:
    device times where the base motion last (re)started and stopped; `plays_upload`:
    whether that motion is `up` playing; `running`: the output is on now.
    BaseMotionError says what is missing (no upload, output never on, not enough data)."""
    if up is None:
        raise BaseMotionError("no base-motion profile was uploaded from here: upload one, "
                              "switch the output on and let it play")
    if motion_start_s is None:
        raise BaseMotionError(f"the output has not been on since {up.profile.name} was "
                              f"uploaded: switch it on and let it play")
    if not plays_upload:
        raise BaseMotionError(f"the base did not move under {up.upload.name} the last time "
                              f"the output was on (another waveform was set): upload "
                              f"{up.profile.name} again, switch the output on and let it play")
    profile = up.profile
    settle = profile.stage.settling_time_s()
    not_before = motion_start_s + settle
    end = None if running else motion_end_s
    ring = session.store.ring("HIGH_RATE")
    newest = newest_device_time(session)
    if newest is None:
        raise BaseMotionError("no telemetry received: connect to the testbed")
    span = newest - motion_start_s + 1.0
    snap = ring.snapshot(["encoder_base"], seconds=max(span, periods * profile.duration_s + 1.0))
    rate = float(ring.packet.rate_hz or session.d.control_rate_hz)
    check, window = check_record(snap.device_time, snap.values["encoder_base"], rate,
                                 profile, end_s=end, not_before_s=not_before, periods=periods)
    return CheckResult(check, window, band_rms(check), tolerance)
