"""Controller design files -> continuous transfer functions -> the device's filter sections.

The work is split into modules with one job each; this module re-exports all their names
so that `groundstation.params.design` stays the place to import them from:

- groundstation.params.tf_algebra: continuous transfer functions in zero-pole-gain form
  (the reference's factors), the output-equivalent c0 from the plant, pole/zero
  cancellation; DesignError and CONTROL_RATE_HZ.
- groundstation.params.design_file: design files (TOML) -> ControllerDesign with the
  checks that name file and field (the file format is described there), and
  table_values (a complete parameter table from a design).
- groundstation.params.discretise: the pre-warped Tustin map to second-order sections
  (refusing roots at the map's singular point s = 2 fs') and how closely the discrete
  cascades follow the continuous design.
"""

from __future__ import annotations

from .design_file import (FRICTION_MODEL_CODES, MODES, TRANSFER_FUNCTIONS, ControllerDesign,
                          FrictionCompensation, load_design, table_values)
from .discretise import (GAIN_REFERENCE_HZ, MATCH_BAND_HZ, SINGULAR_TOLERANCE, DiscreteCascade,
                         DiscretisationMatch, ResponseError, bilinear_rate_hz,
                         bilinear_singular_point, cascade_match, discretisation_match,
                         discretise, discretise_design, match_frequencies, pad_sections,
                         response_error, section_responses, singular_factors, sos_response,
                         warp_pct)
from .tf_algebra import (CANCEL_TOLERANCE, CONTROL_RATE_HZ, INTEGRATOR_TOLERANCE, DesignError,
                         TransferFunction, cancel_common_roots, output_equivalent_c0)

# the private helpers stay importable from here too, as before the split
from .design_file import (_DESIGN_KEYS, _EQUIVALENT_KEYS, _FRICTION_KEYS,  # noqa: F401
                          _PATH_FIELDS, _SATURATION_KEYS, _TF_KEYS, _TOP_KEYS, _copy, _friction,
                          _friction_values, _is_number, _load, _merged_document, _no_unknown,
                          _number, _partner, _table, _testbed, _text, _transfer_function)
from .discretise import _ratio, _share_gain, _singular_text  # noqa: F401
from .tf_algebra import (_check_same_loop, _factor_text, _lead, _path_sum, _poly,  # noqa: F401
                         _roots, _roots_of_factors, _signed, _snap_integrators)

__all__ = [
    # tf_algebra
    "CANCEL_TOLERANCE", "CONTROL_RATE_HZ", "INTEGRATOR_TOLERANCE", "DesignError",
    "TransferFunction", "cancel_common_roots", "output_equivalent_c0",
    # design_file
    "FRICTION_MODEL_CODES", "MODES", "TRANSFER_FUNCTIONS", "ControllerDesign",
    "FrictionCompensation", "load_design", "table_values",
    # discretise
    "GAIN_REFERENCE_HZ", "MATCH_BAND_HZ", "SINGULAR_TOLERANCE", "DiscreteCascade",
    "DiscretisationMatch", "ResponseError", "bilinear_rate_hz", "bilinear_singular_point",
    "cascade_match", "discretisation_match", "discretise", "discretise_design",
    "match_frequencies", "pad_sections", "response_error", "section_responses",
    "singular_factors", "sos_response", "warp_pct",
]
