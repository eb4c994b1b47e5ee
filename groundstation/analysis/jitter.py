"""Line-of-sight jitter: RMS, standard deviation, and the motion seen within one sensor
integration period.

Definitions (the testbed reference; docs/analysis.md has the derivations):

* jitter is the RMS of the LOS angle, or its standard deviation when the angle is not
  zero-mean - both are reported, with the mean;
* the motion a sensor sees during an integration period dT_i is estimated by high-pass
  filtering the angle with H(s) = s / (s + F_i), F_i = 1/dT_i, and taking the RMS
  (`highpass_jitter_rms`); dT_i = 1 s by default;
* for a sinusoid of frequency F_m the exact share is 1 - (2 - 2 cos x) / x^2 with
  x = 2 pi F_m / F_i (`integration_period_factor`).  That is 1 - sinc^2(pi F_m dT_i): the
  fraction of the sinusoid's mean square that lies within one integration period (the
  variance inside a window of length dT_i, averaged over where the window starts).
  `windowed_smear_rms` measures that directly for any signal: the within-window
  variance averaged over every window position, square-rooted.

Samples the scoring sensor could not measure (out of its range, at the A/D rail, not
finite) are excluded and counted, never used: the statistics take the usable samples,
and the windows run per contiguous stretch of them (a stretch also ends where telemetry
frames are missing).  The high-pass filter bridges holes of at most BRIDGE_MAX_PERIODS
of dT_i (input held), restarts from steady state after longer ones, and its first
SETTLING_TIME_CONSTANTS x dT_i after each (re)start are counted apart, not in its RMS
(highpass_sums.py says why: a restart's transient is not motion, and on clipped logs it
made the high-pass RMS exceed the standard deviation).

`los_jitter` works on arrays in memory; `JitterAccumulator` gives the same result for a
signal fed in pieces (a log read in chunks), carrying the filter state, the last window
of samples and running sums from one piece to the next.  No I/O here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from . import AnalysisError
from .highpass_sums import HighpassSums
from .spectra import runs

DEFAULT_INTEGRATION_PERIOD_S = 1.0
#: the high-pass filter runs on through a hole (missing frames and excluded samples
#: together) of at most this fraction of dT_i, its input held: its low-pass state moves at
#: the rate 1/dT_i, so a hold over 1 % of dT_i errs by at most 1 % of the signal's change
#: over the hole (12 frames at 1200 Hz and dT_i = 1 s)
BRIDGE_MAX_PERIODS = 0.01
#: after a (re)start the filter's first SETTLING_TIME_CONSTANTS x dT_i of output are not
#: counted: the start's error in the low-pass state decays as exp(-t/dT_i), so 3 time
#: constants leave 5 % of it in amplitude, 0.25 % in power
SETTLING_TIME_CONSTANTS = 3.0
#: an angle within this fraction of the calibrated range counts as at the range: the
#: A/D's full-scale count times its scale is the range only up to rounding
RANGE_TOLERANCE = 1e-9


# ---------------------------------------------------------------------- closed form
def integration_period_factor(f_m_hz, integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S):
    """1 - (2 - 2 cos x) / x^2, x = 2 pi F_m dT_i: the fraction of a sinusoid's mean
    square that lies within one integration period dT_i (0 at F_m = 0, -> 1 for F_m >>
    1/dT_i, exactly 1 where a whole number of periods fits in dT_i)."""
    _check_period(integration_period_s)
    x = 2 * np.pi * np.asarray(f_m_hz, dtype=float) * integration_period_s
    # 2 - 2 cos x = 4 sin^2(x/2): the factor is 1 - sinc^2(x/2), without the cancellation
    # of 2 - 2 cos x; below x = 0.01 the 1 - sinc^2 still cancels (to 1e-12), and the
    # series x^2/12 - x^4/360 + x^6/20160 is exact to rounding there
    small = np.abs(x) < 1e-2
    half = np.where(small, 1.0, x) / 2
    direct = 1.0 - (np.sin(half) / half) ** 2
    x2 = x * x
    out = np.where(small, x2 / 12 - x2 * x2 / 360 + x2 ** 3 / 20160, direct)
    return float(out) if out.ndim == 0 else out


def sinusoid_smear_rms(amplitude, f_m_hz, integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S):
    """RMS motion within one integration period of a sinusoid of `amplitude` at F_m:
    amplitude * sqrt(factor / 2) (its mean square is amplitude^2 / 2)."""
    return np.asarray(amplitude, dtype=float) * np.sqrt(
        integration_period_factor(f_m_hz, integration_period_s) / 2.0)


def _check_period(integration_period_s: float) -> None:
    if not (integration_period_s > 0 and math.isfinite(integration_period_s)):
        raise AnalysisError(f"the integration period must be > 0 s, not {integration_period_s!r}")


def _check_rate(rate_hz: float) -> None:
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise AnalysisError(f"sample rate must be > 0 Hz, not {rate_hz!r}")


# ---------------------------------------------------------------------- high-pass estimate
def highpass_coefficients(rate_hz: float, integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S):
    """(b, a) of H(s) = s / (s + 1/dT_i) discretised for `rate_hz` by the bilinear
    transform.  The corner is 1/dT_i in rad/s, as the reference writes F_i into H(s);
    at the control rate the transform's frequency warping is negligible there."""
    _check_rate(rate_hz)
    _check_period(integration_period_s)
    return signal.bilinear([1.0, 0.0], [1.0, 1.0 / integration_period_s], fs=rate_hz)


