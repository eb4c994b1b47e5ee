"""Base-motion profiles for the rotary stage: PSD tables -> generator waveforms -> checks.

    psd = load_psd("profiles/base_motion/BM1.csv")
    profile = make_profile(psd, BaseStageModel.from_testbed(testbed), duration_s=60, seed=0)
    fg.upload_arbitrary(1, profile.volts, name="BM1", frequency_hz=profile.frequency_hz)
    ...record the base encoder for whole periods after the stage settles...
    check = check_base_motion(encoder_base, 1200.0, profile)
    print(check.summary()); curves = csp_curves(check)       # arrays for a CSP plot

No I/O beyond reading the PSD file, no plotting, no Qt.
"""

from .psd import BaseMotionError, PsdFileError, PsdTable, load_psd, parse_psd
from .stage import BaseStageModel
from .synthesis import (DEFAULT_DURATION_S, DEFAULT_POINTS, BaseMotionProfile, load_profile,
                        make_profile, synthesise_angle)
from .verify import BaseMotionCheck, CspCurves, check_base_motion, csp_curves, csp_from_psd

__all__ = ["BaseMotionCheck", "BaseMotionError", "BaseMotionProfile", "BaseStageModel",
           "CspCurves", "DEFAULT_DURATION_S", "DEFAULT_POINTS", "PsdFileError", "PsdTable",
           "check_base_motion", "csp_curves", "csp_from_psd", "load_profile", "load_psd",
           "make_profile", "parse_psd", "synthesise_angle"]
