"""Base-motion profiles for the rotary stage: PSD tables -> generator waveforms -> checks.

    psd = load_psd("profiles/base_motion/BM1.csv")
    profile = make_profile(psd, BaseStageModel.from_testbed(testbed), duration_s=60, seed=0)
    fg.upload_arbitrary(1, profile.volts, name="BM1", frequency_hz=profile.frequency_hz)
    ...record the base encoder for whole periods after the stage settles...
    check = check_base_motion(encoder_base, 1200.0, profile)
    # or, from a record with device times: the last settled period, exact spectrum
    check, window = check_record(device_time, encoder_base, 1200.0, profile, not_before_s=t_on + settle)
    print(check.summary()); curves = csp_curves(check)       # arrays for a CSP plot

No I/O beyond reading the PSD file, no plotting, no Qt.
"""

from .psd import BaseMotionError, PsdFileError, PsdTable, load_psd, parse_psd
from .stage import BaseStageModel
from .synthesis import (DEFAULT_DURATION_S, DEFAULT_POINTS, BaseMotionProfile, load_profile,
                        make_profile, synthesise_angle)
from .verify import (BandRms, BaseMotionCheck, CspCurves, PreviewSpectrum, RecordWindow,
                     band_rms, check_base_motion, check_record, csp_curves, csp_from_psd,
                     preview_spectrum, select_window)

__all__ = ["BandRms", "BaseMotionCheck", "BaseMotionError", "BaseMotionProfile", "BaseStageModel",
           "CspCurves", "DEFAULT_DURATION_S", "DEFAULT_POINTS", "PreviewSpectrum", "PsdFileError",
           "PsdTable", "RecordWindow", "band_rms", "check_base_motion", "check_record", "csp_curves",
           "csp_from_psd", "load_profile", "load_psd", "make_profile", "parse_psd",
           "preview_spectrum", "select_window", "synthesise_angle"]
