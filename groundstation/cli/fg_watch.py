"""`fg upload --check`'s watch on the device: the base encoder of the last seconds, with
device times, and the wait for its first frame before the output goes on."""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING

from ..core.errors import GroundStationError

if TYPE_CHECKING:           # numpy is imported when a watch runs: `groundstation --help` stays quick
    import numpy as np


#: how long --check waits for the device's first frame before switching the output on, s
FIRST_FRAME_S = 10.0


class BaseEncoderWatch:
    """Telemetry subscriber keeping the base encoder of the last `keep_s` seconds, with
    device times (unwrapped ticks / control rate) - all a check needs, at 16 bytes a frame."""

    def __init__(self, rate_hz: float, keep_s: float):
        from ..codec.ticks import TickUnwrapper

        self.rate = rate_hz
        self.keep = int(keep_s * rate_hz)
        self._unwrap = TickUnwrapper()
        self._t: list[np.ndarray] = []
        self._x: list[np.ndarray] = []
        self._n = 0
        self._lock = threading.Lock()
        self._first = threading.Event()

    def __call__(self, block) -> None:
        import numpy as np

        if block.name != "HIGH_RATE" or not len(block):
            return
        t = self._unwrap.unwrap(block["tick"]) / self.rate
        x = np.asarray(block["encoder_base"], dtype=float)
        with self._lock:
            self._t.append(t)
            self._x.append(x)
            self._n += len(t)
            self._first.set()
            while self._n - len(self._t[0]) > self.keep and len(self._t) > 1:
                self._n -= len(self._t.pop(0))
                self._x.pop(0)

    def wait_first(self, timeout_s: float) -> bool:
        """True once a frame has arrived; False after `timeout_s` without one."""
        return self._first.wait(timeout_s)

    def newest(self) -> float | None:
        with self._lock:
            return float(self._t[-1][-1]) if self._t else None

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        import numpy as np

        with self._lock:
            if not self._t:
                return np.zeros(0), np.zeros(0)
            return np.concatenate(self._t), np.concatenate(self._x)


def first_frame_before_output(enc: BaseEncoderWatch) -> None:
    """The output-on mark is the newest device time seen: with no frame in yet (a quick
    upload right after connecting) there is none, and the check would have nothing to
    start from - refused before the output goes on."""
    if not enc.wait_first(FIRST_FRAME_S):
        raise GroundStationError(f"no base-encoder telemetry within {FIRST_FRAME_S:g} s of "
                                 f"connecting to the device: nothing to check; the output stays off")
