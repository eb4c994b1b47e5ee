"""Discretisation of the continuous controller designs.

The bilinear (Tustin) map at the control rate, optionally pre-warped, into second-order
sections in the table's row format b0 b1 b2 a0 a1 a2 (a0 = 1), padded with identity rows;
roots at the map's singular point s = 2 fs' are refused.  Also how closely the discrete
cascades follow the continuous ones.  All angular frequencies are rad/s, all frequencies
named `_hz` are Hz.

One of the three modules of the design path (tf_algebra, design_file, discretise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Mapping

import numpy as np

from ..core.numerics_cache import cached_arrays, scipy_version
from .tf_algebra import CONTROL_RATE_HZ, DesignError, TransferFunction, _factor_text

if TYPE_CHECKING:
    from .design_file import ControllerDesign

MATCH_BAND_HZ = 100.0             # discrete and continuous responses are compared up to here
SINGULAR_TOLERANCE = 1e-6         # relative distance from s = 2 fs' at which a root is refused
GAIN_REFERENCE_HZ = 10.0          # sections share the gain equally at this frequency


# ======================================================================================
# discretisation
# ======================================================================================
@dataclass(frozen=True, eq=False)
class DiscreteCascade:
    """One controller cascade as the device runs it (unpadded rows b0 b1 b2 a0 a1 a2)."""

    name: str
    sos: np.ndarray
    integrators: int                # poles at z = 1 that are integrators by design

    @property
    def sections(self) -> int:
        return int(self.sos.shape[0])


def bilinear_rate_hz(rate_hz: float, prewarp_hz: float | None) -> float:
    """The rate to give the plain bilinear map so that it is exact at prewarp_hz.

    s = 2 fs' (z - 1)/(z + 1) maps j w_p to e^(j w_p T) exactly when
    fs' = w_p / (2 tan(w_p T / 2))."""
    if not prewarp_hz:
        return rate_hz
    wp = 2 * math.pi * prewarp_hz
    return wp / (2 * math.tan(wp / (2 * rate_hz)))


def bilinear_singular_point(rate_hz: float = CONTROL_RATE_HZ, prewarp_hz: float | None = None) -> float:
    """The s (rad/s) where the bilinear map this tool uses is singular.

    z = (1 + s/(2 fs'))/(1 - s/(2 fs')) divides by zero at s = 2 fs', with fs' the rate
    given to the map: 2 x 1200 = 2400 rad/s for plain Tustin, w_p / tan(w_p T / 2) when
    pre-warped at f_p (2388.03 rad/s at 46.70 Hz)."""
    return 2.0 * bilinear_rate_hz(rate_hz, prewarp_hz)


def singular_factors(tf: TransferFunction, rate_hz: float = CONTROL_RATE_HZ,
                     prewarp_hz: float | None = None) -> list[tuple[str, complex]]:
    """("zero" | "pole", root) for every root of `tf` at the bilinear map's singular point
    (within SINGULAR_TOLERANCE, relative): a pole there maps to z = infinity, a zero (an
    all-pass or non-minimum-phase factor) to a zero at infinity that leaves the discrete
    filter with a gain of zero.  Neither has a discrete equivalent."""
    point = bilinear_singular_point(rate_hz, prewarp_hz)
    out = []
    for kind, roots in (("zero", tf.zeros), ("pole", tf.poles)):
        for r in roots:
            if abs(complex(r) - point) <= SINGULAR_TOLERANCE * point:
                out.append((kind, complex(r)))
    return out


def _singular_text(label: str, kind: str, root: complex, rate_hz: float,
                   prewarp_hz: float | None) -> str:
    point = bilinear_singular_point(rate_hz, prewarp_hz)
    fs = point / 2
    how = (f"pre-warped at {prewarp_hz:g} Hz, the map uses fs' = {fs:.10g} Hz"
           if prewarp_hz else f"plain Tustin at fs = {rate_hz:g} Hz")
    side = "numerator" if kind == "zero" else "denominator"
    effect = ("it would map to a pole at z = infinity (scipy cannot even form the sections)"
              if kind == "pole" else
              "it would map to a zero at z = infinity: the discrete filter loses that factor "
              "and its gain becomes zero")
    return (f"{label}: the {side} factor {_factor_text(np.array([root]))} puts a {kind} at "
            f"s = {root.real:.10g} rad/s, exactly where the bilinear map z = (1 + sT/2)/(1 - sT/2) "
            f"is singular, s = 2/T = 2 fs' = {point:.10g} rad/s ({how}); {effect}.  Move it "
            f"off that point or change prewarp_hz")


