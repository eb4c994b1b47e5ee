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

The names below are imported on first use (PEP 562): a campaign's check reads a base
motion's PSD and synthesises its profile, which needs numpy only, while the checks of a
recorded motion (verify.py) need scipy.signal and the analysis - 0.3 s of imports the
check would otherwise pay (docs/campaigns.md, "Seventh round").
"""

from __future__ import annotations

from ..core.lazy_names import lazy_dir, lazy_getattr

_LAZY = {
    "BaseMotionError": "psd", "PsdFileError": "psd", "PsdTable": "psd", "load_psd": "psd",
    "parse_psd": "psd",
    "BaseStageModel": "stage",
    "DEFAULT_DURATION_S": "synthesis", "DEFAULT_POINTS": "synthesis",
    "BaseMotionProfile": "synthesis", "load_profile": "synthesis", "make_profile": "synthesis",
    "synthesise_angle": "synthesis",
    "BandRms": "verify", "BaseMotionCheck": "verify", "CspCurves": "verify",
    "PreviewSpectrum": "verify", "RecordWindow": "verify", "band_rms": "verify",
    "check_base_motion": "verify", "check_record": "verify", "csp_curves": "verify",
    "csp_from_psd": "verify", "preview_spectrum": "verify", "select_window": "verify",
}

__getattr__ = lazy_getattr(__name__, _LAZY, globals())
__dir__ = lazy_dir(_LAZY, globals())

__all__ = sorted(_LAZY)
