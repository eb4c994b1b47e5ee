"""Waveform generators for command profiles: pure numpy/scipy, no I/O.

Every generator returns float64 samples at `rate` (the controller's 1200 Hz unless told
otherwise), in the units of the quantity it drives, measured from the *rest value* 0:
no current, no rate, or (for a position reference) the position the profile starts from.

Smoothness is the point of most of the code here.  The device plays whatever it is sent,
sample by sample, so a waveform that starts with a jump or a kink makes the hardware do
exactly that.  Two mechanisms keep the edges clean:

* oscillating waveforms (sine, sweep, noise, PRBS, multisine, CSV data) are multiplied by
  a raised-cosine *taper* over `ramp_s` at each end: the first and last samples are
  exactly 0 and the envelope's slope is 0 there too;
* motions (step, ramp, triangle, constant-velocity moves) are built from their velocity:
  each change of velocity is a raised-cosine blend of `blend_s` (or a minimum-jerk or
  raised-cosine step of `rise_s`), integrated in closed form, so the position is smooth,
  the distance travelled is exactly the one asked for, and the motion starts from rest
  with zero velocity.  A raw step happens only when asked for by name.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

# scipy.signal is imported inside the generators that use it (sweep, band-limited
# noise, PRBS): its import costs about 0.3 s, and a campaign's check builds every
# profile it will play, most of them steps, ramps and sines that never need it.
from ..core.dictionary import default_control_rate_hz
from ..core.errors import GroundStationError

#: the controller's rate, one sample per control period (the protocol dictionary's)
RATE_HZ = default_control_rate_hz()

STEP_SHAPES = ("raised_cosine", "minimum_jerk", "raw")
SWEEP_METHODS = ("logarithmic", "linear")
NOISE_METHODS = ("fft", "butterworth")
MULTISINE_SPACINGS = ("log", "linear")
MULTISINE_PHASES = ("low_crest", "schroeder", "random")

#: iterations of clip-and-refilter allowed to bring band-limited noise under a peak limit
CREST_ITERATIONS = 200
#: phase iterations of a low-crest-factor multisine
MULTISINE_ITERATIONS = 100


class GeneratorError(GroundStationError, ValueError):
    """Generator parameters that cannot give a waveform (the message names the parameter)."""


# ----------------------------------------------------------------------------- helpers
def samples_for(duration_s: float, rate: float = RATE_HZ, what: str = "duration_s") -> int:
    """Number of samples in `duration_s` (rounded to the nearest whole sample)."""
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise GeneratorError(f"{what} must be a finite number > 0, not {duration_s!r}")
    n = int(round(duration_s * rate))
    if n < 1:
        raise GeneratorError(f"{what} = {duration_s} s is shorter than one sample at {rate:g} Hz")
    return n


def _positive(name: str, value: float, *, zero_ok: bool = False) -> float:
    value = float(value)
    if not math.isfinite(value) or value < 0 or (value == 0 and not zero_ok):
        raise GeneratorError(f"{name} must be {'>= 0' if zero_ok else '> 0'}, not {value!r}")
    return value


def _below_nyquist(name: str, f: float, rate: float) -> float:
    f = _positive(name, f)
    if f >= rate / 2:
        raise GeneratorError(f"{name} = {f:g} Hz is not below the Nyquist frequency "
                             f"{rate / 2:g} Hz of the {rate:g} Hz control rate")
    return f


def taper(n: int, ramp_n: int) -> np.ndarray:
    """Raised-cosine envelope of n samples: 0 → 1 over the first ramp_n + 1 samples and
    back to 0 over the last ones; 0 (with zero slope) at both ends.  ramp_n = 0: all ones."""
    w = np.ones(n)
    if ramp_n <= 0:
        return w
    if 2 * ramp_n > n - 1:
        raise GeneratorError(f"the ramps in and out ({ramp_n} samples each) do not fit in "
                             f"{n} samples: shorten ramp_s or lengthen the profile")
    k = np.arange(ramp_n + 1)
    edge = 0.5 - 0.5 * np.cos(np.pi * k / ramp_n)
    w[:ramp_n + 1] = edge
    w[n - 1 - ramp_n:] = edge[::-1]
    return w


def smooth_step(u: np.ndarray, shape: str = "raised_cosine") -> np.ndarray:
    """0 for u ≤ 0, 1 for u ≥ 1, and in between a transition of the named shape.

    raised_cosine: zero slope at both ends; minimum_jerk (10u³ − 15u⁴ + 6u⁵): zero slope
    and zero acceleration at both ends; raw: the jump at u = 0."""
    u = np.asarray(u, dtype=float)
    if shape == "raw":
        return (u >= 0).astype(float)
    c = np.clip(u, 0.0, 1.0)
    if shape == "raised_cosine":
        return 0.5 - 0.5 * np.cos(np.pi * c)
    if shape == "minimum_jerk":
        return c ** 3 * (10.0 - 15.0 * c + 6.0 * c * c)
    raise GeneratorError(f"shape must be one of {', '.join(STEP_SHAPES)}, not {shape!r}")


def _blend_integral(t: np.ndarray, centre: float, blend: float) -> np.ndarray:
    """∫ S dt for a unit velocity change centred at `centre`, S a raised-cosine blend of
    width `blend` (or an instant change for blend = 0).  Closed form: exact distance."""
    if blend <= 0:
        return np.maximum(t - centre, 0.0)
    u = (t - centre) / blend
    out = np.where(u >= 0.5, u, 0.0)
    mid = np.abs(u) < 0.5
    um = u[mid] + 0.5
    out[mid] = 0.5 * um - np.sin(np.pi * um) / (2 * np.pi)
    return out * blend


def velocity_profile(segments: Sequence[tuple[float, float]], blend_s: float,
                     rate: float = RATE_HZ, end_value: float | None = None) -> np.ndarray:
    """Position samples of a motion given as (duration_s, velocity) segments.

    Each velocity change (from rest into the first segment, between segments, and back to
    rest after the last) is a raised-cosine blend of `blend_s` centred on the nominal
    boundary, which keeps the distance of every segment exactly duration × velocity.
    Half a blend is added before the first and after the last boundary, so the motion
    starts and ends at rest with zero velocity.  `end_value` (if given) is written
    exactly into the samples after the motion, removing the rounding of the sum."""
    blend = _positive("blend_s", blend_s, zero_ok=True)
    starts = [blend / 2]
    for d, _ in segments:
        starts.append(starts[-1] + _positive("segment duration", d, zero_ok=True))
    end = starts[-1] + blend / 2
    n = int(math.ceil(end * rate - 1e-9)) + 1
    t = np.arange(n) / rate
    x = np.zeros(n)
    v_prev = 0.0
    for centre, v in zip(starts, [v for _, v in segments] + [0.0]):
        dv = v - v_prev
        if dv:
            x += dv * _blend_integral(t, centre, blend)
        v_prev = v
    if end_value is not None:
        x[t >= end - 1e-12] = end_value
    x[0] = 0.0
    return x


def _pad(x: np.ndarray, n: int | None, what: str, rate: float = RATE_HZ) -> np.ndarray:
    """Hold the last value up to n samples (n = None: as generated)."""
    if n is None or n == len(x):
        return x
    if n < len(x):
        raise GeneratorError(f"duration_s is too short: the {what} needs {len(x)} samples "
                             f"({len(x) / rate:g} s at {rate:g} Hz), the profile has {n}")
    return np.concatenate([x, np.full(n - len(x), x[-1])])


# ----------------------------------------------------------------------------- motions
def step(duration_s: float, level: float, *, t_step_s: float = 0.5, rise_s: float = 0.05,
         shape: str = "raised_cosine", return_at_s: float | None = None,
         rate: float = RATE_HZ) -> np.ndarray:
    """From rest to `level` starting at t_step_s, over rise_s; back to rest from
    return_at_s if given.  shape 'raw' is the one way to get a true jump."""
    n = samples_for(duration_s, rate)
    if shape not in STEP_SHAPES:
        raise GeneratorError(f"shape must be one of {', '.join(STEP_SHAPES)}, not {shape!r}")
    t = np.arange(n) / rate
    t_step_s = _positive("t_step_s", t_step_s, zero_ok=shape != "raw")
    rise = _positive("rise_s", rise_s) if shape != "raw" else 1.0
    if shape != "raw" and t_step_s + rise_s > duration_s:
        raise GeneratorError(f"the step (t_step_s {t_step_s:g} + rise_s {rise_s:g}) does not "
                             f"end within duration_s {duration_s:g}")
    x = level * smooth_step((t - t_step_s) / rise, shape)
    if return_at_s is not None:
        if return_at_s < t_step_s + (rise_s if shape != "raw" else 0.0):
            raise GeneratorError("return_at_s must come after the step has risen")
        if shape != "raw" and return_at_s + rise_s > duration_s:
            raise GeneratorError(f"the return step (return_at_s {return_at_s:g} + rise_s "
                                 f"{rise_s:g}) does not end within duration_s {duration_s:g}")
        x -= level * smooth_step((t - return_at_s) / rise, shape)
    return x


def ramp(level: float, ramp_time_s: float, *, hold_s: float = 0.0, t_start_s: float = 0.0,
         back: bool = True, blend_s: float = 0.1, duration_s: float | None = None,
         rate: float = RATE_HZ) -> np.ndarray:
    """A linear ramp from rest to `level` over ramp_time_s, held for hold_s, and (back =
    true) the same ramp down to rest; corners blended over blend_s."""
    ramp_time_s = _positive("ramp_time_s", ramp_time_s)
    slope = level / ramp_time_s
    segs = [(_positive("t_start_s", t_start_s, zero_ok=True), 0.0), (ramp_time_s, slope),
            (_positive("hold_s", hold_s, zero_ok=True), 0.0)]
    if back:
        segs.append((ramp_time_s, -slope))
    x = velocity_profile(segs, blend_s, rate, end_value=0.0 if back else level)
    return _pad(x, None if duration_s is None else samples_for(duration_s, rate), "ramp", rate)


def triangle(amplitude: float, velocity: float, *, cycles: int = 1, turnaround_s: float = 0.5,
             duration_s: float | None = None, rate: float = RATE_HZ) -> np.ndarray:
    """A triangle wave at constant |velocity|: rest → +amplitude → −amplitude → … → rest,
    `cycles` full cycles (4·amplitude/velocity each); reversals blended over turnaround_s."""
    a = _positive("amplitude", amplitude)
    v = _positive("velocity", velocity)
    if int(cycles) != cycles or cycles < 1:
        raise GeneratorError(f"cycles must be a whole number ≥ 1, not {cycles!r}")
    leg = a / v
    segs = [(leg, v)] + [(2 * leg, v if j % 2 == 0 else -v) for j in range(1, 2 * int(cycles))] \
        + [(leg, v)]
    x = velocity_profile(segs, turnaround_s, rate, end_value=0.0)
    return _pad(x, None if duration_s is None else samples_for(duration_s, rate), "triangle", rate)


def constant_velocity(velocity: float, stroke: float, *, accel_s: float = 0.2,
                      dwell_s: float = 0.5, cycles: int = 1, lead_s: float = 0.0,
                      duration_s: float | None = None, rate: float = RATE_HZ) -> np.ndarray:
    """Constant-velocity passes over a stroke centred on the rest position: rest →
    +stroke/2, dwell, a pass to −stroke/2 at −velocity, dwell, a pass back at +velocity,
    … (`cycles` back-and-forth pairs), and back to rest.  Each full pass covers the whole
    stroke at constant velocity between accel_s blends (steady-state friction vs velocity)."""
    v = _positive("velocity", velocity)
    s = _positive("stroke", stroke)
    if int(cycles) != cycles or cycles < 1:
        raise GeneratorError(f"cycles must be a whole number ≥ 1, not {cycles!r}")
    dwell = _positive("dwell_s", dwell_s, zero_ok=True)
    pass_s = s / v
    if accel_s > pass_s:
        raise GeneratorError(f"accel_s = {accel_s:g} s is longer than a pass over the stroke "
                             f"({pass_s:g} s at this velocity): no constant-velocity part is left")
    segs = [(_positive("lead_s", lead_s, zero_ok=True), 0.0), (pass_s / 2, v), (dwell, 0.0)]
    for c in range(int(cycles)):
        segs += [(pass_s, -v), (dwell, 0.0)]
        segs += [(pass_s, v), (dwell, 0.0)] if c < cycles - 1 else []
    segs += [(pass_s / 2, v)]
    x = velocity_profile(segs, accel_s, rate, end_value=0.0)
    return _pad(x, None if duration_s is None else samples_for(duration_s, rate),
                "constant-velocity motion", rate)


# ----------------------------------------------------------------------------- oscillations
def sine(duration_s: float, amplitude: float, frequency_hz: float, *, ramp_s: float = 1.0,
         rate: float = RATE_HZ) -> np.ndarray:
    """amplitude·sin(2π f t), tapered in and out over ramp_s."""
    n = samples_for(duration_s, rate)
    f = _below_nyquist("frequency_hz", frequency_hz, rate)
    t = np.arange(n) / rate
    return amplitude * np.sin(2 * np.pi * f * t) * taper(n, int(round(ramp_s * rate)))


def swept_sine(duration_s: float, amplitude: float, f_start_hz: float, f_stop_hz: float, *,
               method: str = "logarithmic", ramp_s: float = 1.0, rate: float = RATE_HZ) -> np.ndarray:
    """A sine whose frequency runs from f_start_hz at t = 0 to f_stop_hz at the end
    (scipy.signal.chirp, starting at phase 0), tapered in and out over ramp_s."""
    n = samples_for(duration_s, rate)
    f0 = _below_nyquist("f_start_hz", f_start_hz, rate)
    f1 = _below_nyquist("f_stop_hz", f_stop_hz, rate)
    if method not in SWEEP_METHODS:
        raise GeneratorError(f"method must be one of {', '.join(SWEEP_METHODS)}, not {method!r}")
    t = np.arange(n) / rate
    t1 = (n - 1) / rate
    from scipy import signal
    y = signal.chirp(t, f0, t1, f1, method=method, phi=-90.0)
    return amplitude * y * taper(n, int(round(ramp_s * rate)))


def sweep_frequency(t: np.ndarray, duration_s: float, f_start_hz: float, f_stop_hz: float,
                    method: str = "logarithmic", rate: float = RATE_HZ) -> np.ndarray:
    """Instantaneous frequency of `swept_sine` at times t (what a test or a plot needs)."""
    t1 = (samples_for(duration_s, rate) - 1) / rate
    if method == "linear":
        return f_start_hz + (f_stop_hz - f_start_hz) * t / t1
    return f_start_hz * (f_stop_hz / f_start_hz) ** (t / t1)


def _band_mask(n: int, rate: float, f_low: float, f_high: float) -> np.ndarray:
    f = np.fft.rfftfreq(n, 1.0 / rate)
    return (f >= f_low) & (f <= f_high)


def band_limited_noise(duration_s: float, rms: float, f_low_hz: float, f_high_hz: float, *,
                       seed: int = 0, ramp_s: float = 1.0, method: str = "fft", order: int = 4,
                       peak_limit: float | None = None, rate: float = RATE_HZ) -> np.ndarray:
    """Gaussian noise confined to [f_low_hz, f_high_hz], tapered over ramp_s, with an RMS of
    exactly `rms` over the full-amplitude part (between the ramps).

    method 'fft' zeroes every FFT bin outside the band (a brick-wall band; nothing outside
    it but what the tapers smear); 'butterworth' filters forwards and backwards
    (sosfiltfilt, zero phase) with a Butterworth band-pass of `order`.  With peak_limit,
    the peaks are brought under it by clipping and re-band-limiting in turn (the band and
    the RMS stay exact); a limit the noise cannot reach is an error naming the crest factor."""
    n = samples_for(duration_s, rate)
    rms = _positive("rms", rms)
    f_high = _below_nyquist("f_high_hz", f_high_hz, rate)
    f_low = _positive("f_low_hz", f_low_hz, zero_ok=True)
    if f_low >= f_high:
        raise GeneratorError(f"f_low_hz ({f_low:g}) must be below f_high_hz ({f_high:g})")
    if method not in NOISE_METHODS:
        raise GeneratorError(f"method must be one of {', '.join(NOISE_METHODS)}, not {method!r}")
    ramp_n = int(round(ramp_s * rate))
    w = taper(n, ramp_n)
    steady = slice(ramp_n, n - ramp_n) if ramp_n else slice(0, n)
    if method == "fft":
        mask = _band_mask(n, rate, f_low, f_high)
        if not mask.any():
            raise GeneratorError(f"no frequency of a {n}-sample profile lies in "
                                 f"[{f_low:g}, {f_high:g}] Hz: widen the band or lengthen it")

        def shape(x: np.ndarray) -> np.ndarray:
            spec = np.fft.rfft(x)
            spec[~mask] = 0.0
            return np.fft.irfft(spec, n)
    else:
        if int(order) != order or not 1 <= order <= 10:
            raise GeneratorError(f"order must be a whole number 1 … 10, not {order!r}")
        from scipy import signal
        if f_low > 0:
            sos = signal.butter(int(order), [f_low, f_high], btype="bandpass", fs=rate, output="sos")
        else:
            sos = signal.butter(int(order), f_high, btype="lowpass", fs=rate, output="sos")
        if n <= 3 * (2 * sos.shape[0] + 1):
            raise GeneratorError(f"{n} samples are too few for a Butterworth filter of order "
                                 f"{order}: lengthen the profile or use method = 'fft'")

        def shape(x: np.ndarray) -> np.ndarray:
            return signal.sosfiltfilt(sos, x)

    rng = np.random.default_rng(seed)
    x = shape(rng.standard_normal(n))

    def scaled(y: np.ndarray) -> np.ndarray:
        r = float(np.sqrt(np.mean(y[steady] ** 2)))
        if r == 0:
            raise GeneratorError("the band-limited noise is zero: widen the band")
        return y * (rms / r)

    x = scaled(x)
    if peak_limit is not None:
        limit = _positive("peak_limit", peak_limit)
        if limit <= rms:
            raise GeneratorError(f"peak_limit ({limit:g}) must be above the RMS ({rms:g}): "
                                 f"band-limited noise cannot have a crest factor of 1")
        for _ in range(CREST_ITERATIONS):
            if np.abs(x * w).max() <= limit:
                break
            # clip a little below the limit: re-band-limiting brings part of the peak back
            x = scaled(shape(np.clip(x, -0.97 * limit, 0.97 * limit)))
        else:
            raise GeneratorError(
                f"could not bring the noise's peaks under peak_limit {limit:g} (crest factor "
                f"{limit / rms:.2f}); reached {np.abs(x * w).max() / rms:.2f} - raise the limit, "
                f"lower the RMS or widen the band")
    return x * w


def prbs(amplitude: float, bits: int, *, samples_per_bit: int = 1, periods: int = 1,
         ramp_s: float = 0.5, seed: int = 0, rate: float = RATE_HZ) -> np.ndarray:
    """A maximum-length binary sequence (scipy.signal.max_len_seq) of ±amplitude, each bit
    held samples_per_bit samples, `periods` whole periods at full amplitude, with ramps of
    ramp_s before and after in which the sequence continues cyclically under the taper."""
    a = _positive("amplitude", amplitude)
    if int(bits) != bits or not 2 <= bits <= 32:
        raise GeneratorError(f"bits must be a whole number 2 … 32, not {bits!r}")
    if int(samples_per_bit) != samples_per_bit or samples_per_bit < 1:
        raise GeneratorError(f"samples_per_bit must be a whole number ≥ 1, not {samples_per_bit!r}")
    if int(periods) != periods or periods < 1:
        raise GeneratorError(f"periods must be a whole number ≥ 1, not {periods!r}")
    bits, spb = int(bits), int(samples_per_bit)
    length = (1 << bits) - 1
    ramp_n = int(round(ramp_s * rate))
    n = 2 * ramp_n + int(periods) * length * spb
    if n > 50_000_000:
        raise GeneratorError(f"a PRBS of {bits} bits x {spb} x {periods} periods is far longer "
                             f"than any profile the device accepts")
    rng = np.random.default_rng(seed)
    state = rng.integers(0, 2, bits).astype(np.int8)
    if not state.any():
        state[0] = 1                          # the all-zero state never leaves zero
    from scipy import signal
    seq, _ = signal.max_len_seq(bits, state=state, length=length)
    levels = np.where(seq > 0, a, -a)
    k = (np.arange(n) - ramp_n) // spb % length
    return levels[k] * taper(n, ramp_n)


def multisine_frequencies(f_low_hz: float, f_high_hz: float, n_freqs: int, period_s: float, *,
                          spacing: str = "log", rate: float = RATE_HZ) -> np.ndarray:
    """The multisine's frequencies: n_freqs spaced over [f_low, f_high], each moved to the
    nearest multiple of 1/period (so each period holds whole cycles: no leakage in an FFT
    of whole periods); duplicates after rounding are dropped."""
    period_n = samples_for(period_s, rate, "period_s")
    df = rate / period_n
    f_high = _below_nyquist("f_high_hz", f_high_hz, rate)
    f_low = _positive("f_low_hz", f_low_hz)
    if f_low >= f_high:
        raise GeneratorError(f"f_low_hz ({f_low:g}) must be below f_high_hz ({f_high:g})")
    if spacing not in MULTISINE_SPACINGS:
        raise GeneratorError(f"spacing must be one of {', '.join(MULTISINE_SPACINGS)}, not {spacing!r}")
    if int(n_freqs) != n_freqs or n_freqs < 1:
        raise GeneratorError(f"n_freqs must be a whole number ≥ 1, not {n_freqs!r}")
    lo, hi = math.ceil(f_low / df - 1e-9), math.floor(f_high / df + 1e-9)
    if hi < lo:
        raise GeneratorError(f"no multiple of 1/period_s = {df:g} Hz lies in [{f_low:g}, "
                             f"{f_high:g}] Hz: lengthen period_s")
    want = np.geomspace(f_low, f_high, int(n_freqs)) if spacing == "log" \
        else np.linspace(f_low, f_high, int(n_freqs))
    k = np.unique(np.clip(np.rint(want / df), lo, hi).astype(int))
    return k * df


def multisine(rms: float, f_low_hz: float, f_high_hz: float, *, n_freqs: int = 20,
              period_s: float = 10.0, periods: int = 1, spacing: str = "log",
              phases: str = "low_crest", seed: int = 0, ramp_s: float = 1.0,
              rate: float = RATE_HZ) -> np.ndarray:
    """Equal-amplitude sinusoids at `multisine_frequencies`; `periods` whole periods at full
    amplitude with an RMS of exactly `rms`, and ramps of ramp_s before and after (the
    periodic signal continued under the taper).

    phases: 'schroeder' (the classic low-crest-factor formula, best for linear spacing),
    'random' (seeded), or 'low_crest' (default): Schroeder phases improved by clipping the
    peaks and taking the phases back from the clipped signal's spectrum, iterated, keeping
    the best; the amplitudes and frequencies stay exact, only the phases change."""
    rms = _positive("rms", rms)
    if phases not in MULTISINE_PHASES:
        raise GeneratorError(f"phases must be one of {', '.join(MULTISINE_PHASES)}, not {phases!r}")
    if int(periods) != periods or periods < 1:
        raise GeneratorError(f"periods must be a whole number ≥ 1, not {periods!r}")
    freqs = multisine_frequencies(f_low_hz, f_high_hz, n_freqs, period_s, spacing=spacing, rate=rate)
    period_n = samples_for(period_s, rate, "period_s")
    bins = np.rint(freqs * period_n / rate).astype(np.int64)
    m = len(bins)
    if phases == "random":
        phi = np.random.default_rng(seed).uniform(0, 2 * np.pi, m)
    else:
        k = np.arange(1, m + 1)
        phi = -np.pi * k * (k - 1) / m

    def period(ph: np.ndarray) -> np.ndarray:
        # one period by inverse FFT: exact sinusoids on the period's frequency grid
        spec = np.zeros(period_n // 2 + 1, complex)
        spec[bins] = np.exp(1j * ph) * (period_n / 2)
        return np.fft.irfft(spec, period_n)

    one = period(phi)
    if phases == "low_crest" and m > 2:
        best = one
        for _ in range(MULTISINE_ITERATIONS):
            # clipping at 1.2 x RMS worked best over 1-100 Hz, 10-50 tones (crest factor
            # ~2.8 from Schroeder's ~4.4 for log spacing)
            level = 1.2 * float(np.sqrt(np.mean(one ** 2)))
            phi = np.angle(np.fft.rfft(np.clip(one, -level, level))[bins])
            one = period(phi)
            if np.abs(one).max() < np.abs(best).max():
                best = one
        one = best
    one = one * (rms / float(np.sqrt(np.mean(one ** 2))))
    ramp_n = int(round(ramp_s * rate))
    n = 2 * ramp_n + int(periods) * period_n
    x = one[(np.arange(n) - ramp_n) % period_n]
    return x * taper(n, ramp_n)


def resample_series(values: np.ndarray, times_s: np.ndarray | None = None, *, ramp_s: float = 0.0,
                    rate: float = RATE_HZ) -> np.ndarray:
    """Samples from data (a CSV file's column): as they are when `times_s` is None (one per
    control period), otherwise linearly interpolated onto the 1200 Hz grid from times_s[0]
    to times_s[-1]; tapered over ramp_s if > 0.  Data with content above 600 Hz must be
    low-pass filtered first: interpolation does not remove it."""
    y = np.asarray(values, dtype=float)
    if y.ndim != 1 or len(y) < 1:
        raise GeneratorError("the data must be one column with at least one value")
    if not np.all(np.isfinite(y)):
        bad = int(np.flatnonzero(~np.isfinite(y))[0])
        raise GeneratorError(f"value {bad + 1} is not a finite number")
    if times_s is not None:
        t = np.asarray(times_s, dtype=float)
        if t.shape != y.shape:
            raise GeneratorError("the time and value columns differ in length")
        if len(t) < 2 or not np.all(np.diff(t) > 0) or not np.all(np.isfinite(t)):
            raise GeneratorError("the time column must increase strictly (at least two rows)")
        n = int(math.floor((t[-1] - t[0]) * rate + 1e-9)) + 1
        y = np.interp(t[0] + np.arange(n) / rate, t, y)
    ramp_n = int(round(ramp_s * rate))
    return y * taper(len(y), ramp_n) if ramp_n else y
