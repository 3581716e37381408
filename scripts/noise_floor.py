"""How much velocity error and jitter does LoBSTr's tracker noise (1 cm per axis, every frame)
leave on the tracked points themselves, whatever an estimator then does with them?

The clip's virtual trackers, clean and noisy, go through the live filter (causal) and the
offline smoother (both sides) at a range of acceleration settings; the figures are the
tracker positions' velocity error (cm/s, as MPJVE) and jitter against the clean trackers.
A joint an estimator puts on a tracker inherits at least the best of these.

Usage: .venv/bin/python scripts/noise_floor.py [--split test] [--sensors six_point]
"""

import argparse

import numpy as np

from sparse_body.core.metrics import jitter, mpjve
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.tracker_filter import FilterConfig, TrackerFilter
from sparse_body.core.tracker_smoother import smooth_frames
from sparse_body.data.catalog import find_mocap_root, load_clip, split_clips
from sparse_body.data.virtual_trackers import LOBSTR_NOISE, NO_NOISE, synthesize_trackers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--split", default="test")
    parser.add_argument("--sensors", default="six_point")
    args = parser.parse_args()
    sensors = load_sensor_config(args.sensors)
    clips = []
    for clip in split_clips(find_mocap_root(), args.split):
        motion = load_clip(clip)
        clean = synthesize_trackers(motion, sensors, NO_NOISE)
        clips.append((clean.positions, list(synthesize_trackers(motion, sensors, LOBSTR_NOISE, seed=1)), motion.fps))

    def figures(run) -> tuple[float, float, list[float]]:
        """Velocity error and jitter over all trackers, and the velocity error of each."""
        rows, per_site = [], []
        for truth, noisy, fps in clips:
            est = np.array([f.positions for f in run(noisy)])
            rows.append((len(truth), mpjve(est, truth, fps), jitter(est, fps)))
            per_site.append([mpjve(est[:, [s]], truth[:, [s]], fps) for s in range(est.shape[1])])
        n, v, j = np.array(rows).T
        return float(np.average(v, weights=n)), float(np.average(j, weights=n)), np.average(per_site, axis=0, weights=n)

    print(f"{args.sensors} tracker positions, {args.split} split ({len(clips)} clips), LoBSTr noise")
    clean = np.average([jitter(t, f) for t, _, f in clips], weights=[len(t) for t, _, _ in clips])
    print(f"clean trackers: jitter {clean:.1f}")
    velocity, shake, _ = figures(lambda frames: frames)
    print(f"raw noisy: velocity error {velocity:.1f} cm/s, jitter {shake:.1f}")
    for a in (0.1, 0.2, 0.35, 0.5, 1.0):
        config = FilterConfig(position_noise=0.01, rotation_noise=0.0, acceleration=a)

        def live(frames, config=config):
            each = TrackerFilter(config, sensors.site_names)
            return [each(f) for f in frames]

        velocity, shake, per_site = figures(live)
        print(f"live filter, acceleration {a:.2f}: velocity error {velocity:.1f} cm/s, jitter {shake:.1f}")
        print(
            "  per site: " + ", ".join(f"{name} {v:.1f}" for name, v in zip(sensors.site_names, per_site, strict=True))
        )
    for a in (0.3, 0.5, 0.7, 1.0, 1.5, 3.0):
        config = FilterConfig(position_noise=0.01, rotation_noise=0.0, smooth_acceleration=a)
        velocity, shake, _ = figures(lambda frames, config=config: smooth_frames(frames, config))
        print(f"offline smoother, acceleration {a:.2f}: velocity error {velocity:.1f} cm/s, jitter {shake:.1f}")


if __name__ == "__main__":
    main()