def discretise(tf: TransferFunction, rate_hz: float = CONTROL_RATE_HZ,
               prewarp_hz: float | None = None, name: str = "transfer function") -> np.ndarray:
    """Tustin (optionally pre-warped) -> second-order sections, gain shared across them.
    A root at the map's singular point raises DesignError naming it."""
    bad = singular_factors(tf, rate_hz, prewarp_hz)
    if bad:
        raise DesignError("; ".join(_singular_text(name, kind, r, rate_hz, prewarp_hz) for kind, r in bad))
    # s = 0 maps to (2fs + 0)/(2fs - 0) = 1 exactly, so an integrator stays on z = 1
    sos = _bilinear_sections(tf.zeros, tf.poles, tf.gain, bilinear_rate_hz(rate_hz, prewarp_hz))
    return _share_gain(sos, rate_hz)


def _bilinear_sections(zeros, poles, gain: float, map_rate_hz: float) -> np.ndarray:
    """scipy.signal's bilinear map and section pairing (zpk2sos), kept on disk by their
    inputs (core/numerics_cache.py): a check of designs read before imports no
    scipy.signal."""

    def compute():
        from scipy import signal

        zd, pd, kd = signal.bilinear_zpk(zeros, poles, gain, map_rate_hz)
        return (np.atleast_2d(signal.zpk2sos(zd, pd, kd)),)

    def valid(arrays) -> bool:
        return len(arrays) == 1 and arrays[0].ndim == 2 and arrays[0].shape[0] >= 1 \
            and arrays[0].shape[1] == 6

    inputs = (np.asarray(zeros, dtype=complex), np.asarray(poles, dtype=complex),
              float(gain), float(map_rate_hz))
    return cached_arrays("sections", scipy_version(), inputs, compute, valid)[0]


def _share_gain(sos: np.ndarray, rate_hz: float) -> np.ndarray:
    """Give every section the same magnitude at GAIN_REFERENCE_HZ (zpk2sos puts the whole
    gain into the first section).  In double precision this changes no result, but the
    sections' internal signals stay of comparable size and each row reads as a unit-size
    filter.  Left alone if a section vanishes or blows up at the reference frequency."""
    if sos.shape[0] < 2:
        return sos
    mags = np.abs(section_responses(sos, np.exp(2j * np.pi * GAIN_REFERENCE_HZ / rate_hz)))
    if not np.all(np.isfinite(mags)) or np.any(mags == 0):
        return sos
    share = np.exp(np.mean(np.log(mags)))
    out = sos.copy()
    out[:, :3] *= (share / mags)[:, None]
    return out


def section_responses(sos: np.ndarray, z) -> np.ndarray:
    """(b0 z^2 + b1 z + b2) / (a0 z^2 + a1 z + a2) of every row at the points z: shape (rows, *z)."""
    sos = np.asarray(sos, dtype=float)
    z = np.asarray(z, dtype=complex)
    b0, b1, b2, a0, a1, a2 = (sos[:, j].reshape((-1,) + (1,) * z.ndim) for j in range(6))
    return ((b0 * z + b1) * z + b2) / ((a0 * z + a1) * z + a2)


def sos_response(sos: np.ndarray, z) -> np.ndarray:
    """The cascade's value at the points z (e^(j w T) for a frequency response)."""
    return np.prod(section_responses(sos, z), axis=0)


def pad_sections(sos: np.ndarray, rows: int, name: str = "cascade") -> np.ndarray:
    """Fill up to `rows` with identity sections [1, 0, 0, 1, 0, 0]."""
    if sos.shape[0] > rows:
        raise DesignError(f"{name} needs {sos.shape[0]} second-order sections; the parameter "
                          f"table holds {rows} (reduce the order to at most {2 * rows})")
    out = np.tile([1.0, 0.0, 0.0, 1.0, 0.0, 0.0], (rows, 1))
    out[:sos.shape[0]] = sos
    return out


def discretise_design(design: ControllerDesign, rate_hz: float = CONTROL_RATE_HZ) -> dict[str, DiscreteCascade]:
    """c0, c1, c2 of the design as unpadded discrete cascades."""
    return {name: DiscreteCascade(name, discretise(tf, rate_hz, design.prewarp_hz, name), tf.integrators)
            for name, tf in design.cascades.items()}


