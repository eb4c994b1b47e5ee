"""What the GUI's Session reports about the work it runs on its worker threads, as plain
records (no Qt here): the payloads of its typed signals that are not already a record of
another package (ActiveTable and UploadRecord come from params/, StepResult and the
campaign's outcome from the campaign controller), and the callback through which the
Session's collaborators add to its event log.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from ...profiles.upload import PlaybackResult

#: where the Session's collaborators say what happened, for the operator's event log:
#: (level, source, text), e.g. ("WARNING", "profile", "pluck: aborted: ...")
EventSink = Callable[[str, str, str], None]

#: how a profile playback ended: played to its end; the device ended it before its end
#: (a fault, a limit); the operator's abort; it could not be played (link, refusal, bug)
PLAY_STATUSES = ("completed", "ended early", "aborted", "failed")


@dataclass(frozen=True)
class PlayOutcome:
    """The end of one profile playback (ProfilePlayback.sig_done, session.profiles)."""

    status: str                 # one of PLAY_STATUSES
    text: str                   # for the operator: what happened, or why not
    result: PlaybackResult | None = None   # None when playing raised (no result to show)

    def __post_init__(self) -> None:
        if self.status not in PLAY_STATUSES:
            raise ValueError(f"PlayOutcome: unknown status {self.status!r}")

    @property
    def completed(self) -> bool:
        return self.status == "completed"


__all__ = ["EventSink", "PLAY_STATUSES", "PlayOutcome"]
