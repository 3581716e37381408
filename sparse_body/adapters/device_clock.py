"""Device time -> host time.

A tracker stamps samples with its own microsecond counter (32 bits: it wraps every 71.6
minutes) that runs at its own slightly wrong rate. A sample's host arrival time is its
device time plus an offset plus a transport delay that is never negative, so the smallest
(arrival - device time) over a recent window is the offset with the least delay in it.
The window slides, which follows the drift between the two clocks; a device counter that
goes back by more than a wrap can explain (the device restarted) starts over.
"""

from __future__ import annotations

from collections import deque

WRAP_US = 1 << 32


class DeviceClock:
    def __init__(self, window: float = 5.0) -> None:
        self.window = window
        self.reset()

    def reset(self) -> None:
        self._last_raw: int | None = None
        self._epochs = 0
        self._offsets: deque[tuple[float, float]] = deque()  # (arrival, arrival - device seconds)
        self.restarts = 0

    def _unwrap(self, raw_us: int) -> float:
        if self._last_raw is not None and raw_us < self._last_raw:
            if self._last_raw - raw_us > WRAP_US // 2:
                self._epochs += 1  # the counter wrapped
            else:
                restarted = self._last_raw - raw_us > 1_000_000
                if restarted:  # the device restarted: a new timeline
                    self.restarts += 1
                    self._epochs = 0
                    self._offsets.clear()
        self._last_raw = raw_us
        return (self._epochs * WRAP_US + raw_us) * 1e-6

    def to_host(self, raw_us: int, arrival: float) -> float:
        """The host time at which the device took a sample, given when it arrived."""
        device = self._unwrap(int(raw_us))
        offset = arrival - device
        while self._offsets and self._offsets[-1][1] >= offset:  # monotonic deque: min in O(1)
            self._offsets.pop()
        self._offsets.append((arrival, offset))
        while self._offsets[0][0] < arrival - self.window:
            self._offsets.popleft()
        return device + self._offsets[0][1]
