"""Base-motion power spectral densities: a table of (frequency in Hz, PSD in rad^2/Hz).

File format (`profiles/base_motion/*.csv`):

    # comments anywhere (also after a value), blank lines ignored
    frequency_hz,psd_rad2_per_hz        <- optional header line, before the data
    0.1,1.2e-6
    0.5,1.2e-6
    ...

Frequencies strictly increasing and >= 0, PSD values >= 0 and finite, at least two rows.
Between rows the PSD is interpolated on log-log axes (a straight line in dB per octave,
as vibration spectra are specified), linearly where a row has frequency or PSD 0; outside
the table it is 0 (the spectrum is band-limited).  A malformed file raises PsdFileError
naming the file and line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import GroundStationError


class BaseMotionError(GroundStationError):
    """A base-motion profile cannot be made or checked as asked (the message says why)."""


class PsdFileError(BaseMotionError):
    """A PSD table is missing or malformed (the message names the file and line)."""


@dataclass(frozen=True)
class PsdTable:
    """A band-limited one-sided PSD of the base angle."""

    frequency_hz: np.ndarray
    psd_rad2_per_hz: np.ndarray
    name: str = "psd"
    source: str = ""
    comments: tuple[str, ...] = field(default=(), compare=False)

    def __post_init__(self):
        f = np.asarray(self.frequency_hz, dtype=float)
        s = np.asarray(self.psd_rad2_per_hz, dtype=float)
        if f.ndim != 1 or f.shape != s.shape or len(f) < 2:
            raise BaseMotionError("a PSD table needs two equally long columns of at least 2 rows")
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(s))):
            raise BaseMotionError("PSD table values must be finite")
        if f[0] < 0 or np.any(np.diff(f) <= 0):
            raise BaseMotionError("PSD table frequencies must be >= 0 and strictly increasing")
        if np.any(s < 0) or not np.any(s > 0):
            raise BaseMotionError("PSD table values must be >= 0 and not all 0")
        object.__setattr__(self, "frequency_hz", f)
        object.__setattr__(self, "psd_rad2_per_hz", s)

    # ------------------------------------------------------------------ shape
    @property
    def band_hz(self) -> tuple[float, float]:
        """The frequencies between which the PSD is not zero."""
        nz = np.nonzero(self.psd_rad2_per_hz > 0)[0]
        lo = self.frequency_hz[max(nz[0] - 1, 0)]
        hi = self.frequency_hz[min(nz[-1] + 1, len(self.frequency_hz) - 1)]
        return float(lo), float(hi)

    def _loglog(self, i: int) -> bool:
        f, s = self.frequency_hz, self.psd_rad2_per_hz
        return f[i] > 0 and s[i] > 0 and s[i + 1] > 0

    def density(self, frequency_hz) -> np.ndarray:
        """PSD (rad^2/Hz) at the given frequencies; 0 outside the table."""
        x = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
        f, s = self.frequency_hz, self.psd_rad2_per_hz
        out = np.zeros_like(x)
        seg = np.searchsorted(f, x, side="right") - 1
        seg = np.where(x == f[-1], len(f) - 2, seg)
        inside = (seg >= 0) & (seg < len(f) - 1)
        for i in np.unique(seg[inside]):
            m = inside & (seg == i)
            if self._loglog(i):
                b = math.log(s[i + 1] / s[i]) / math.log(f[i + 1] / f[i])
                out[m] = s[i] * (x[m] / f[i]) ** b
            else:
                out[m] = s[i] + (s[i + 1] - s[i]) * (x[m] - f[i]) / (f[i + 1] - f[i])
        return out

    def _segment_integral(self, i: int, upper: np.ndarray) -> np.ndarray:
        """Integral of the PSD from f[i] to `upper` (each within segment i), exact."""
        f1, f2 = self.frequency_hz[i], self.frequency_hz[i + 1]
        s1, s2 = self.psd_rad2_per_hz[i], self.psd_rad2_per_hz[i + 1]
        if self._loglog(i):
            b = math.log(s2 / s1) / math.log(f2 / f1)
            if abs(b + 1) < 1e-12:
                return s1 * f1 * np.log(upper / f1)
            return s1 * f1 / (b + 1) * ((upper / f1) ** (b + 1) - 1)
        slope = (s2 - s1) / (f2 - f1)
        d = upper - f1
        return s1 * d + slope * d * d / 2

    def cumulative(self, frequency_hz) -> np.ndarray:
        """Cumulative spectral power (rad^2): the PSD integrated from 0 to each frequency."""
        x = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
        f = self.frequency_hz
        whole = np.array([float(self._segment_integral(i, np.array(f[i + 1])))
                          for i in range(len(f) - 1)])
        before = np.concatenate([[0.0], np.cumsum(whole)])      # CSP at each table row
        xc = np.clip(x, f[0], f[-1])
        seg = np.clip(np.searchsorted(f, xc, side="right") - 1, 0, len(f) - 2)
        out = before[seg].copy()
        for i in np.unique(seg):
            m = seg == i
            out[m] += self._segment_integral(i, xc[m])
        return out

    def variance_rad2(self) -> float:
        return float(self.cumulative(self.frequency_hz[-1])[0])

    def rms_rad(self) -> float:
        return math.sqrt(self.variance_rad2())

    def scaled_to_rms(self, rms_rad: float) -> "PsdTable":
        """The same shape with the given RMS."""
        if not (rms_rad > 0 and math.isfinite(rms_rad)):
            raise BaseMotionError(f"a target RMS must be a positive number, not {rms_rad!r}")
        k = (rms_rad / self.rms_rad()) ** 2
        return PsdTable(self.frequency_hz, self.psd_rad2_per_hz * k, self.name, self.source,
                        self.comments)


def parse_psd(text: str, source: str = "<text>", name: str | None = None) -> PsdTable:
    """Parse the CSV text of a PSD table (see the module's docstring for the format)."""
    rows: list[tuple[float, float]] = []
    comments: list[str] = []
    header_seen = False
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line, _, comment = raw.partition("#")
        if comment.strip() and not line.strip():
            comments.append(comment.strip())
        line = line.strip()
        if not line:
            continue
        fields = [p.strip() for p in line.split(",")]
        where = f"{source}:{lineno}"
        if len(fields) != 2:
            raise PsdFileError(f"{where}: expected 2 comma-separated values (frequency_hz, "
                               f"psd_rad2_per_hz), found {len(fields)}: {line!r}")
        try:
            fr, psd = float(fields[0]), float(fields[1])
        except ValueError:
            if rows or header_seen:
                raise PsdFileError(f"{where}: not a number: {line!r} (only one header line, "
                                   f"before the data)") from None
            header_seen = True
            if "deg" in fields[1].lower():
                raise PsdFileError(f"{where}: the PSD column is in degrees ({fields[1]!r}); "
                                   f"give it in rad^2/Hz") from None
            continue
        if not (math.isfinite(fr) and math.isfinite(psd)):
            raise PsdFileError(f"{where}: values must be finite numbers: {line!r}")
        if fr < 0:
            raise PsdFileError(f"{where}: frequency {fr:g} Hz is negative")
        if psd < 0:
            raise PsdFileError(f"{where}: PSD {psd:g} rad^2/Hz is negative")
        if rows and fr <= rows[-1][0]:
            raise PsdFileError(f"{where}: frequency {fr:g} Hz is not above the previous row's "
                               f"{rows[-1][0]:g} Hz (frequencies must increase)")
        rows.append((fr, psd))
    if len(rows) < 2:
        raise PsdFileError(f"{source}: a PSD table needs at least 2 rows of frequency_hz,"
                           f"psd_rad2_per_hz, found {len(rows)}")
    arr = np.array(rows)
    if not np.any(arr[:, 1] > 0):
        raise PsdFileError(f"{source}: every PSD value is 0 (no motion to make)")
    return PsdTable(arr[:, 0], arr[:, 1], name or Path(source).stem, source, tuple(comments))


def load_psd(path: str | Path) -> PsdTable:
    """Read a PSD table file; PsdFileError (naming file and line) if it is not one."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise PsdFileError(f"{path}: PSD file not found (see profiles/base_motion/)") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise PsdFileError(f"{path}: cannot read ({exc})") from None
    return parse_psd(text, str(path), path.stem)
