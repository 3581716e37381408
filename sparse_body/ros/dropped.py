"""Input a node refused, counted by reason: said once in the log, then counted on /diagnostics
(the retarget and the constraint node, which read the body's JointState from any peer)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable


class DroppedInputs:
    """Counts of refused input by reason, and when the newest was refused (time.monotonic())."""

    def __init__(self, say: Callable[[str], object]) -> None:
        self.say = say  # the log's warning, told each reason the first time
        self.counts: dict[str, int] = {}
        self.last = -math.inf

    def drop(self, reason: str) -> None:
        self.counts[reason] = self.counts.get(reason, 0) + 1
        self.last = time.monotonic()
        if self.counts[reason] == 1:  # said once; counted on /diagnostics after that
            self.say(f"input dropped: {reason}")

    def recent(self, seconds: float) -> bool:
        """Whether an input was dropped within the last `seconds`."""
        return time.monotonic() - self.last < seconds

    def values(self, prefix: str) -> dict[str, str]:
        """/diagnostics' values: `prefix` + reason -> count, by reason."""
        return {f"{prefix}{reason}": str(n) for reason, n in sorted(self.counts.items())}
