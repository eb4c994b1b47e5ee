"""Limit monitoring from the TOML limits: green / yellow / red per channel, latched.

A subscriber like the recorder: each block is checked with a few vectorised compares
per limited item.  The worst state seen since the operator last acknowledged stays
latched, so a red excursion of one sample cannot go unnoticed between two repaints.
No Qt here.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from ..codec import TelemetryBlock
from ..core.dictionary import Dictionary

GREEN, YELLOW, RED = 0, 1, 2


@dataclass
class LimitState:
    channel: str                 # "PACKET.item"
    units: str
    current: int                 # state of the newest sample
    latched: int                 # worst state since the last acknowledge
    value: float                 # newest value
    worst_value: float           # value that caused the latch
    worst_time: float            # host time of that sample
    yellow: tuple[float, float] | None
    red: tuple[float, float] | None


class LimitMonitor:
    def __init__(self, dictionary: Dictionary):
        self._lock = threading.Lock()
        self.states: dict[str, LimitState] = {}
        self._items: dict[str, list] = {}
        for p in dictionary.packets:
            for item in p.items:
                if item.limits is not None:
                    self._items.setdefault(p.name, []).append(item)
                    key = f"{p.name}.{item.name}"
                    self.states[key] = LimitState(key, item.units, GREEN, GREEN, float("nan"),
                                                  float("nan"), 0.0, item.limits.yellow, item.limits.red)

    def __call__(self, block: TelemetryBlock) -> None:
        for item in self._items.get(block.name, ()):
            v = np.asarray(block.columns[item.name], dtype=np.float64)
            level = np.zeros(len(v), dtype=np.int8)
            lim = item.limits
            if lim.yellow is not None:
                level[(v < lim.yellow[0]) | (v > lim.yellow[1])] = YELLOW
            if lim.red is not None:
                level[(v < lim.red[0]) | (v > lim.red[1])] = RED
            worst = int(np.argmax(level))
            times = np.broadcast_to(block.host_time, (len(v),))
            with self._lock:
                st = self.states[f"{block.name}.{item.name}"]
                st.current, st.value = int(level[-1]), float(v[-1])
                if level[worst] > st.latched:
                    st.latched, st.worst_value, st.worst_time = int(level[worst]), float(v[worst]), float(times[worst])

    def acknowledge(self, channel: str | None = None) -> None:
        """Clear latches (one channel, or all) down to the current state."""
        with self._lock:
            for key, st in self.states.items():
                if channel is None or key == channel:
                    st.latched, st.worst_value = st.current, st.value

    def snapshot(self) -> list[LimitState]:
        with self._lock:
            return [LimitState(**vars(s)) for s in self.states.values()]

    @property
    def worst(self) -> int:
        with self._lock:
            return max((s.latched for s in self.states.values()), default=GREEN)
