"""Profile playback for the window's session: a profile uploaded (verified), armed,
played to its end and disarmed on a worker thread through the Station, with the
operator's abort ending it at once.

`ProfilePlayback` is owned by the Session (`session.profiles`): the Session decides
whether its link can take a profile now and hands over its Station; the playback runs
one profile at a time and reports each stage as its own signals."""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING

from PySide6.QtCore import QObject, Signal

from ...core.errors import GroundStationError
from ...profiles import Profile
from .commands import StartThread
from .events import EventSink, PlayOutcome

if TYPE_CHECKING:
    from ...station.station import Station

log = logging.getLogger(__name__)

#: after an abort, how long a playing profile may take to show its end in the telemetry
#: before the player stops waiting and makes the device safe itself
PROFILE_ABORT_GRACE_S = 1.0


class ProfileAborted(GroundStationError):
    """The operator aborted a profile that was being uploaded or played."""


class ProfilePlayback(QObject):
    """Plays one profile at a time on a Station (worker thread): steps, upload, progress,
    then once sig_done with a PlayOutcome."""

    sig_step = Signal(str)                   # "uploading", "mode RELATIVE", "playing", ...
    sig_upload = Signal(float)               # fraction of the profile uploaded
    sig_progress = Signal(int, int)          # samples played, sample count
    sig_done = Signal(object)                # PlayOutcome (session/events.py)

    def __init__(self, start_thread: StartThread, report: EventSink,
                 parent: QObject | None = None):
        super().__init__(parent)
        self._start_thread = start_thread
        self._report = report
        # written by the worker when the playback ends, read on the GUI thread
        self._playing = False
        self._abort = threading.Event()

    @property
    def playing(self) -> bool:
        """A profile is being uploaded or played (until just before sig_done)."""
        return self._playing

    def abort(self) -> None:
        """End a playing profile's wait: it reports "aborted".  The device's own ABORT is
        the Session's to send; this only stops the player waiting for the profile's end
        (after PROFILE_ABORT_GRACE_S it makes the device safe itself)."""
        self._abort.set()

    def play(self, station: Station, profile: Profile, mode: str | None = None) -> str | None:
        """Upload (verified), arm, play to the end and disarm `profile` on `station`
        (Station.play_profile, journaled into the recording if one runs) on a worker
        thread.  Returns why not (nothing sent), else None.  The caller has checked that
        the link is up and nothing else owns the device."""
        if self._playing:
            return "a profile is already playing"
        self._playing = True
        self._abort.clear()
        self._report("INFO", "profile", f"playing {profile.name} ({profile.duration:g} s, "
                                        f"{profile.target}) in {mode or 'its default mode'}")
        self._start_thread(lambda: self._run(station, profile, mode), "gs-profile-play")
        return None

    def _run(self, station: Station, profile: Profile, mode: str | None) -> None:
        """Worker thread: the whole playback, ending in one sig_done."""
        aborted_at: list[float] = []

        def on_step(text: str) -> None:
            if self._abort.is_set():        # between upload, mode, arm and start
                raise ProfileAborted(f"{profile.name}: aborted by the operator before playback "
                                     f"started; the device was made safe")
            self.sig_step.emit(text)

        def progress(played: int, count: int) -> None:
            self.sig_progress.emit(played, count)
            if self._abort.is_set():
                # the device's ABORT ends playback within a period, and the player sees it
                # in the telemetry; should that not come, stop waiting and make safe here
                if not aborted_at:
                    aborted_at.append(time.monotonic())
                elif time.monotonic() - aborted_at[0] > PROFILE_ABORT_GRACE_S:
                    raise ProfileAborted(f"{profile.name}: aborted by the operator after {played} "
                                         f"of {count} samples; the device was made safe")

        try:
            result = station.play_profile(
                profile, mode, progress=progress, on_step=on_step,
                upload_progress=lambda _step, f: self.sig_upload.emit(f))
        except ProfileAborted as exc:
            outcome = PlayOutcome("aborted", str(exc))
        except GroundStationError as exc:   # ScriptError too: a device fault, not open
            outcome = PlayOutcome("aborted" if self._abort.is_set() else "failed", str(exc))
        except Exception as exc:            # a bug: the player made the device safe; say so
            log.exception("playing %s", profile.name)
            outcome = PlayOutcome("failed", f"{type(exc).__name__}: {exc}")
        else:
            if result.completed:
                outcome = PlayOutcome("completed", result.text(), result)
            elif self._abort.is_set():
                # the device ends an aborted profile "disarmed" (its first event): the
                # operator's abort is the cause
                outcome = PlayOutcome("aborted", f"aborted by the operator: {result.text()}",
                                      result)
            else:
                outcome = PlayOutcome("ended early", result.text(), result)
        finally:
            self._playing = False
        self._report("INFO" if outcome.status == "completed" else
                     "WARNING" if outcome.status == "aborted" else "ERROR",
                     "profile", f"{profile.name}: {outcome.status}: {outcome.text}")
        self.sig_done.emit(outcome)


__all__ = ["PROFILE_ABORT_GRACE_S", "ProfileAborted", "ProfilePlayback"]
