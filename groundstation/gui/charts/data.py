"""What the strip charts show, without Qt: the window lengths and timebases offered,
each packet's samples as fetched from the telemetry store for a redraw (with the
host-time mapping described in charts/panel.py), and the rendering figures reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...live.display_buffers import TelemetryStore, aligned_envelope, bin_factor

WINDOW_PRESETS_S = (1, 2, 5, 10, 20, 30, 60, 120, 300, 600)
WINDOW_MIN_S, WINDOW_MAX_S = 1.0, 600.0
TIMEBASES = ("device", "host")


@dataclass(frozen=True)
class ChartStats:
    """Rendering figures for the status bar and the benchmark."""

    fps: float                 # redraws in the last second
    last_refresh_ms: float     # duration of the last refresh (snapshot + decimate + setData)
    points: int                # points handed to the curves in the last refresh
    decimation: int            # largest samples-per-bin factor in the last refresh (1: none)


@dataclass
class _Series:
    """One packet's samples as fetched for a redraw (oldest first)."""

    device_time: np.ndarray
    host_offset: float         # host clock − device clock (s), see the module docstring
    values: dict[str, np.ndarray]
    gap_times: np.ndarray      # device time of the first sample after each gap
    gap_sizes: np.ndarray
    first_index: int = 0       # the ring's number of the first sample (bins align to it)

    def x(self, timebase: str) -> np.ndarray:
        return self.device_time + self.host_offset if timebase == "host" else self.device_time

    def gap_x(self, timebase: str) -> np.ndarray:
        return self.gap_times + self.host_offset if timebase == "host" else self.gap_times


@dataclass
class _Trace:
    """One packet's points for a redraw: x in the chart's timebase, and per channel the
    samples (per == 1) or min, max per bin of `per` samples; `breaks`: point indices
    before which a sequence gap breaks the line."""

    x: np.ndarray
    values: dict[str, np.ndarray]
    per: int
    breaks: np.ndarray
    gap_x: np.ndarray          # gaps in the span, in the chart's timebase
    gap_sizes: np.ndarray


def frozen_trace(series: _Series, timebase: str, lo: float, hi: float, bins: int) -> _Trace:
    """The points of frozen (paused) data between lo and hi, binned as live."""
    x = series.x(timebase)
    i0 = max(int(np.searchsorted(x, lo, side="left")) - 1, 0)
    i1 = int(np.searchsorted(x, hi, side="right")) + 1
    xs = x[i0:i1]
    gx = series.gap_x(timebase)
    span = (gx >= xs[0]) & (gx <= xs[-1]) if len(xs) else np.zeros(len(gx), dtype=bool)
    gx, gn = gx[span], series.gap_sizes[span]
    per = bin_factor(len(xs), bins)
    values = {}
    if per == 1:
        at = np.searchsorted(xs, gx, side="left")
        breaks = at[(at > 0) & (at < len(xs))]
        for name, v in series.values.items():
            values[name] = v[i0:i1]
        return _Trace(xs, values, 1, breaks, gx, gn)
    for name, v in series.values.items():
        bx, values[name] = aligned_envelope(xs, v[i0:i1], series.first_index + i0, per)
    if not values:
        bx = xs[:0]
    b = np.searchsorted(bx[0::2], gx, side="right") - 1
    return _Trace(bx, values, per, 2 * np.unique(b[b >= 1]), gx, gn)


def _window_label(seconds: float) -> str:
    return f"{seconds / 60:g} min" if seconds >= 60 else f"{seconds:g} s"


def newest_times(store: TelemetryStore) -> dict[str, float]:
    """Device time of every packet's newest sample (a zero-length snapshot)."""
    out = {}
    for name, ring in store.rings.items():
        dev = ring.snapshot([], seconds=0.0).device_time
        if len(dev):
            out[name] = float(dev[-1])
    return out


def fetch_series(store: TelemetryStore, wanted: dict[str, set[str]], window_s: float,
                 frozen_end: dict[str, float] | None) -> dict[str, _Series]:
    """The wanted channels of each packet (packet -> channel names): the newest
    `window_s` seconds, or while paused (`frozen_end`: packet -> device time of its
    newest sample when paused) the `window_s` seconds up to that end."""
    out = {}
    for packet, names in wanted.items():
        ring = store.rings.get(packet)
        if ring is None:
            continue
        if frozen_end is None:
            snap = ring.snapshot(sorted(names), seconds=window_s)
            dev, values = snap.device_time, snap.values
            gaps, sizes = snap.gap_device_times, snap.gap_sizes
        else:
            end = frozen_end.get(packet, -math.inf)
            snap = ring.snapshot(sorted(names))
            dev = snap.device_time
            i0 = int(np.searchsorted(dev, end - window_s, side="left"))
            i1 = int(np.searchsorted(dev, end, side="right"))
            dev = dev[i0:i1]
            values = {k: v[i0:i1] for k, v in snap.values.items()}
            keep = snap.gap_device_times <= end
            gaps, sizes = snap.gap_device_times[keep], snap.gap_sizes[keep]
        if not len(dev):
            continue
        host = snap.host_time if frozen_end is None else snap.host_time[i0:i1]
        offset = float(np.nanmin(host - dev)) if np.isfinite(host).any() else 0.0
        first = snap.first_index + (0 if frozen_end is None else i0)
        out[packet] = _Series(dev, offset, values, gaps, sizes, first)
    return out

