"""The Analysis dock's live window: what the window's telemetry store holds, analysed like
a log.  No widgets here.

`take_snapshot(session, seconds)` runs on the GUI thread: it copies the newest `seconds`
of device time (None: all the store keeps) of the HIGH_RATE channels the metrics read
out of the Session's TelemetryStore - the ring's own snapshot, a few array copies under
its lock - and notes which testbed the constants come from.  `live_metrics(snapshot)`
runs on a worker thread: it turns the copy into the columns a log holds and hands them
to `log_metrics.metrics_from_columns`, the code analyze_log runs on each chunk it reads.
So the live window and a log of the same frames give the same figures, frames missing
from the window (holes in the device tick) counted and never bridged in the same way.

The store keeps engineering values; the scored sensor's A/D count (which tells a
sample at the rail from a large angle) is recovered from them exactly, by the
dictionary's inverse conversion rounded to the wire type, as the recorder keeps it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...analysis import AnalysisError
from ...analysis.jitter import DEFAULT_INTEGRATION_PERIOD_S
from ...analysis.log_metrics import (CURRENTS, PACKET, SATURATION_BITS, LogMetrics,
                                     metrics_from_columns)
from ...analysis.names import DEFAULT_SENSOR, METRICS, SENSORS
from ...analysis.testbed_figures import TestbedFigures, figures_from_testbed
from ...analysis.spectra import DEFAULT_SEGMENT_S
from ...core.dictionary import PacketDef
from ...logs import LogReader
from ...plant.testbed import Testbed, load_testbed

#: the span the dock analyses by default: the last 30 s the window holds
DEFAULT_LIVE_SECONDS = 30.0
#: the channels the metrics read (those the packet has)
CHANNELS = ("tick", *SENSORS, *CURRENTS, *SATURATION_BITS)


@dataclass(frozen=True, eq=False)
class LiveSnapshot:
    """A copy of the newest HIGH_RATE frames the window holds, oldest first."""

    seconds: float | None              # the span asked for (None: all the store keeps)
    device_time: np.ndarray            # s since the device booted
    columns: dict[str, np.ndarray]     # the store's values (engineering units; bits 0/1)
    packet: PacketDef                  # the items' wire types and conversions
    rate_hz: float                     # the control rate: one frame per tick
    testbed: Testbed | str | None      # the session's testbed (loaded, or its file; None: default)
    replay_log: Path | None = None     # the log being replayed (its own testbed is used)

    @property
    def name(self) -> str:
        """How the dock names it: its row's 'log', the failure it may become."""
        if self.seconds is None:
            return "live window (all it holds)"
        return f"live window (last {self.seconds:.1f} s)"

    @property
    def frames(self) -> int:
        return len(self.device_time)

    def __repr__(self) -> str:            # not the arrays (a log line names it)
        return f"LiveSnapshot({self.name!r}, {self.frames} frames)"


def live_available(session: Any) -> bool:
    """True while a live link or a replay feeds the window's charts."""
    return (getattr(session, "client", None) is not None
            or getattr(session, "replay", None) is not None)


def take_snapshot(session: Any, seconds: float | None = DEFAULT_LIVE_SECONDS) -> LiveSnapshot:
    """GUI thread: copy the newest `seconds` (None or <= 0: all) of the session's store."""
    span = None if seconds is None or seconds <= 0 else float(seconds)
    ring = session.store.ring(PACKET)
    names = [c for c in CHANNELS if c in ring.channels]
    snap = ring.snapshot(names, span)
    station = getattr(session, "station", None)
    testbed = station.testbed if station is not None else getattr(session, "testbed", None)
    replay = getattr(session, "replay", None)
    return LiveSnapshot(span, snap.device_time, dict(snap.values), ring.packet, float(ring.rate),
                        testbed, Path(replay.path) if replay is not None else None)


def _figures(snap: LiveSnapshot, testbed: str | Path | Testbed | None) -> TestbedFigures:
    """The testbed constants: the file the operator chose, else the replayed log's own
    (as analyze_log takes them), else the session's testbed (the default one if it has
    none, as the Station's)."""
    if testbed is not None:
        tb = testbed if isinstance(testbed, Testbed) else load_testbed(testbed)
        return TestbedFigures.of(tb, f"testbed file {tb.path}")
    if snap.replay_log is not None:
        with LogReader(snap.replay_log) as r:
            return figures_from_testbed(r)
    tb = snap.testbed if isinstance(snap.testbed, Testbed) else load_testbed(snap.testbed)
    return TestbedFigures.of(tb, f"the session's testbed {tb.path}")


def live_columns(snap: LiveSnapshot, sensor: str) -> dict[str, np.ndarray]:
    """The snapshot as the columns a log holds: the tick as the wire's u32 and, for the
    scored sensor when it has a conversion to an integer count, "raw/<sensor>"."""
    cols = dict(snap.columns)
    if "tick" in cols:
        cols["tick"] = cols["tick"].astype(np.uint32)
    item = snap.packet.item_by_name.get(sensor)
    if (item is not None and sensor in cols and item.has_conversion
            and item.wire_dtype.kind in "iu" and np.all(np.isfinite(cols[sensor]))):
        cols[f"raw/{sensor}"] = item.to_raw(cols[sensor]).astype(item.wire_dtype.newbyteorder("="))
    return cols


def live_metrics(snap: LiveSnapshot, *, sensor: str = DEFAULT_SENSOR,
                 integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S,
                 testbed: str | Path | Testbed | None = None,
                 psd_segment_s: float = DEFAULT_SEGMENT_S,
                 metrics=METRICS) -> LogMetrics:
    """Worker thread: the metrics of a snapshot (LogMetrics, labelled with its name; the
    window's ends in device time, s since the device booted).  Raises AnalysisError when
    it holds no frames or lacks what a metric needs, TestbedConfigError / LogError when
    the testbed's constants cannot be read."""
    if not snap.frames:
        raise AnalysisError(f"{snap.name}: no {PACKET} frames yet (connect, or open a log)")
    return metrics_from_columns(
        live_columns(snap, sensor), snap.rate_hz, _figures(snap, testbed), source=snap.name,
        window_s=(float(snap.device_time[0]), float(snap.device_time[-1])), metrics=metrics,
        sensor=sensor, integration_period_s=integration_period_s, psd_segment_s=psd_segment_s,
        test_name="live")


__all__ = ["CHANNELS", "DEFAULT_LIVE_SECONDS", "LiveSnapshot", "live_available", "live_columns",
           "live_metrics", "take_snapshot"]
