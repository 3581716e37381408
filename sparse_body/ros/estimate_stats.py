"""What an estimating node counts, and the /diagnostics status it makes of it (ROS-free, so
the wording and levels are tested without a node)."""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

OK, WARN, ERROR = 0, 1, 2  # diagnostic_msgs/DiagnosticStatus levels
WINDOW = 600  # estimates the rate and latency figures are taken over


@dataclass
class EstimateStats:
    steps: deque = field(default_factory=lambda: deque(maxlen=WINDOW))  # when estimates were made (monotonic)
    latency: deque = field(default_factory=lambda: deque(maxlen=WINDOW))  # tracker stamp to outputs sent, s
    invalid: int = 0
    errors: int = 0
    resets: int = 0  # clock jumps back
    last_error: str = ""
    input_driven: int = 0
    fallback: int = 0  # estimates the fallback timer made
    over_budget: int = 0  # estimates budget_fallback made: the estimator's step missed its budget

    def error(self, text: str) -> None:
        self.errors += 1
        self.last_error = text

    def estimated(self, at: float, fallback: bool, latency: float | None) -> None:
        """An estimate was made at monotonic time `at` (the node has just read the clock)."""
        self.steps.append(at)
        if latency is not None:
            self.latency.append(latency)
        if fallback:
            self.fallback += 1
        else:
            self.input_driven += 1

    def status(
        self, site_names, ages: np.ndarray | None, site_valid: np.ndarray | None, rejected: dict[str, int]
    ) -> tuple[int, str, dict[str, str]]:
        """(level, message, values) of the node's diagnostic status: rates and latency over the
        last estimates, each tracker's age at the last estimate, refused samples by reason."""
        recent = [t for t in self.steps if t > time.monotonic() - 2.0]
        rate = (len(recent) - 1) / (recent[-1] - recent[0]) if len(recent) > 2 else 0.0
        lat = np.array(self.latency) * 1000 if self.latency else np.zeros(1)
        values = {
            "output rate [Hz]": f"{rate:.1f}",
            "latency p50 [ms]": f"{np.percentile(lat, 50):.1f}",
            "latency p99 [ms]": f"{np.percentile(lat, 99):.1f}",
            "invalid estimates": str(self.invalid),
            "estimator errors": str(self.errors),
            "clock jumps back": str(self.resets),
            "estimates driven by input": str(self.input_driven),
            "estimates by the fallback timer": str(self.fallback),
            "estimates by budget_fallback (step over budget)": str(self.over_budget),
            "over budget [%]": f"{100.0 * self.over_budget / max(1, self.input_driven + self.fallback):.1f}",
        }
        stale = []
        if ages is not None and site_valid is not None:
            for site, age, ok in zip(site_names, ages, site_valid, strict=True):
                values[f"{site} age [s]"] = "never seen" if not np.isfinite(age) else f"{age:.3f}"
                if not ok:
                    stale.append(site)
        for reason, count in rejected.items():
            values[f"rejected samples: {reason}"] = str(count)
        if self.errors:
            values["last error"] = self.last_error
        level, message = OK, "estimating"
        if stale:
            level, message = WARN, f"stale or missing trackers: {', '.join(stale)}"
        if self.errors and self.last_error:
            level, message = ERROR, f"estimator errors ({self.errors}): {self.last_error}"
        return level, message, values
