"""Bench instruments: the base-disturbance function generator (B&K Precision 4053B) over VISA.

    from groundstation.instruments import open_generator, SafetyLimits
    with open_generator("USB0::...::INSTR", testbed=load_testbed(path)) as fg:
        fg.configure(1, waveform="SINE", frequency_hz=2, amplitude_vpp=0.5, offset_v=0)
        fg.set_output(1, True)
    # outputs are off again here (and on abort, on garbage collection, at exit)

One job per module:
  spec4050     what the instrument accepts: the limits table, sample and reply formats
               (shared with the simulated instrument and the GUI)
  visa_link    the VISA session: opening, one transaction at a time, I/O errors in one
               line, outputs off on failure and at the end
  fg4050       the driver: SCPI commands, channel state, checks before sending
  records4050  what the instrument reports, parsed (basic wave, output, arb selection)
  safety       the testbed's own limits ([limits] of the testbed file)
  fg_errors    the exceptions
pyvisa is imported only when a generator is opened or resources are listed.
"""

from .fg4050 import FunctionGenerator4050, open_generator
from .records4050 import ArbSelection, ArbUpload, BasicWave, OutputState
from .spec4050 import Identity
from .fg_errors import (InstrumentError, InstrumentLimitError, InstrumentLinkError,
                        SafetyLimitError, SettingRefusedError)
from .visa_link import ResourceListing, list_resources, normalise_backend
from .safety import SafetyLimits

__all__ = ["ArbSelection", "ArbUpload", "BasicWave", "FunctionGenerator4050", "Identity",
           "InstrumentError", "InstrumentLimitError", "InstrumentLinkError", "OutputState",
           "ResourceListing", "SafetyLimitError", "SafetyLimits", "SettingRefusedError",
           "list_resources", "normalise_backend", "open_generator"]
