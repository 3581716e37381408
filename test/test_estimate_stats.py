"""The estimator node's /diagnostics status, made from its counts without a node."""

import time

import numpy as np

from sparse_body.ros.estimate_stats import ERROR, OK, WARN, EstimateStats


def test_status_names_stale_trackers_and_errors_and_counts_each_estimate():
    stats = EstimateStats()
    for k in range(5):
        stats.estimated(time.monotonic(), fallback=k == 4, latency=0.002 * (k + 1))
    sites = ["head", "left_hand"]
    level, message, values = stats.status(sites, np.array([0.01, np.inf]), np.array([True, False]), {"nan": 3})
    assert level == WARN and message == "stale or missing trackers: left_hand"
    assert values["estimates driven by input"] == "4" and values["estimates by the fallback timer"] == "1"
    assert values["head age [s]"] == "0.010" and values["left_hand age [s]"] == "never seen"
    assert values["rejected samples: nan"] == "3" and values["latency p50 [ms]"] == "6.0"
    stats.error("FloatingPointError: boom")
    level, message, values = stats.status(sites, None, None, {})
    assert level == ERROR and message == "estimator errors (1): FloatingPointError: boom"
    assert values["last error"] == "FloatingPointError: boom"
    assert EstimateStats().status([], None, None, {})[:2] == (OK, "estimating")
