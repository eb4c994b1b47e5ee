"""The session's profile playback: a profile uploaded (verified), armed, played to its
end and disarmed on a worker thread through the Station, with the operator's abort
ending it at once.  A mixin of gui/session.Session, kept apart because it is a job of
its own: it uses the session's link, Station, workers, abort flag and signals."""

from __future__ import annotations

import logging
import time

from ...core.errors import GroundStationError
from ...profiles import Profile
from .events import PlayOutcome

log = logging.getLogger(__name__)

#: after an abort, how long a playing profile may take to show its end in the telemetry
#: before the player stops waiting and makes the device safe itself
PROFILE_ABORT_GRACE_S = 1.0


class ProfileAborted(GroundStationError):
    """The operator aborted a profile that was being uploaded or played."""


class ProfilePlaybackMixin:
    @property
    def profile_playing(self) -> bool:
        return self._playing

    def play_profile(self, profile: Profile, mode: str | None = None) -> str | None:
        """Upload (verified), arm, play to the end and disarm a profile on a worker thread
        (Station.play_profile), journaled into the recording if one runs.  Returns why
        not (nothing sent), else None; progress arrives as sig_profile_step /
        sig_profile_upload / sig_profile_progress, then once sig_profile_done with a
        PlayOutcome.  Abort ends it at once."""
        client, station = self.client, self.station
        if (self.replay is not None or client is None or station is None
                or client.link_state != "up"):
            return "not connected: connect to the device first"
        if self._playing:
            return "a profile is already playing"
        if self.campaign.running:
            return "a campaign is running: it owns the device until it ends"
        self._playing = True
        self._play_abort.clear()
        self.sig_event.emit("INFO", "profile", f"playing {profile.name} ({profile.duration:g} s, "
                                               f"{profile.target}) in {mode or 'its default mode'}")

        aborted_at: list[float] = []

        def check_abort() -> None:
            if self._play_abort.is_set():
                raise ProfileAborted(f"{profile.name}: aborted by the operator before playback "
                                     f"started; the device was made safe")

        def on_step(text: str) -> None:
            check_abort()                   # between upload, mode, arm and start
            self.sig_profile_step.emit(text)

        def progress(played: int, count: int) -> None:
            self.sig_profile_progress.emit(played, count)
            if self._play_abort.is_set():
                # the device's ABORT ends playback within a period, and the player sees it
                # in the telemetry; should that not come, stop waiting and make safe here
                if not aborted_at:
                    aborted_at.append(time.monotonic())
                elif time.monotonic() - aborted_at[0] > PROFILE_ABORT_GRACE_S:
                    raise ProfileAborted(f"{profile.name}: aborted by the operator after {played} "
                                         f"of {count} samples; the device was made safe")

        def work() -> None:
            try:
                result = station.play_profile(
                    profile, mode, progress=progress, on_step=on_step,
                    upload_progress=lambda _step, f: self.sig_profile_upload.emit(f))
            except ProfileAborted as exc:
                outcome = PlayOutcome("aborted", str(exc))
            except GroundStationError as exc:   # ScriptError too: a device fault, not open
                outcome = PlayOutcome("aborted" if self._play_abort.is_set() else "failed", str(exc))
            except Exception as exc:        # a bug: the player made the device safe; say so
                log.exception("playing %s", profile.name)
                outcome = PlayOutcome("failed", f"{type(exc).__name__}: {exc}")
            else:
                if result.completed:
                    outcome = PlayOutcome("completed", result.text(), result)
                elif self._play_abort.is_set():
                    # the device ends an aborted profile "disarmed" (its first event):
                    # the operator's abort is the cause
                    outcome = PlayOutcome("aborted", f"aborted by the operator: {result.text()}",
                                          result)
                else:
                    outcome = PlayOutcome("ended early", result.text(), result)
            finally:
                self._playing = False
            self.sig_event.emit("INFO" if outcome.status == "completed" else
                                "WARNING" if outcome.status == "aborted" else "ERROR",
                                "profile", f"{profile.name}: {outcome.status}: {outcome.text}")
            self.sig_profile_done.emit(outcome)
        self._worker(work, "gs-profile-play")
        return None


__all__ = ["PROFILE_ABORT_GRACE_S", "ProfileAborted", "ProfilePlaybackMixin"]
