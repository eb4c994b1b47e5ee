"""Bench instruments: the base-disturbance function generator (B&K Precision 4053B) over VISA.

    from groundstation.instruments import open_generator, SafetyLimits
    with open_generator("USB0::...::INSTR", testbed=load_testbed(path)) as fg:
        fg.configure(1, waveform="SINE", frequency_hz=2, amplitude_vpp=0.5, offset_v=0)
        fg.set_output(1, True)
    # outputs are off again here (and on abort, on garbage collection, at exit)

The instrument's limits and formats live in `spec4050` (shared with the simulator);
pyvisa is imported only when a generator is opened or resources are listed.
"""

from .fg4050 import (ArbSelection, ArbUpload, BasicWave, FunctionGenerator4050, Identity,
                     InstrumentError, InstrumentLimitError, InstrumentLinkError, OutputState,
                     ResourceListing, SafetyLimitError, SafetyLimits, SettingRefusedError,
                     list_resources, normalise_backend, open_generator)

__all__ = ["ArbSelection", "ArbUpload", "BasicWave", "FunctionGenerator4050", "Identity",
           "InstrumentError", "InstrumentLimitError", "InstrumentLinkError", "OutputState",
           "ResourceListing", "SafetyLimitError", "SafetyLimits", "SettingRefusedError",
           "list_resources", "normalise_backend", "open_generator"]