def highpass(angle, rate_hz: float, integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S) -> np.ndarray:
    """The angle through H(s), started in steady state on the first sample (a constant
    offset gives no start transient: its output is 0 throughout)."""
    x = _series(angle)
    b, a = highpass_coefficients(rate_hz, integration_period_s)
    y, _ = signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])
    return y


def highpass_jitter_rms(angle, rate_hz: float,
                        integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S) -> float:
    """RMS of the high-passed angle: the reference's estimate of the motion within one
    integration period (one contiguous series; `los_jitter` handles exclusions)."""
    y = highpass(angle, rate_hz, integration_period_s)
    return math.sqrt(float(np.dot(y, y)) / len(y))


# ---------------------------------------------------------------------- windowed estimate
def window_samples(rate_hz: float, integration_period_s: float) -> int:
    """Samples in one integration period (N samples span N sample intervals = dT_i)."""
    _check_rate(rate_hz)
    _check_period(integration_period_s)
    n = int(round(integration_period_s * rate_hz))
    if n < 2:
        raise AnalysisError(f"an integration period of {integration_period_s:g} s holds fewer "
                            f"than 2 samples at {rate_hz:g} Hz")
    return n


def window_variance_sum(x: np.ndarray, n: int) -> tuple[float, int]:
    """(sum over every window of `n` consecutive samples of `x` of the variance within
    it, number of windows).

    Sums of squares from one running sum over a long record would lose the small
    within-window variance to rounding when the angle drifts far (a 1 mrad offset and a
    0.1 urad jitter are 1e8 apart in square).  So the record is cut into blocks of n
    samples, each taken relative to its own first sample.  The window starting at offset
    o of block b covers samples o..n-1 of block b and 0..o-1 of block b+1, whose values
    move onto block b's reference by d (the difference of the two references): its sum
    is s1 = T_b - C_b[o] + C_{b+1}[o] + o d and its sum of squares s2 = Q_b - C2_b[o] +
    C2_{b+1}[o] + 2 d C_{b+1}[o] + o d^2 (T, Q: block totals; C, C2: running sums).  The
    sum over o of s2 then needs only weighted block sums, and that of s1^2 three more,
    so the cost is a few passes over the data."""
    x = np.asarray(x, dtype=float)
    n_win = len(x) - n + 1
    if n_win <= 0:
        return 0.0, 0
    nb = -(-n_win // n)                         # blocks holding window starts
    need = (nb + 1) * n                         # ... and the block after the last of them
    xp = np.concatenate([x, np.full(need - len(x), x[-1])]) if need > len(x) else x[:need]
    blocks = xp.reshape(nb + 1, n)
    ref = blocks[:, 0].copy()
    z = blocks - ref[:, None]
    c1 = np.empty((nb + 1, n + 1))
    c1[:, 0] = 0.0
    np.cumsum(z, axis=1, out=c1[:, 1:])
    o = np.arange(n, dtype=float)
    w = (n - 1) - o                   # sum over o of C[o] = sum over j of z_j (n - 1 - j)
    w1 = z @ w
    z *= z
    q = z.sum(axis=1)
    w2 = z @ w
    d = ref[1:] - ref[:-1]
    t = c1[:-1, n]
    a = c1[1:, :n] - c1[:-1, :n]                # s1 = a + t + o d
    so, so2 = n * (n - 1) / 2.0, (n - 1) * n * (2 * n - 1) / 6.0
    sum_s2 = n * q[:-1] - w2[:-1] + w2[1:] + 2.0 * d * w1[1:] + d * d * so
    sum_a = a.sum(axis=1)
    sum_s1sq = (np.einsum("ij,ij->i", a, a) + 2.0 * t * sum_a + 2.0 * d * (a @ o)
                + n * t * t + 2.0 * t * d * so + d * d * so2)
    per_block = sum_s2 / n - sum_s1sq / (n * n)
    total = float(per_block[:-1].sum())
    # the last block's windows one by one: those past the record's end read padding
    b, last = nb - 1, n_win - (nb - 1) * n
    ol = o[:last]
    s1 = a[b, :last] + t[b] + ol * d[b]
    c2b = np.concatenate([[0.0], np.cumsum(z[b, :last - 1])]) if last > 1 else np.zeros(1)
    c2n = np.concatenate([[0.0], np.cumsum(z[b + 1, :last - 1])]) if last > 1 else np.zeros(1)
    s2 = q[b] - c2b + c2n + 2.0 * d[b] * c1[b + 1, :last] + ol * d[b] * d[b]
    total += float(np.maximum(s2 / n - (s1 / n) ** 2, 0.0).sum())
    return max(total, 0.0), n_win


def windowed_smear_rms(angle, rate_hz: float,
                       integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S) -> float:
    """The direct ("exact") estimate of the motion within one integration period: the
    variance of the angle within a window of dT_i, averaged over every window position
    (one per sample), square-rooted.

    Every position, not back-to-back windows: windows dT_i apart see a sinusoid of
    F_m = (k + 1/2)/dT_i always at the same phase, and their mean is then off the true
    average by -44 % to +30 % in RMS, depending on that phase (0.5 Hz, dT_i = 1 s)."""
    x = _series(angle)
    n = window_samples(rate_hz, integration_period_s)
    total, count = window_variance_sum(x, n)
    if not count:
        raise AnalysisError(f"the windowed smear needs at least one integration period "
                            f"({integration_period_s:g} s = {n} samples); the series has {len(x)}")
    return math.sqrt(total / count)


def _series(angle) -> np.ndarray:
    x = np.asarray(angle, dtype=float)
    if x.ndim != 1 or len(x) == 0:
        raise AnalysisError("the jitter needs a non-empty 1-D angle series")
    if not np.all(np.isfinite(x)):
        raise AnalysisError("the angle series holds non-finite values: exclude them "
                            "(los_jitter(valid=...)) first")
    return x


# ---------------------------------------------------------------------- usable samples
def sensor_valid(angle, *, range_rad: float | None = None, raw_counts=None) -> np.ndarray:
    """True where the sensor measured: finite, |angle| below its calibrated range
    (`range_rad`, None: no range) and the raw A/D count (`raw_counts`, integer array,
    None: unknown) not at either end of its type (the rail)."""
    x = np.asarray(angle, dtype=float)
    ok = np.isfinite(x)
    if range_rad is not None:
        ok &= np.abs(x) < range_rad * (1.0 - RANGE_TOLERANCE)
    if raw_counts is not None:
        c = np.asarray(raw_counts)
        if c.shape != x.shape:
            raise AnalysisError("raw counts and angles must be equally long")
        if c.dtype.kind in "iu":
            info = np.iinfo(c.dtype)
            ok &= (c != info.min) & (c != info.max)
    return ok


# ---------------------------------------------------------------------- the result
@dataclass(frozen=True)
class JitterResult:
    """Jitter of the scored sensor over a window, in rad (the channel's units)."""

    sensor: str
    mean_rad: float
    rms_rad: float                    # total RMS, mean included
    std_rad: float                    # standard deviation (mean removed)
    highpass_rms_rad: float           # RMS after H(s) = s/(s + 1/dT_i)
    smear_rms_rad: float              # windowed estimate (nan: no stretch of dT_i)
    integration_period_s: float
    samples_used: int
    samples_excluded: int             # out of range / at the rail / not finite
    segments: int                     # contiguous stretches of usable samples
    missing_frames: int = 0           # telemetry frames lost inside the window
    exclusion_rule: str = ""          # what made a sample unusable, for the reader
    highpass_samples_used: int = 0    # settled high-pass outputs in highpass_rms_rad
    highpass_samples_settling: int = 0  # outputs discarded while the filter settled
    highpass_restarts: int = 0        # filter (re)starts: the first, then after long holes

    def text(self) -> str:
        """One line for the CLI, in urad."""
        def u(v: float) -> str:
            return "n/a" if not math.isfinite(v) else f"{v * 1e6:.3f}"
        t = self.integration_period_s
        s = (f"{self.sensor or 'angle'}: RMS {u(self.rms_rad)} urad (mean {u(self.mean_rad)}, std "
             f"{u(self.std_rad)}), high-pass {t:g} s {u(self.highpass_rms_rad)} urad "
             f"({self.highpass_samples_used} settled samples, {self.highpass_samples_settling} "
             f"settling), windowed {t:g} s {u(self.smear_rms_rad)} urad; {self.samples_used} "
             f"samples used in {self.segments} segment(s), {self.samples_excluded} excluded")
        if self.missing_frames:
            s += f", {self.missing_frames} frames missing"
        return s


def highpass_sums(rate_hz: float, integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S
                  ) -> HighpassSums:
    """The high-pass sums with this module's bridge and settling (BRIDGE_MAX_PERIODS,
    SETTLING_TIME_CONSTANTS) for `rate_hz` and dT_i."""
    b, a = highpass_coefficients(rate_hz, integration_period_s)
    return HighpassSums(b, a, bridge_samples=int(math.floor(BRIDGE_MAX_PERIODS * integration_period_s
                                                            * rate_hz)),
                        settle_samples=int(math.ceil(SETTLING_TIME_CONSTANTS * integration_period_s
                                                     * rate_hz)))


def _missing(n: int, gap_before, missing_before) -> np.ndarray | None:
    """Frames missing before each sample for HighpassSums: `missing_before` where given
    (0 where gap_before marks a hole of unknown length: made -1, a hard break), else -1
    wherever gap_before is set."""
    if missing_before is not None:
        m = np.asarray(missing_before, dtype=np.int64)
        if m.shape != (n,):
            raise AnalysisError(f"missing_before must have one entry per sample ({n})")
        if gap_before is not None:
            m = np.where(np.asarray(gap_before, dtype=bool) & (m == 0), -1, m)
        return m
    if gap_before is None:
        return None
    return np.where(np.asarray(gap_before, dtype=bool), -1, 0)


def los_jitter(angle_rad, rate_hz: float, *,
               integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S,
               valid=None, gap_before=None, missing_before=None, sensor: str = "",
               missing_frames: int = 0, exclusion_rule: str = "") -> JitterResult:
    """Jitter figures of an angle series in memory.

    `valid` (bool per sample, e.g. from `sensor_valid`) excludes samples; non-finite
    ones are excluded anyway.  `gap_before` (bool per sample) marks where frames are
    missing before a sample: the windows restart there.  `missing_before` (int per
    sample: how many frames are missing before it; -1 unknown) lets the high-pass
    bridge a short hole; without it every gap restarts the filter."""
    x = np.asarray(angle_rad, dtype=float)
    if x.ndim != 1 or len(x) == 0:
        raise AnalysisError(f"no {sensor or 'angle'} samples in the window")
    ok = np.isfinite(x) if valid is None else np.asarray(valid, dtype=bool) & np.isfinite(x)
    segs = runs(len(x), ok, gap_before)
    used = x[ok]
    if not len(used):
        raise AnalysisError(f"all {len(x)} {sensor or 'angle'} samples of the window are excluded"
                            f"{' (' + exclusion_rule + ')' if exclusion_rule else ''}: choose "
                            f"another window or sensor")
    hp = highpass_sums(rate_hz, integration_period_s)
    hp.feed(x, ok, _missing(len(x), gap_before, missing_before))
    n_win = window_samples(rate_hz, integration_period_s)
    var_sum, windows = 0.0, 0
    for i0, i1 in segs:
        s, c = window_variance_sum(x[i0:i1], n_win)
        var_sum += s
        windows += c
    return JitterResult(
        sensor=sensor, mean_rad=float(np.mean(used)), rms_rad=math.sqrt(float(np.mean(used * used))),
        std_rad=float(np.std(used)), highpass_rms_rad=_highpass_rms(hp),
        smear_rms_rad=math.sqrt(var_sum / windows) if windows else math.nan,
        integration_period_s=float(integration_period_s), samples_used=int(len(used)),
        samples_excluded=int(len(x) - len(used)), segments=len(segs),
        missing_frames=int(missing_frames), exclusion_rule=exclusion_rule,
        highpass_samples_used=hp.used, highpass_samples_settling=hp.settling,
        highpass_restarts=hp.restarts)


def _highpass_rms(hp: HighpassSums) -> float:
    """RMS over the settled outputs; nan when no stretch outlasted the settling."""
    return math.sqrt(hp.sum_squares / hp.used) if hp.used else math.nan


class JitterAccumulator:
    """`los_jitter` for a series fed in pieces: feed(angle, valid, gap_before) in
    order, then result().  Memory: one integration period of samples and a few sums."""

    def __init__(self, rate_hz: float, integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S):
        self.rate_hz = float(rate_hz)
        self.integration_period_s = float(integration_period_s)
        self._hp = highpass_sums(rate_hz, integration_period_s)
        self._n_win = window_samples(rate_hz, integration_period_s)
        # running sums of (x - shift): the first usable sample as shift keeps the
        # variance from cancelling against a large mean
        self._shift: float | None = None
        self.n = 0
        self.excluded = 0
        self.segments = 0
        self._s1 = 0.0
        self._s2 = 0.0
        self._var_sum = 0.0
        self._windows = 0
        #: the smallest and largest usable sample: equal means the sensor never moved
        #: (a sensor not fitted on this set-up reads one constant)
        self.lowest = math.inf
        self.highest = -math.inf
        self._open = False                 # the last sample fed is part of a stretch still open
        self._tail = np.zeros(0)           # its last n_win - 1 samples (windows across pieces)

    def feed(self, angle_rad, valid=None, gap_before=None, missing_before=None) -> None:
        """The next piece, as los_jitter takes the whole (`missing_before`: frames missing
        before each sample, for the high-pass's bridge)."""
        x = np.asarray(angle_rad, dtype=float)
        n = len(x)
        if not n:
            return
        ok = np.isfinite(x) if valid is None else np.asarray(valid, dtype=bool) & np.isfinite(x)
        self._hp.feed(x, ok, _missing(n, gap_before, missing_before))
        used = x if ok.all() else x[ok]          # no copy in the usual case
        self.excluded += n - len(used)
        if len(used):
            if self._shift is None:
                self._shift = float(used[0])
            u = used - self._shift
            self.lowest = min(self.lowest, float(used.min()))
            self.highest = max(self.highest, float(used.max()))
            self.n += len(u)
            self._s1 += float(u.sum())
            self._s2 += float(np.dot(u, u))
        first_gap = gap_before is not None and bool(np.asarray(gap_before)[0])
        for i0, i1 in runs(n, ok, gap_before):
            seg = x[i0:i1]
            continues = i0 == 0 and self._open and not first_gap
            if not continues:
                self.segments += 1
            buf = np.concatenate([self._tail, seg]) if continues else seg
            s, c = window_variance_sum(buf, self._n_win)
            self._var_sum += s
            self._windows += c
            self._tail = buf[len(buf) - (self._n_win - 1):].copy() if len(buf) >= self._n_win else buf.copy()
        self._open = bool(ok[-1])
        if not self._open:
            self._tail = np.zeros(0)

    def result(self, sensor: str = "", *, missing_frames: int = 0, exclusion_rule: str = "") -> JitterResult:
        if not self.n:
            total = self.excluded
            raise AnalysisError(f"all {total} {sensor or 'angle'} samples of the window are excluded"
                                f"{' (' + exclusion_rule + ')' if exclusion_rule else ''}: choose "
                                f"another window or sensor" if total else
                                f"no {sensor or 'angle'} samples in the window")
        m1 = self._s1 / self.n
        var = max(0.0, self._s2 / self.n - m1 * m1)
        mean = self._shift + m1
        return JitterResult(
            sensor=sensor, mean_rad=mean, rms_rad=math.sqrt(var + mean * mean), std_rad=math.sqrt(var),
            highpass_rms_rad=_highpass_rms(self._hp),
            smear_rms_rad=math.sqrt(self._var_sum / self._windows) if self._windows else math.nan,
            integration_period_s=self.integration_period_s, samples_used=self.n,
            samples_excluded=self.excluded, segments=self.segments,
            missing_frames=int(missing_frames), exclusion_rule=exclusion_rule,
            highpass_samples_used=self._hp.used, highpass_samples_settling=self._hp.settling,
            highpass_restarts=self._hp.restarts)


def error_table(frequencies_hz, rate_hz: float, *,
                integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S,
                seconds: float = 600.0) -> list[dict[str, float]]:
    """How far the high-pass estimate is from the exact integration-period share, per
    sinusoid frequency: both measured by this module on a unit sinusoid of `seconds`,
    beside the closed form.  Fractions are of the sinusoid's RMS (1/sqrt 2)."""
    rows = []
    t = np.arange(int(round(seconds * rate_hz))) / rate_hz
    for f in frequencies_hz:
        x = np.sin(2 * np.pi * f * t)
        rms = 1 / math.sqrt(2)
        exact = math.sqrt(integration_period_factor(f, integration_period_s))
        hp = highpass_jitter_rms(x, rate_hz, integration_period_s) / rms
        win = windowed_smear_rms(x, rate_hz, integration_period_s) / rms
        w = 2 * math.pi * f
        gain = w / math.hypot(w, 1.0 / integration_period_s)       # |H(j w)|
        rows.append({"f_m_hz": float(f), "exact_fraction": exact, "windowed_fraction": win,
                     "highpass_fraction": hp, "highpass_gain": gain,
                     "highpass_error": hp / exact - 1.0 if exact > 0 else math.inf})
    return rows


__all__ = ["BRIDGE_MAX_PERIODS", "DEFAULT_INTEGRATION_PERIOD_S", "JitterAccumulator",
           "SETTLING_TIME_CONSTANTS", "highpass_sums", "JitterResult", "error_table",
           "highpass", "highpass_coefficients", "highpass_jitter_rms", "integration_period_factor",
           "los_jitter", "sensor_valid", "sinusoid_smear_rms", "window_samples",
           "window_variance_sum", "windowed_smear_rms"]
