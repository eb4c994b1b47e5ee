"""Figures of merit computed from recorded telemetry: line-of-sight jitter, control
energy, spectra - from arrays in memory, or from a log read in bounded chunks.

    from groundstation.analysis import los_jitter, control_energy, psd, csp, analyze_log

The numerics (jitter.py, energy.py, spectra.py) take arrays and hold no I/O and no Qt;
log_metrics.py is the adapter that reads a log through `groundstation.logs.LogReader`.
`analyze_log` is imported on first use, so the numerics do not pull in h5py.
See docs/analysis.md for the definitions.
"""

from __future__ import annotations

from ..core.errors import GroundStationError


class AnalysisError(GroundStationError):
    """An analysis cannot be done on the data given (the message says what is missing
    and what to do: another sensor, another window, a testbed file)."""


# after AnalysisError: the modules import it from here
from .energy import ControlEnergy, EnergyAccumulator, control_energy  # noqa: E402
from .jitter import (DEFAULT_INTEGRATION_PERIOD_S, JitterAccumulator, JitterResult,  # noqa: E402
                     highpass_jitter_rms, integration_period_factor, los_jitter, sensor_valid,
                     sinusoid_smear_rms, windowed_smear_rms)
from .spectra import Spectrum, WelchAccumulator, csp, psd  # noqa: E402

_LAZY = {"analyze_log": "log_metrics", "LogMetrics": "log_metrics", "SENSORS": "log_metrics",
         "METRICS": "log_metrics"}


def __getattr__(name: str):
    # the log adapter imports h5py (through the reader): only when it is asked for
    if name in _LAZY:
        from importlib import import_module
        return getattr(import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["AnalysisError", "ControlEnergy", "DEFAULT_INTEGRATION_PERIOD_S", "EnergyAccumulator",
           "JitterAccumulator", "JitterResult", "LogMetrics", "METRICS", "SENSORS", "Spectrum",
           "WelchAccumulator", "analyze_log", "control_energy", "csp", "highpass_jitter_rms",
           "integration_period_factor", "los_jitter", "psd", "sensor_valid", "sinusoid_smear_rms",
           "windowed_smear_rms"]
