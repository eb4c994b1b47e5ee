"""Frequency responses from open-loop random-excitation records, and the model's.

System identification on the rig (reference §7) drives one motor with band-limited random
current, open loop, and records the encoders (and the gyro on the inertial rig).  This
module turns such a record into a frequency response and puts the testbed model's
response on the same frequency grid, so a plot can overlay them and a number can say how
far apart they are.

Estimator: H1 = S_xy / S_xx
----------------------------
S_xx is the input's auto-spectrum and S_xy the cross-spectrum from input to output, both
Welch averages over the *same* segments with the *same* window (``scipy.signal.welch`` and
``scipy.signal.csd`` with identical arguments), so the ratio is consistent bin by bin.
H1 is the right estimator when the noise is on the output (encoder noise, friction
disturbance) and the input is known well (the commanded current): output noise averages
out of S_xy, whereas it would bias H2 = S_yy / S_yx.

The ordinary coherence γ² = |S_xy|² / (S_xx·S_yy) comes from the same three spectra.  It
says which bins are trustworthy: with uncorrelated output noise of spectrum S_nn,
γ² = SNR / (1 + SNR), SNR = |H|²·S_xx / S_nn, so γ² ≈ 1 means the output in that bin is
explained linearly by the input, and a low γ² means noise, nonlinearity (friction!) or no
excitation there.  With a single segment γ² ≡ 1 whatever the data, so at least two
segments are required.

Units: the response is in output units per input unit (rad/A for encoder angle against
motor current; multiply the model's rad/in-oz by K_t to compare, ``per_amp=True`` below).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from ..plant import model as plant_model
from ..plant.testbed import Testbed
from . import AnalysisError

__all__ = [
    "FrfError", "FrequencyResponse", "FrfComparison", "MODEL_INPUTS", "MODEL_OUTPUTS",
    "MODEL_ALIASES", "h1_estimate", "model_response", "compare_frf",
]


class FrfError(AnalysisError, ValueError):
    """Input to a frequency-response estimate or model evaluation is unusable (the message
    says which argument and why)."""


MIN_SEGMENT_SAMPLES = 8     # shorter segments have too few bins to be a frequency response
MIN_SEGMENTS = 2            # one segment gives γ² ≡ 1: no information about noise


@dataclass(frozen=True, eq=False)
class FrequencyResponse:
    """A measured frequency response on Welch's frequency grid (0 … rate/2)."""

    freq_hz: np.ndarray          # bin centre frequencies
    response: np.ndarray         # complex H1, output units per input unit
    coherence: np.ndarray        # ordinary coherence γ², 0 … 1 (nan where a spectrum is 0)
    segments: int                # Welch segments averaged
    units: str                   # e.g. "rad/A"
    rate_hz: float               # sample rate of the record
    nperseg: int                 # samples per segment (frequency resolution rate/nperseg)

    @property
    def magnitude_db(self) -> np.ndarray:
        """20·log10|H| (nan where H is undefined or 0)."""
        return _db(self.response)

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase of H in degrees, unwrapped over the bins where H is defined."""
        return _unwrapped_phase_deg(self.response)

    @property
    def resolution_hz(self) -> float:
        return self.rate_hz / self.nperseg


@dataclass(frozen=True, eq=False)
class FrfComparison:
    """Measured against model, only where the measurement is trustworthy."""

    freq_hz: np.ndarray
    magnitude_ratio_db: np.ndarray     # 20·log10(|measured| / |model|); nan where not used
    phase_difference_deg: np.ndarray   # arg(measured / model) in (−180, 180]; nan where not used
    used: np.ndarray                   # bool: coherence ≥ min_coherence and both responses defined
    min_coherence: float
    rms_magnitude_ratio_db: float      # over the used bins (nan if none)
    max_abs_magnitude_ratio_db: float
    max_abs_phase_difference_deg: float

    @property
    def bins_used(self) -> int:
        return int(np.count_nonzero(self.used))


# ======================================================================================
# measurement
# ======================================================================================
def _as_signal(name: str, values) -> np.ndarray:
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise FrfError(f"{name} must be a 1-D array of numbers") from None
    if a.ndim != 1:
        raise FrfError(f"{name} must be 1-D, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        i = int(np.argmax(~np.isfinite(a)))
        raise FrfError(f"{name} contains a non-finite value at sample {i} ({a[i]})")
    return a


def _default_nperseg(n: int) -> int:
    """The largest power of two giving at least 8 half-overlapping segments (about 15),
    a usual balance between frequency resolution and variance; never below the minimum."""
    p = 2 ** int(math.floor(math.log2(max(n / 8.0, 1.0))))
    return max(p, MIN_SEGMENT_SAMPLES)


def _checked_rate(rate_hz) -> float:
    try:
        fs = float(rate_hz)
    except (TypeError, ValueError):
        raise FrfError(f"rate_hz = {rate_hz!r}: must be a number > 0 (Hz)") from None
    if not (math.isfinite(fs) and fs > 0.0):
        raise FrfError(f"rate_hz = {rate_hz!r}: must be finite and > 0 (Hz)")
    return fs


def _checked_segments(n: int, nperseg, noverlap) -> tuple[int, int, int]:
    """(nperseg, noverlap, number of Welch segments) for a record of `n` samples, with
    the defaults filled in; raises FrfError if they cannot give a coherence."""
    if n < MIN_SEGMENTS * MIN_SEGMENT_SAMPLES:
        raise FrfError(f"record too short for a frequency response: {n} samples "
                       f"(need at least {MIN_SEGMENTS * MIN_SEGMENT_SAMPLES})")
    if nperseg is None:
        nperseg = _default_nperseg(n)
    if isinstance(nperseg, bool) or not isinstance(nperseg, (int, np.integer)):
        raise FrfError(f"nperseg = {nperseg!r}: must be an integer number of samples")
    nperseg = int(nperseg)
    if nperseg < MIN_SEGMENT_SAMPLES:
        raise FrfError(f"nperseg = {nperseg}: must be at least {MIN_SEGMENT_SAMPLES} samples")
    if noverlap is None:
        noverlap = nperseg // 2
    if isinstance(noverlap, bool) or not isinstance(noverlap, (int, np.integer)) \
            or not 0 <= noverlap < nperseg:
        raise FrfError(f"noverlap = {noverlap!r}: must be an integer in [0, nperseg) = "
                       f"[0, {nperseg})")
    noverlap = int(noverlap)
    segments = 1 + (n - nperseg) // (nperseg - noverlap) if n >= nperseg else 0
    if segments < MIN_SEGMENTS:
        raise FrfError(f"record too short for nperseg = {nperseg}: {n} samples give "
                       f"{segments} segment(s), need at least {MIN_SEGMENTS} "
                       f"(coherence from one segment is always 1); record at least "
                       f"{nperseg + (MIN_SEGMENTS - 1) * (nperseg - noverlap)} samples or "
                       f"use a shorter nperseg")
    return nperseg, noverlap, segments


def _require_excitation(x: np.ndarray) -> None:
    # "No excitation" is judged on the detrended input, as the spectra see it: a constant
    # current (or all zeros) has S_xx = 0 in every bin and H1 would be 0/0 everywhere.
    # The threshold is relative to the input's own size (round-off of a large offset).
    x_dev = x - x.mean()
    scale = max(float(np.max(np.abs(x))), np.finfo(float).tiny)
    if float(np.max(np.abs(x_dev))) <= 1e-12 * scale:
        raise FrfError("input has no excitation (it is constant): a frequency response "
                       "needs a varying input, e.g. the random current of the sysid profiles")


def _h1_and_coherence(sxx: np.ndarray, syy: np.ndarray, sxy: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """H1 = S_xy/S_xx and the coherence from the spectra, NaN in bins without power."""
    # Bins without input power (band-limited excitation) have no response: nan, not a
    # division warning.  Relative threshold: leakage of a window leaves tiny non-zero S_xx.
    floor = 1e-14 * float(np.max(sxx))
    ok_x = sxx > floor
    h = np.full(sxx.shape, np.nan + 1j * np.nan, dtype=complex)
    h[ok_x] = sxy[ok_x] / sxx[ok_x]
    ok_xy = ok_x & (syy > 1e-14 * max(float(np.max(syy)), np.finfo(float).tiny))
    coh = np.full(sxx.shape, np.nan)
    coh[ok_xy] = np.abs(sxy[ok_xy]) ** 2 / (sxx[ok_xy] * syy[ok_xy])
    np.clip(coh, 0.0, 1.0, out=coh)     # round-off can put a perfect bin at 1 + 1e-16
    return h, coh


def h1_estimate(input, output, rate_hz: float, nperseg: int | None = None, *,
                noverlap: int | None = None, window: str = "hann",
                input_units: str = "", output_units: str = "") -> FrequencyResponse:
    """H1 frequency response from ``input`` to ``output`` sampled at ``rate_hz``.

    nperseg   samples per Welch segment (frequency resolution rate_hz/nperseg); default:
              the largest power of two with at least 8 segments in the record.
    noverlap  samples shared by neighbouring segments (default nperseg // 2).
    window    scipy window name, the same for S_xx and S_xy.
    Each segment's mean is removed (a current offset or an angle bias carries no dynamics).

    Raises FrfError for: non-numeric or non-finite samples, different lengths, a record
    shorter than two segments, a bad rate or segment length, and an input without
    excitation (constant).  Bins where S_xx is zero (band-limited input) get nan.
    """
    x = _as_signal("input", input)
    y = _as_signal("output", output)
    if x.size != y.size:
        raise FrfError(f"input and output must have the same length (same samples): "
                       f"{x.size} vs {y.size}")
    fs = _checked_rate(rate_hz)
    nperseg, noverlap, segments = _checked_segments(x.size, nperseg, noverlap)
    _require_excitation(x)
    kw = dict(fs=fs, window=window, nperseg=nperseg, noverlap=noverlap,
              detrend="constant", return_onesided=True, scaling="density")
    try:
        f, sxx = signal.welch(x, **kw)
        _, syy = signal.welch(y, **kw)
        _, sxy = signal.csd(x, y, **kw)
    except ValueError as exc:           # e.g. an unknown window name
        raise FrfError(f"spectral estimate failed: {exc}") from None
    h, coh = _h1_and_coherence(sxx, syy, sxy)
    if output_units or input_units:
        units = f"{output_units or '1'}/{input_units or '1'}"
    else:
        units = "output/input"
    return FrequencyResponse(freq_hz=f, response=h, coherence=coh, segments=int(segments),
                             units=units, rate_hz=fs, nperseg=nperseg)


# ======================================================================================
# the testbed model on the same grid
# ======================================================================================
# inputs of plant/model.py's state space: the motor torques (in-oz)
MODEL_INPUTS = {"T1": 0, "T2": 1}
# outputs, as rows picking states; phi1, phi2 are the encoders (relative to the base)
MODEL_OUTPUTS = ("phi1", "phi2", "los_angle", "los_rate", "gyro_rate")
# the reference's g1(s), g2(s): motor torque to LOS angle
MODEL_ALIASES = {"g1": "T1->los_angle", "g2": "T2->los_angle"}
_OUTPUT_UNITS = {"phi1": "rad", "phi2": "rad", "los_angle": "rad", "los_rate": "rad/s",
                 "gyro_rate": "rad/s"}


def _parse_which(which: str, tb: Testbed) -> tuple[str, str]:
    spec = MODEL_ALIASES.get(which, which)
    if not isinstance(spec, str) or "->" not in spec:
        raise FrfError(f"which = {which!r}: use 'INPUT->OUTPUT' with INPUT in "
                       f"{', '.join(MODEL_INPUTS)} and OUTPUT in {', '.join(MODEL_OUTPUTS)}, "
                       f"or one of {', '.join(MODEL_ALIASES)}")
    inp, out = (s.strip() for s in spec.split("->", 1))
    if inp not in MODEL_INPUTS:
        raise FrfError(f"which = {which!r}: unknown input {inp!r} (use {', '.join(MODEL_INPUTS)})")
    if out not in MODEL_OUTPUTS:
        raise FrfError(f"which = {which!r}: unknown output {out!r} "
                       f"(use {', '.join(MODEL_OUTPUTS)})")
    if not tb.is_2dof and (inp == "T2" or out == "phi2"):
        raise FrfError(f"which = {which!r}: the 1-DOF testbed {tb.name!r} has no fine motor "
                       f"(T2) and no inner axis (phi2)")
    return inp, out


def _output_row(out: str, tb: Testbed) -> np.ndarray:
    c = np.zeros(plant_model.N_STATE)
    if out == "phi1":
        c[plant_model.TH1], c[plant_model.THB] = 1.0, -1.0
    elif out == "phi2":
        c[plant_model.TH2], c[plant_model.THB] = 1.0, -1.0
    elif out == "los_angle":
        c[plant_model.TH2 if tb.is_2dof else plant_model.TH1] = 1.0
    elif out == "los_rate":
        c[plant_model.W2 if tb.is_2dof else plant_model.W1] = 1.0
    else:                                   # gyro_rate: the gyro's own 2nd-order response
        c[plant_model.GY] = 1.0
    return c


def model_response(testbed: Testbed, which: str, freq_hz, *, sample_rate_hz: float | None = None,
                   friction_stiffness_in_oz_per_rad: float = 0.0,
                   per_amp: bool = False) -> np.ndarray:
    """The testbed model's frequency response on ``freq_hz`` (complex).

    which   'INPUT->OUTPUT': INPUT T1 (coarse motor torque) or T2 (fine motor torque);
            OUTPUT phi1 / phi2 (outer / inner encoder, relative to the base), los_angle
            (inertial LOS angle), los_rate (inertial LOS rate), gyro_rate (what the gyro
            reports: its 2nd-order bandwidth and its delay included).  'g1' and 'g2' are
            the reference's T1 → LOS and T2 → LOS.
    sample_rate_hz  None: the continuous model H(jω), as plant.model.plant_transfer_functions.
            A rate: the zero-order-hold equivalent at that rate, H(e^{jωT}) — what a
            record sampled at that rate, with the current held for a period, measures
            (differs from H(jω) near Nyquist).
    friction_stiffness_in_oz_per_rad  k_f of a linearised bearing friction (a spring from
            the outer axis to the base, e.g. σ·f(0) for small-amplitude motion); 0: the
            model's own friction-free plant (viscous b_f only), as g1/g2 in the reference.
    per_amp  multiply by the motor's torque constant K_t: response per ampere of motor
            current, to compare with an FRF measured against current_coarse / current_fine.

    Units: rad/in-oz or (rad/s)/in-oz (per_amp: rad/A, (rad/s)/A).  The model is a free
    rotation at 0 Hz (infinite compliance): freq 0 gives nan.
    """
    if not isinstance(testbed, Testbed):
        raise FrfError(f"testbed must be a plant.testbed.Testbed, got {type(testbed).__name__}")
    inp, out = _parse_which(which, testbed)
    try:
        f = np.asarray(freq_hz, dtype=np.float64)
    except (TypeError, ValueError):
        raise FrfError("freq_hz must be an array of frequencies in Hz") from None
    if f.ndim != 1 or not np.all(np.isfinite(f)) or np.any(f < 0.0):
        raise FrfError("freq_hz must be a 1-D array of finite frequencies >= 0 Hz")
    kf = float(friction_stiffness_in_oz_per_rad)
    if not (math.isfinite(kf) and kf >= 0.0):
        raise FrfError(f"friction_stiffness_in_oz_per_rad = {friction_stiffness_in_oz_per_rad!r}:"
                       f" must be finite and >= 0")
    A, B = plant_model.continuous_model(testbed)
    if kf > 0.0:
        # T_dahl = k_f·(θ1 − θ_b) enters through the model's friction-torque input column
        rel = np.zeros(plant_model.N_STATE)
        rel[plant_model.TH1], rel[plant_model.THB] = 1.0, -1.0
        A = A + kf * np.outer(B[:, 2], rel)
    b = B[:, MODEL_INPUTS[inp]]
    c = _output_row(out, testbed)
    eye = np.eye(plant_model.N_STATE)
    h = np.full(f.shape, np.nan + 1j * np.nan, dtype=complex)
    pos = f > 0.0
    if sample_rate_hz is None:
        s = 2j * np.pi * f[pos]
        mats = s[:, None, None] * eye - A
        vec = b
    else:
        fs = float(sample_rate_hz)
        if not (math.isfinite(fs) and fs > 0.0):
            raise FrfError(f"sample_rate_hz = {sample_rate_hz!r}: must be finite and > 0 (Hz)")
        Ad, Bd = plant_model.discretise(A, B, 1.0 / fs)
        z = np.exp(2j * np.pi * f[pos] / fs)
        mats = z[:, None, None] * eye - Ad
        vec = Bd[:, MODEL_INPUTS[inp]]
    if np.any(pos):
        rhs = np.broadcast_to(vec.astype(complex), (mats.shape[0], vec.size))[..., None]
        try:
            xs = np.linalg.solve(mats, rhs)[..., 0]
        except np.linalg.LinAlgError:
            raise FrfError("model_response: the model is singular at one of the requested "
                           "frequencies (a pole on the imaginary axis)") from None
        h[pos] = xs @ c
    if out == "gyro_rate":
        # the gyro's transport delay (reference: 2.6 ms) is a pure phase lag
        h = h * np.exp(-2j * np.pi * f * testbed.sensors["gyro_delay"])
    if per_amp:
        motor = testbed.motor_coarse if inp == "T1" else testbed.motor_fine
        h = h * motor["torque_constant"]
    return h


def compare_frf(measured: FrequencyResponse, model, *, min_coherence: float = 0.9,
                band_hz: tuple[float, float] | None = None) -> FrfComparison:
    """Magnitude ratio (dB) and phase difference (deg) of ``measured`` against ``model``
    (complex, on measured.freq_hz), only in bins with coherence ≥ ``min_coherence`` (and
    inside ``band_hz`` if given) where both are defined and non-zero; other bins are nan.
    """
    if not isinstance(measured, FrequencyResponse):
        raise FrfError("measured must be a FrequencyResponse (from h1_estimate)")
    m = np.asarray(model, dtype=complex)
    if m.shape != measured.freq_hz.shape:
        raise FrfError(f"model response has {m.size} values, the measurement "
                       f"{measured.freq_hz.size} bins: evaluate the model on measured.freq_hz")
    if not 0.0 <= float(min_coherence) <= 1.0:
        raise FrfError(f"min_coherence = {min_coherence!r}: must be in [0, 1]")
    h = measured.response
    used = (np.isfinite(h) & np.isfinite(m) & (np.abs(h) > 0.0) & (np.abs(m) > 0.0)
            & np.isfinite(measured.coherence))
    used[used] &= measured.coherence[used] >= min_coherence
    if band_hz is not None:
        lo, hi = float(band_hz[0]), float(band_hz[1])
        if not lo < hi:
            raise FrfError(f"band_hz = {band_hz!r}: need low < high")
        used &= (measured.freq_hz >= lo) & (measured.freq_hz <= hi)
    ratio_db = np.full(h.shape, np.nan)
    dphase = np.full(h.shape, np.nan)
    r = h[used] / m[used]
    ratio_db[used] = 20.0 * np.log10(np.abs(r))
    dphase[used] = np.degrees(np.angle(r))         # angle() is in (−π, π]: already wrapped
    if np.any(used):
        rms = float(np.sqrt(np.mean(ratio_db[used] ** 2)))
        mx = float(np.max(np.abs(ratio_db[used])))
        mp = float(np.max(np.abs(dphase[used])))
    else:
        rms = mx = mp = math.nan
    return FrfComparison(freq_hz=measured.freq_hz, magnitude_ratio_db=ratio_db,
                         phase_difference_deg=dphase, used=used,
                         min_coherence=float(min_coherence), rms_magnitude_ratio_db=rms,
                         max_abs_magnitude_ratio_db=mx, max_abs_phase_difference_deg=mp)


# ======================================================================================
# helpers
# ======================================================================================
def _db(h: np.ndarray) -> np.ndarray:
    out = np.full(h.shape, np.nan)
    ok = np.isfinite(h) & (np.abs(h) > 0.0)
    out[ok] = 20.0 * np.log10(np.abs(h[ok]))
    return out


def _unwrapped_phase_deg(h: np.ndarray) -> np.ndarray:
    out = np.full(h.shape, np.nan)
    ok = np.isfinite(h)
    out[ok] = np.degrees(np.unwrap(np.angle(h[ok])))
    return out
