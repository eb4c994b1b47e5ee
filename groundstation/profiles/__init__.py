"""Command profiles: waveform generators (waveforms.py), profile files and their checks
(profile.py), upload and playback on the device (upload.py).  See profiles/waveforms/."""

from .profile import load_profile, profile_from_dict
from .samples import TARGETS, Profile, ProfileFileError
from .checks import check_profile
from .checks import ProfileCheck
from .samples import ProfileError, ProfileRefused
from .summary import ProfileSummary, preview, summarise, write_csv
from .upload import (PlaybackError, PlaybackResult, ProfileLoader, ProfilePlayer, ProfileRecord,
                     ProfileUploadError, default_mode)

__all__ = ["TARGETS", "PlaybackError", "PlaybackResult", "Profile", "ProfileCheck", "ProfileError",
           "ProfileFileError", "ProfileLoader", "ProfilePlayer", "ProfileRecord", "ProfileRefused",
           "ProfileSummary", "ProfileUploadError", "check_profile", "default_mode", "load_profile",
           "preview", "profile_from_dict", "summarise", "write_csv"]
