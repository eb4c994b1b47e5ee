"""Power spectral density (Welch) and cumulative spectral power of a sampled signal.

`psd()` is scipy.signal.welch with the choices fixed once for the whole ground station:
Hann windows, 50 % overlap, the mean of each segment removed ("constant" detrend), a
one-sided density in units^2/Hz of the signal's own units.  `csp()` is the running
integral of a PSD over frequency (trapezoidal, 0 at the first frequency); the square
root of its last value is the RMS of the detrended signal, and the square root of the
curve says how much of that RMS lies below each frequency.

Stretches that must not be joined (samples excluded because the sensor was out of
range, frames missing in the telemetry) are handled by averaging only Welch segments
that lie wholly inside one contiguous stretch: a segment never spans a hole.

`psd_of_segments()` is `psd()` with the segment length in samples, and `psd_by_time()`
the live spectrum view's PSD: a short record given by its sample times, split where the
time jumps or frames were lost, the segment length chosen from its longest stretch.

`WelchAccumulator` computes the same average from a signal fed in pieces (a log read
in chunks): it keeps the unfinished segment's samples from one piece to the next, so
the segments - and hence the result - are the same as for the whole array in memory.
No I/O here; the log adapter (log_metrics.py) does the reading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.integrate import cumulative_trapezoid

from . import AnalysisError

WINDOW = "hann"
OVERLAP = 0.5
DEFAULT_SEGMENT_S = 10.0          # 0.1 Hz resolution; an hour gives ~720 averages


def csp(frequency_hz, psd) -> np.ndarray:
    """Cumulative spectral power: the trapezoidal running integral of `psd` over
    `frequency_hz`, 0 at the first frequency (units^2 when psd is in units^2/Hz)."""
    f = np.asarray(frequency_hz, dtype=float)
    p = np.asarray(psd, dtype=float)
    if f.shape != p.shape or f.ndim != 1:
        raise AnalysisError(f"frequency and PSD must be two equally long 1-D arrays, not "
                            f"shapes {f.shape} and {p.shape}")
    if len(f) == 0:
        return np.zeros(0)
    return cumulative_trapezoid(p, f, initial=0.0)


def band_rms(frequency_hz, psd) -> float:
    """The RMS a PSD holds between its first and last frequency: the square root of
    its trapezoidal integral (the cumulative spectral power's end value); NaN with
    fewer than two frequencies."""
    power = csp(frequency_hz, psd)
    return float(np.sqrt(power[-1])) if len(power) > 1 else float("nan")


@dataclass(frozen=True)
class Spectrum:
    """A one-sided Welch PSD and what it was computed from."""

    frequency_hz: np.ndarray
    density: np.ndarray            # units^2/Hz
    units: str                     # of the signal ("rad": density in rad^2/Hz)
    rate_hz: float
    segment_samples: int           # Welch segment length (nperseg)
    segments: int                  # segments averaged

    @property
    def resolution_hz(self) -> float:
        return self.rate_hz / self.segment_samples

    @property
    def csp(self) -> np.ndarray:
        """Cumulative spectral power, units^2."""
        return csp(self.frequency_hz, self.density)

    @property
    def rms(self) -> float:
        """sqrt of the CSP's last value: the RMS of the signal with each segment's mean removed."""
        c = self.csp
        return math.sqrt(max(0.0, float(c[-1]))) if len(c) else 0.0

    def density_units(self) -> str:
        return f"{self.units}^2/Hz" if self.units else "1/Hz"


def segment_samples(rate_hz: float, segment_s: float, available: int) -> int:
    """Welch segment length: `segment_s` of samples, at most the `available` ones (a
    short record gets one segment of its own length rather than none)."""
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise AnalysisError(f"sample rate must be > 0 Hz, not {rate_hz!r}")
    if not (segment_s > 0 and math.isfinite(segment_s)):
        raise AnalysisError(f"the PSD segment length must be > 0 s, not {segment_s!r}")
    return max(2, min(int(round(segment_s * rate_hz)), int(available)))


def _welch_sum(x: np.ndarray, rate_hz: float, nperseg: int) -> tuple[np.ndarray, np.ndarray, int]:
    """(f, sum of the per-segment periodograms, number of segments) of the segments
    that fit wholly in `x`, by scipy.signal.welch (which returns their mean)."""
    noverlap = int(nperseg * OVERLAP)
    step = nperseg - noverlap
    k = (len(x) - noverlap) // step if len(x) >= nperseg else 0
    if k == 0:
        return np.zeros(0), np.zeros(0), 0
    used = x[:nperseg + (k - 1) * step]
    f, p = signal.welch(used, fs=rate_hz, window=WINDOW, nperseg=nperseg, noverlap=noverlap,
                        detrend="constant", scaling="density", return_onesided=True)
    return f, p * k, k


class _Periodograms:
    """The same segments' periodograms as scipy.signal.welch, summed with one batched
    FFT per piece.  scipy's welch (1.17) detrends and transforms segment by segment; on
    the hour of an hour-long log that is 4x slower than the batch, and the chunked
    reader feeds many pieces.  tests/analysis/test_analysis_spectra.py checks the two agree."""

    def __init__(self, rate_hz: float, nperseg: int):
        self.nperseg = nperseg
        self.step = nperseg - int(nperseg * OVERLAP)
        self.window = signal.get_window(WINDOW, nperseg)        # periodic Hann, as welch
        self.frequency_hz = np.fft.rfftfreq(nperseg, 1.0 / rate_hz)
        # density scaling, and the one-sided doubling of every bin but DC (and Nyquist)
        self.scale = np.full(len(self.frequency_hz), 2.0 / (rate_hz * float(np.dot(self.window, self.window))))
        self.scale[0] /= 2.0
        if nperseg % 2 == 0:
            self.scale[-1] /= 2.0

    def sum(self, x: np.ndarray) -> tuple[np.ndarray, int]:
        """(sum of the periodograms of the whole segments in x, their number)."""
        k = (len(x) - self.nperseg) // self.step + 1 if len(x) >= self.nperseg else 0
        if not k:
            return np.zeros(len(self.frequency_hz)), 0
        out = np.zeros(len(self.frequency_hz))
        segs = np.lib.stride_tricks.sliding_window_view(x, self.nperseg)[::self.step][:k]
        # batches of ~2^18 samples bound the temporaries (~10 MB) whatever the piece
        per = max(1, (1 << 18) // self.nperseg)
        for i in range(0, k, per):
            s = segs[i:i + per]
            s = s - s.mean(axis=1, keepdims=True)
            s *= self.window
            spec = np.fft.rfft(s, axis=1)
            out += np.einsum("ij,ij->j", spec.real, spec.real) + np.einsum("ij,ij->j", spec.imag, spec.imag)
        return out * self.scale, k


def runs(n: int, valid=None, gap_before=None) -> list[tuple[int, int]]:
    """[start, stop) of each stretch of consecutive usable samples among n: `valid`
    False excludes a sample, `gap_before` True starts a new stretch at a sample (frames
    are missing before it)."""
    ok = np.ones(n, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    brk = np.zeros(n, dtype=bool) if gap_before is None else np.asarray(gap_before, dtype=bool)
    if ok.shape != (n,) or brk.shape != (n,):
        raise AnalysisError(f"valid and gap_before must have one entry per sample ({n})")
    prev_ok = np.concatenate([[False], ok[:-1]])
    starts = np.flatnonzero(ok & (~prev_ok | brk))
    next_ok = np.concatenate([ok[1:], [False]])
    next_brk = np.concatenate([brk[1:], [True]])
    stops = np.flatnonzero(ok & (~next_ok | next_brk)) + 1
    return list(zip(starts.tolist(), stops.tolist()))


def psd(x, rate_hz: float, *, segment_s: float = DEFAULT_SEGMENT_S, valid=None, gap_before=None,
        units: str = "rad") -> Spectrum:
    """Welch PSD of `x` sampled at `rate_hz` (see the module docstring for the choices).

    Segments are `segment_s` long (at most the record's length); with `valid` /
    `gap_before` only segments wholly inside one contiguous stretch are averaged."""
    a = np.asarray(x, dtype=float)
    if a.ndim != 1 or len(a) == 0:
        raise AnalysisError("the PSD needs a non-empty 1-D series")
    nperseg = segment_samples(rate_hz, segment_s, len(a))
    return psd_of_segments(a, rate_hz, nperseg, valid=valid, gap_before=gap_before, units=units)


def psd_of_segments(x, rate_hz: float, nperseg: int, *, valid=None, gap_before=None,
                    units: str = "rad") -> Spectrum:
    """Welch PSD of `x` with segments of `nperseg` samples: every segment that lies
    wholly inside one contiguous stretch (`valid`, `gap_before` as for `runs`) counts
    once in the average.  `psd()` with the segment length in samples."""
    a = np.asarray(x, dtype=float)
    total, count, f = None, 0, None
    for i0, i1 in runs(len(a), valid, gap_before):
        fr, s, k = _welch_sum(a[i0:i1], rate_hz, nperseg)
        if k:
            total = s if total is None else total + s
            count += k
            f = fr
    if not count:
        raise AnalysisError(f"no contiguous stretch of {nperseg} usable samples "
                            f"({nperseg / rate_hz:g} s) for a PSD segment: shorten the segment "
                            f"or choose a window with fewer excluded samples and gaps")
    return Spectrum(f, total / count, units, float(rate_hz), nperseg, count)


MIN_SEGMENT = 64                  # the shortest segment psd_by_time uses
MAX_SEGMENT = 8192


def time_breaks(t, gap_times=None) -> np.ndarray:
    """`gap_before` for samples stamped with times `t` (seconds, rising): a stretch ends
    where the time jumps by more than 1.5 sample periods (the median spacing), and at
    the first sample at or after each of `gap_times` (where frames went missing)."""
    t = np.asarray(t, dtype=float)
    n = len(t)
    brk = np.zeros(n, dtype=bool)
    if n < 2:
        return brk
    period = float(np.median(np.diff(t)))
    brk[1:] = np.diff(t) > 1.5 * period
    if gap_times is not None and len(gap_times):
        idx = np.searchsorted(t, np.asarray(gap_times, dtype=float), side="left")
        brk[idx[idx < n]] = True
    return brk


def psd_by_time(t, x, gap_times=None, *, max_segment: int = MAX_SEGMENT,
                units: str = "") -> Spectrum | None:
    """Welch PSD of a short record given by its sample times, as the live spectrum view
    shows it: the rate is the median sample spacing's, a stretch ends at a NaN, a time
    jump or a sequence gap (`time_breaks`), and the segment length is the largest power
    of two giving about four segments in the longest stretch (`MIN_SEGMENT` ..
    `max_segment`).  None when fewer than `MIN_SEGMENT` samples are recorded, the times
    do not rise, or no stretch holds a whole segment.

    Every segment counts once in the average, as in `psd()`: a stretch weighs in by its
    number of segments.  (The live view used to weight each stretch's mean by its
    length in samples; with one stretch, the usual case, the two are the same.)"""
    t = np.asarray(t, dtype=float)
    a = np.asarray(x, dtype=float)
    if len(t) < MIN_SEGMENT:
        return None
    period = float(np.median(np.diff(t)))
    if not period > 0:
        return None
    valid = np.isfinite(a)
    gap_before = time_breaks(t, gap_times)
    longest = max((i1 - i0 for i0, i1 in runs(len(a), valid, gap_before)), default=0)
    if longest < MIN_SEGMENT:
        return None
    nperseg = int(min(max_segment, max(MIN_SEGMENT, 2 ** int(math.log2(max(longest // 4, 1))))))
    return psd_of_segments(a, 1.0 / period, nperseg, valid=valid, gap_before=gap_before,
                           units=units)


class WelchAccumulator:
    """Welch's average over a signal that arrives in pieces, with the same segments as
    `psd()` on the whole: feed(piece, valid, gap_before) in order, then result()."""

    def __init__(self, rate_hz: float, nperseg: int, units: str = "rad"):
        if nperseg < 2:
            raise AnalysisError(f"a PSD segment needs at least 2 samples, not {nperseg}")
        self.rate_hz = float(rate_hz)
        self.nperseg = int(nperseg)
        self.units = units
        self._p = _Periodograms(self.rate_hz, self.nperseg)
        self._tail = np.zeros(0)        # samples of the current stretch not yet in a whole segment
        self._open = False              # the last sample fed ended a usable stretch still open
        self._sum = np.zeros(len(self._p.frequency_hz))
        self.segments = 0

    def feed(self, x, valid=None, gap_before=None) -> None:
        a = np.asarray(x, dtype=float)
        n = len(a)
        if not n:
            return
        ok = np.ones(n, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
        for i0, i1 in runs(n, ok, gap_before):
            continues = (i0 == 0 and self._open
                         and not (gap_before is not None and bool(np.asarray(gap_before)[0])))
            buf = np.concatenate([self._tail, a[i0:i1]]) if continues else a[i0:i1]
            s, k = self._p.sum(buf)
            if k:
                self._sum += s
                self.segments += k
                buf = buf[k * self._p.step:]
            self._tail = buf.copy()          # not a view that would keep the whole piece
        # the stretch stays open into the next piece only if this piece ends on a usable sample
        self._open = bool(ok[-1])
        if not self._open:
            self._tail = np.zeros(0)

    def result(self) -> Spectrum:
        if not self.segments:
            raise AnalysisError(f"no contiguous stretch of {self.nperseg} usable samples "
                                f"({self.nperseg / self.rate_hz:g} s) for a PSD segment: shorten "
                                f"the segment or choose a window with fewer excluded samples and gaps")
        return Spectrum(self._p.frequency_hz.copy(), self._sum / self.segments, self.units,
                        self.rate_hz, self.nperseg, self.segments)


__all__ = ["DEFAULT_SEGMENT_S", "MAX_SEGMENT", "MIN_SEGMENT", "OVERLAP", "Spectrum", "WINDOW",
           "WelchAccumulator", "csp", "psd", "psd_by_time", "psd_of_segments", "runs",
           "segment_samples", "time_breaks"]
