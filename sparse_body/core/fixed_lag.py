"""Live smoothing with a chosen lag (the filter option `filter_lag`, seconds; node parameter
of the same name): each frame that comes in releases the frame `lag` seconds before it,
smoothed by the samples that came after it.

Why: the live filter has only the past, and under noise it must choose between lag and
shake; the offline smoother (core/tracker_smoother.py) has the whole future but needs the
whole recording. A user who can wait a few frames gets most of the smoother's gain for a
latency they choose (the README's lag curve gives what each lag buys, measured).

How: the live filter's recursion forwards (the same model, noise levels and accelerations,
and the same rules for starting a site over), every state of the last frames kept; at each
frame, the offline smoother's backward step (tracker_smoother.rts_step) from the newest
sample down to the released frame. With a lag of 0 frames this is the live filter; with a
lag longer than the recording, the offline smoother (both are tests). Invalid, non-finite
and unfiltered samples pass untouched, as the live filter passes them.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from .tracker_filter import FilterConfig, covariance_step
from .tracker_smoother import _Rotation, _Vector, rts_step
from .types import TrackerFrame


@dataclass(frozen=True)
class _Sample:
    """One usable sample of one site, as the forward filter left it."""

    frame: int  # the running number of its frame
    stamp: float
    state: tuple  # (value, rate, covariance) after the sample
    predicted: tuple | None  # (value, rate, covariance) it was compared with; None: started over here


class _Chain:
    """One site's position (or orientation) samples: the forward filter's state after each
    of the frames still held, newest last."""

    def __init__(self, q: float, r: float, space, jump: float, gap: float) -> None:
        self.q, self.r, self.space, self.jump, self.gap = q, r, space, jump, gap
        self.samples: deque[_Sample] = deque()
        self.last: _Sample | None = None  # the newest sample, kept after it leaves `samples`

    def add(self, frame: int, stamp: float, z: np.ndarray) -> None:
        """The forward filter's step on sample z (tracker_filter._position / _orientation)."""
        last, space = self.last, self.space
        dt = stamp - last.stamp if last is not None else math.nan
        sample = None
        if last is not None and 0 < dt <= self.gap:
            value, rate, cov = last.state
            pred = space.advance(value, rate, dt)
            e = space.minus(z, pred)
            if space is _Rotation or e @ e <= self.jump * self.jump:
                pred_cov, (k0, k1), updated = covariance_step(cov, dt, self.q, self.r)
                state = (space.plus(pred, k0 * e), rate + k1 * e, updated)
                sample = _Sample(frame, stamp, state, (pred, rate, pred_cov))
        if sample is None:  # start over from this sample: the rate unknown (zero, wide)
            sample = _Sample(frame, stamp, (z, np.zeros(3), (self.r, 0.0, 1e4 * self.r)), None)
        self.samples.append(sample)
        self.last = sample

    def smoothed(self, frame: int) -> np.ndarray | None:
        """The value at that frame, smoothed by every held sample after it (None: no sample
        of this site in that frame)."""
        samples = self.samples
        while samples and samples[0].frame < frame:  # released already
            samples.popleft()
        if not samples or samples[0].frame != frame:
            return None
        later = samples[-1]
        value, rate = later.state[0], later.state[1]
        for k in range(len(samples) - 2, -1, -1):
            earlier = samples[k]
            if later.predicted is None:  # a new start: nothing after it speaks for this one
                value, rate = earlier.state[0], earlier.state[1]
            else:
                value, rate = rts_step(
                    earlier.state, later.predicted, later.stamp - earlier.stamp, (value, rate), self.space
                )
            later = earlier
        return value


class FixedLagSmoother:
    """The tracker filter with a lag: call it with each frame; it returns the frame lag_frames
    before, smoothed (None while fewer have come since a reset); flush() returns the frames
    still held, smoothed by what there is, at the end of a recording."""

    def __init__(self, config: FilterConfig, lag_frames: int) -> None:
        if lag_frames < 0:
            raise ValueError(f"the lag must be 0 frames or more, got {lag_frames}")
        self.config, self.lag_frames = config, int(lag_frames)
        c = config
        self._quantities: list[tuple[float, float, type, float]] = []  # (r, q, space, jump threshold)
        if c.position_noise > 0:
            self._quantities.append((max(c.position_noise, 1e-9) ** 2, c.acceleration**2, _Vector, c.jump))
        if c.rotation_noise > 0:
            self._quantities.append(
                (max(math.radians(c.rotation_noise), 1e-9) ** 2, c.spin_acceleration**2, _Rotation, math.inf)
            )
        self.reset()

    def reset(self) -> None:
        self._frames: deque[tuple[int, TrackerFrame]] = deque()
        self._chains: dict[tuple[str, int], _Chain] = {}  # (site, quantity): its samples
        self._count = 0

    def __call__(self, frame: TrackerFrame) -> TrackerFrame | None:
        self._add(frame)
        return self._release() if len(self._frames) > self.lag_frames else None

    def stream(self, frames):
        """A recording's frames smoothed, one out for each one in, in order."""
        for frame in frames:
            out = self(frame)
            if out is not None:
                yield out
        yield from self.flush()

    def flush(self) -> list[TrackerFrame]:
        out = []
        while self._frames:
            out.append(self._release())
        return out

    def _add(self, frame: TrackerFrame) -> None:
        number, self._count = self._count, self._count + 1
        self._frames.append((number, frame))
        for i, site in enumerate(frame.sites):
            if not frame.valid[i]:
                continue
            for which, (r, q, space, jump) in enumerate(self._quantities):
                z = _usable(frame, i, space)
                if z is not None:
                    chain = self._chains.get((site, which))
                    if chain is None:
                        chain = self._chains[(site, which)] = _Chain(q, r, space, jump, self.config.gap)
                    chain.add(number, float(frame.stamp), z)

    def _release(self) -> TrackerFrame:
        number, frame = self._frames.popleft()
        positions = np.array(frame.positions, dtype=float)
        orientations = np.array(frame.orientations, dtype=float)
        for i, site in enumerate(frame.sites):
            for which, (_, _, space, _) in enumerate(self._quantities):
                chain = self._chains.get((site, which))
                value = chain.smoothed(number) if chain is not None else None
                if value is not None:
                    (orientations if space is _Rotation else positions)[i] = value
        return TrackerFrame(frame.stamp, frame.sites, positions, orientations, frame.valid)


def _usable(frame: TrackerFrame, i: int, space) -> np.ndarray | None:
    """Site i's sample of this quantity as the live filter takes it (an orientation made unit
    length), or None where it passes untouched (space.usable)."""
    value = np.asarray((frame.positions if space is _Vector else frame.orientations)[i], dtype=float)
    if not space.usable(value):
        return None
    return value if space is _Vector else value / math.sqrt(float(value @ value))
