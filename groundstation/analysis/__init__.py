"""Figures of merit computed from recorded telemetry: line-of-sight jitter, control
energy, spectra - from arrays in memory, or from a log read in bounded chunks.

    from groundstation.analysis import los_jitter, control_energy, psd, csp, analyze_log

The numerics (jitter.py, energy.py, spectra.py) take arrays and hold no I/O and no Qt;
log_metrics.py is the adapter that reads a log through `groundstation.logs.LogReader`.
Every name is imported on first use: the package itself imports neither scipy nor h5py.
See docs/analysis.md for the definitions.
"""

from __future__ import annotations

from ..core.errors import GroundStationError
from ..core.lazy_names import lazy_dir, lazy_getattr


class AnalysisError(GroundStationError):
    """An analysis cannot be done on the data given (the message says what is missing
    and what to do: another sensor, another window, a testbed file)."""


# The numerics (scipy) and the log adapter (h5py) are imported on first use (PEP 562):
# a command that only checks a file against the analysis's names (analysis/names.py)
# does not pay for them at its start.
_LAZY = {"ControlEnergy": "energy", "EnergyAccumulator": "energy", "control_energy": "energy",
         "DEFAULT_INTEGRATION_PERIOD_S": "jitter", "JitterAccumulator": "jitter",
         "JitterResult": "jitter", "highpass_jitter_rms": "jitter",
         "integration_period_factor": "jitter", "los_jitter": "jitter", "sensor_valid": "jitter",
         "sinusoid_smear_rms": "jitter", "windowed_smear_rms": "jitter",
         "Spectrum": "spectra", "WelchAccumulator": "spectra", "csp": "spectra", "psd": "spectra",
         "analyze_log": "log_metrics", "LogMetrics": "log_metrics",
         "SENSORS": "names", "METRICS": "names"}


__getattr__ = lazy_getattr(__name__, _LAZY, globals())
__dir__ = lazy_dir(_LAZY, globals())

__all__ = ["AnalysisError", "ControlEnergy", "DEFAULT_INTEGRATION_PERIOD_S", "EnergyAccumulator",
           "JitterAccumulator", "JitterResult", "LogMetrics", "METRICS", "SENSORS", "Spectrum",
           "WelchAccumulator", "analyze_log", "control_energy", "csp", "highpass_jitter_rms",
           "integration_period_factor", "los_jitter", "psd", "sensor_valid", "sinusoid_smear_rms",
           "windowed_smear_rms"]
