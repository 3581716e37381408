"""Live smoothing with a chosen lag (core/fixed_lag.py, the filter option filter_lag): its two
ends are the live filter and the offline smoother, and in between it trades latency for shake."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sparse_body.core.fixed_lag import FixedLagSmoother
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import Skeleton
from sparse_body.core.tracker_filter import FilterConfig, TrackerFilter
from sparse_body.core.tracker_smoother import smooth_frames
from sparse_body.core.types import TrackerFrame
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import LOBSTR_NOISE, NO_NOISE, synthesize_trackers
from sparse_body.methods.factory import create_estimator

SITES = ("head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")
NOISY = FilterConfig(position_noise=0.01, rotation_noise=1.5, gap=0.1)


def _messy_stream(rng, n: int, jumps: bool) -> list[TrackerFrame]:
    """Six trackers with dropped, non-finite and denormalised samples and gaps; with jumps,
    also a relocalised system and a clock that goes back."""
    steps = [1 / 60, 1 / 90, 0.3, -0.5] if jumps else [1 / 60, 1 / 90, 0.3, 1 / 60]
    t = np.cumsum(rng.choice(steps, size=n, p=[0.8, 0.17, 0.02, 0.01]))
    positions = np.cumsum(rng.normal(0, 0.01, (n, 6, 3)), axis=0)
    if jumps:
        positions[rng.random(n) < 0.01] += 2.0
    orientations = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.05, (n * 6, 3)), axis=0)).as_quat()
    orientations = orientations.reshape(n, 6, 4) * rng.choice([1.0, 1.05, 0.5], size=(n, 6, 1), p=[0.9, 0.08, 0.02])
    positions[rng.random((n, 6)) < 0.01] = np.nan
    valid = rng.random((n, 6)) > 0.03
    return [TrackerFrame(float(t[i]), SITES, positions[i], orientations[i], valid[i]) for i in range(n)]


def _same(a: list[TrackerFrame], b: list[TrackerFrame], atol: float) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert x.stamp == y.stamp and np.array_equal(x.valid, y.valid)
        np.testing.assert_allclose(x.positions, y.positions, rtol=0, atol=atol, equal_nan=True)
        np.testing.assert_allclose(x.orientations, y.orientations, rtol=0, atol=atol, equal_nan=True)


@pytest.mark.parametrize("config", [FilterConfig(), NOISY, FilterConfig(rotation_noise=0.0)])
def test_a_lag_of_no_frames_is_the_live_filter(rng, config):
    frames = _messy_stream(rng, 1200, jumps=True)
    live = TrackerFilter(config, SITES)
    _same(list(FixedLagSmoother(config, 0).stream(frames)), [live(f) for f in frames], atol=1e-12)


def test_a_lag_longer_than_the_recording_is_the_offline_smoother(rng):
    """With the offline smoother's accelerations set to the live filter's (the fixed-lag
    smoother follows the live filter's), and no jumps (the two cut a run at a jump by
    different tests: the innovation live, the step between samples offline)."""
    config = FilterConfig(
        position_noise=0.01, rotation_noise=1.5, gap=0.1, smooth_acceleration=0.5, smooth_spin_acceleration=1.5
    )
    frames = _messy_stream(rng, 600, jumps=False)
    smoother = FixedLagSmoother(config, len(frames))
    assert all(smoother(f) is None for f in frames)  # nothing released before the lag is up
    _same(smoother.flush(), smooth_frames(frames, config), atol=1e-9)


def test_each_frame_of_lag_buys_steadier_trackers_on_a_noisy_walk():
    """Between its ends the smoother trades latency for shake: the tracker positions'
    velocity error falls with every lag in 0, 3, 6, 12 frames (a walk with LoBSTr's noise)."""
    motion = synthetic_walk(6.0)
    sensors = load_sensor_config("six_point")
    truth = synthesize_trackers(motion, sensors, NO_NOISE).positions
    noisy = list(synthesize_trackers(motion, sensors, LOBSTR_NOISE, seed=2))
    config = FilterConfig(position_noise=0.01, rotation_noise=1.5)
    errors = []
    for lag in (0, 3, 6, 12):
        out = list(FixedLagSmoother(config, lag).stream(noisy))
        assert [f.stamp for f in out] == [f.stamp for f in noisy]  # one out for each one in, in order
        est = np.array([f.positions for f in out])
        errors.append(np.linalg.norm(np.diff(est - truth, axis=0), axis=-1).mean() * motion.fps)
    offline = np.array([f.positions for f in smooth_frames(noisy, config)])
    assert errors == sorted(errors, reverse=True) and errors[-1] < 0.7 * errors[0], errors
    assert errors[-1] > np.linalg.norm(np.diff(offline - truth, axis=0), axis=-1).mean() * motion.fps * 0.9


def test_the_filter_lag_option_delays_each_pose_by_its_frames_and_is_range_checked():
    motion = synthetic_walk(2.0)
    sensors = load_sensor_config("six_point")
    frames = list(synthesize_trackers(motion, sensors, LOBSTR_NOISE, seed=1))
    lagged = create_estimator("ik", sensors, motion.skeleton, fps=motion.fps, filter_lag=0.05)
    assert lagged.lag == pytest.approx(3 / motion.fps)
    poses = [lagged.step(f) for f in frames[:10]]
    assert not any(p.valid for p in poses[:3])  # held while the first frames are smoothed
    assert [p.stamp for p in poses[3:]] == [f.stamp for f in frames[:7]]  # then each pose is 3 frames old
    assert all(p.stamp < q.stamp for p, q in zip(poses, poses[1:], strict=False))  # stamps never go back
    # offline, the same poses, aligned with their frames: one per frame, the last ones flushed
    offline = lagged.process(frames)
    assert [p.stamp for p in offline] == [f.stamp for f in frames]
    for live, late in zip(poses[3:], offline, strict=False):
        np.testing.assert_allclose(live.local_quats, late.local_quats, atol=1e-12)
        np.testing.assert_allclose(live.root_position, late.root_position, atol=1e-12)
    for bad in (0.6, -0.1):
        with pytest.raises(ValueError, match="filter: lag must be from 0 to 0.5 .seconds."):
            create_estimator("ik", sensors, Skeleton.canonical(), filter_lag=bad)


def test_the_readme_lag_table_is_what_the_measured_curve_renders_to():
    """The README's lag rows (each figure with its clip-bootstrap interval) come from
    docs/lag_curve.json as `scripts/lag_curve.py --render` prints it, measuring nothing."""
    import re
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    rendered = subprocess.run(
        [
            sys.executable,
            str(root / "scripts" / "lag_curve.py"),
            "--render",
            "--output",
            str(root / "docs/lag_curve.json"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout
    readme = (root / "docs" / "results.md").read_text()  # the lag table the README links
    rows = {
        "ik, six-point": "ik/six_point",
        "dtp, six-point": "dtp/six_point",
        "lobstr, four-point": "lobstr/four_point",
    }
    for shown, name in rows.items():
        cells = re.search(rf"^\| {shown} \| (.*) \|$", readme, re.M).group(1).split(" | ")
        measured = re.search(rf"^\| {name} \| vr \| [^|]* \| (.*) \|$", rendered, re.M).group(1)
        assert [c.replace(" (bar met)", "") for c in measured.split(" | ")] == cells, shown
        assert all("[" in c for c in cells)  # each with its interval
