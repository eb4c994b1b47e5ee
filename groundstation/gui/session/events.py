"""What the GUI's Session reports about the work it runs on its worker threads, as plain
records (no Qt here): the payloads of its typed signals that are not already a record of
another package (ActiveTable and UploadRecord come from params/, StepResult and the
campaign's outcome from the campaign controller).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ...profiles.upload import PlaybackResult

#: how a profile playback ended: played to its end; the device ended it before its end
#: (a fault, a limit); the operator's abort; it could not be played (link, refusal, bug)
PLAY_STATUSES = ("completed", "ended early", "aborted", "failed")


@dataclass(frozen=True)
class PlayOutcome:
    """The end of one profile playback (Session.sig_profile_done)."""

    status: str                 # one of PLAY_STATUSES
    text: str                   # for the operator: what happened, or why not
    result: PlaybackResult | None = None   # None when playing raised (no result to show)

    def __post_init__(self) -> None:
        if self.status not in PLAY_STATUSES:
            raise ValueError(f"PlayOutcome: unknown status {self.status!r}")

    @property
    def completed(self) -> bool:
        return self.status == "completed"


__all__ = ["PLAY_STATUSES", "PlayOutcome"]
