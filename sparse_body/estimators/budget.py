"""A live step within the frame's budget: the estimator in a worker thread, a cheaper one
where it misses (issue 52).

Live, one step longer than the trackers' period puts every later estimate behind. Here the
estimator steps in a worker thread while the caller waits for it up to a deadline. When the
deadline passes first, the caller gets the fallback estimator's pose of that frame (IK: a
fraction of a millisecond) and goes on; the estimator finishes the late frame in its thread
and skips the frames that come while it is busy. Its late pose is dropped: it would be older
than the fallback's already given.

Each estimator sees only the frames it steps, through its own input filter: for a method with
history (DragPoser's last latent, a network's window) a skipped frame is a gap, as after a
dropped tracker frame. The fallback steps only where it is used, so it costs nothing while
the estimator keeps to its budget. ROS-free: the node gives the deadline and says on
/estimate_status and /diagnostics which pose it published.
"""

from __future__ import annotations

import math
import time
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as Pending

from ..core.types import BodyPose, TrackerFrame
from .base import Estimator


class BudgetedStep:
    """step(frame, deadline) -> (pose, whether the fallback made it)."""

    def __init__(self, estimator: Estimator, fallback: Estimator | None) -> None:
        self.estimator, self.fallback = estimator, fallback
        # without a fallback the estimator steps in the caller's thread, as it always did
        self._worker = ThreadPoolExecutor(1, thread_name_prefix="budgeted_step") if fallback is not None else None
        self._running: Future | None = None  # the estimator's step the caller stopped waiting for

    def step(self, frame: TrackerFrame, deadline: float) -> tuple[BodyPose, bool]:
        """The estimator's pose of frame if it comes before `deadline` (time.monotonic(); inf:
        no deadline), else the fallback's. An error of a late step is raised at the next call."""
        if self._worker is None or self.fallback is None:
            return self.estimator.step(frame), False
        if self._running is not None:
            if not self._running.done():  # still on an earlier frame: this one is the fallback's
                return self.fallback.step(frame), True
            late, self._running = self._running, None
            late.result()  # its pose is dropped; its error, if any, is raised here
        running = self._worker.submit(self.estimator.step, frame)
        wait = None if deadline == math.inf else deadline - time.monotonic()
        if wait is not None and wait <= 0.0:  # past already: not waited for, whatever the worker does
            self._running = running
            return self.fallback.step(frame), True
        try:
            return running.result(timeout=wait), False
        except Pending:
            self._running = running
            return self.fallback.step(frame), True

    def reset(self) -> None:
        """Forget all history: the late step, if any, is let finish first (never reset mid-step)."""
        self._settle()
        self.estimator.reset()
        if self.fallback is not None:
            self.fallback.reset()

    def close(self) -> None:
        self._settle()
        if self._worker is not None:
            self._worker.shutdown(wait=True)
            self._worker = None

    def _settle(self) -> None:
        if self._running is not None:
            running, self._running = self._running, None
            running.exception()  # waits; a late error is moot once the estimator starts over