# --- how well the discrete cascades follow the continuous ones -------------------------
@dataclass(frozen=True)
class ResponseError:
    """Worst deviation of a discrete response from its continuous design below a band."""

    magnitude_pct: float          # max | |H_d| / |H_c| - 1 | * 100
    phase_deg: float              # max | angle(H_d / H_c) |
    magnitude_at_hz: float
    phase_at_hz: float

    def within(self, magnitude_pct: float = 1.0, phase_deg: float = 1.0) -> bool:
        return self.magnitude_pct <= magnitude_pct and self.phase_deg <= phase_deg

    def text(self) -> str:
        return (f"{self.magnitude_pct:.2f} % (at {self.magnitude_at_hz:.3g} Hz) / "
                f"{self.phase_deg:.2f} deg (at {self.phase_at_hz:.3g} Hz)")


def match_frequencies(band_hz: float = MATCH_BAND_HZ) -> np.ndarray:
    """A grid fine enough for the lightly damped notches (a few Hz wide) of the designs."""
    return np.unique(np.concatenate([np.logspace(-2, math.log10(band_hz), 300),
                                     np.linspace(band_hz / 2000, band_hz, 2000)]))


def response_error(ratio: np.ndarray, freqs_hz: np.ndarray) -> ResponseError:
    """ResponseError of H_d/H_c given on freqs_hz."""
    mag = np.abs(np.abs(ratio) - 1.0) * 100.0
    ph = np.abs(np.angle(ratio, deg=True))
    i, j = int(np.argmax(mag)), int(np.argmax(ph))
    return ResponseError(float(mag[i]), float(ph[j]), float(freqs_hz[i]), float(freqs_hz[j]))


def cascade_match(tf: TransferFunction, sos: np.ndarray, rate_hz: float = CONTROL_RATE_HZ,
                  band_hz: float = MATCH_BAND_HZ) -> ResponseError:
    """Discrete cascade vs its continuous transfer function, 0 < f <= band_hz."""
    f = match_frequencies(band_hz)
    ratio = _ratio(sos_response(sos, np.exp(2j * np.pi * f / rate_hz)), tf.frequency_response(f))
    return response_error(ratio, f)


def _ratio(discrete: np.ndarray, continuous: np.ndarray) -> np.ndarray:
    """discrete / continuous, 1 where both are equal (a zero-gain cascade matches exactly)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(discrete == continuous, 1.0 + 0j, discrete / continuous)


@dataclass(frozen=True)
class DiscretisationMatch:
    """Discrete vs continuous controller below `band_hz`: each cascade, and the two paths
    the device computes from the error, e -> u1 = c0 c1' and e -> u2 = c0 c2'."""

    band_hz: float
    rate_hz: float
    prewarp_hz: float | None
    warp_pct: float                          # frequency warp of the map at band_hz (%)
    cascades: dict[str, ResponseError]
    paths: dict[str, ResponseError]
    closed_loop: ResponseError | None = None  # sensitivity 1/(1+L), filled in by loop.validate

    @property
    def worst(self) -> ResponseError:
        """The worst magnitude and the worst phase error over the two paths."""
        m = max(self.paths.values(), key=lambda r: r.magnitude_pct)
        p = max(self.paths.values(), key=lambda r: r.phase_deg)
        return ResponseError(m.magnitude_pct, p.phase_deg, m.magnitude_at_hz, p.phase_at_hz)


def discretisation_match(design: ControllerDesign, cascades: Mapping[str, np.ndarray] | None = None,
                         rate_hz: float = CONTROL_RATE_HZ,
                         band_hz: float = MATCH_BAND_HZ) -> DiscretisationMatch:
    """How closely the discrete cascades (default: the design's own discretisation; or the
    rows of a table, identity padding included) follow the continuous design."""
    if cascades is None:
        cascades = {k: c.sos for k, c in discretise_design(design, rate_hz).items()}
    f = match_frequencies(band_hz)
    z = np.exp(2j * np.pi * f / rate_hz)
    ratio = {k: _ratio(sos_response(cascades[k], z), tf.frequency_response(f))
             for k, tf in design.cascades.items()}
    return DiscretisationMatch(
        band_hz, rate_hz, design.prewarp_hz, warp_pct(band_hz, rate_hz, design.prewarp_hz),
        cascades={k: response_error(r, f) for k, r in ratio.items()},
        paths={"e->u1": response_error(ratio["c0"] * ratio["c1"], f),
               "e->u2": response_error(ratio["c0"] * ratio["c2"], f)})


def warp_pct(f_hz: float, rate_hz: float = CONTROL_RATE_HZ, prewarp_hz: float | None = None) -> float:
    """How much faster (%) the bilinear map runs the continuous response at f_hz: the
    discrete response at f is the continuous one at f (1 + warp/100)."""
    fs = bilinear_rate_hz(rate_hz, prewarp_hz)
    w = 2 * math.pi * f_hz
    return (2 * fs * math.tan(w / (2 * rate_hz)) / w - 1.0) * 100.0

