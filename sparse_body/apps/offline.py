"""Offline processing without ROS: motion -> tracker bag, and tracker bag -> estimate bag."""

from __future__ import annotations

from pathlib import Path

from ..core.sensors import SensorConfig
from ..core.skeleton import Skeleton
from ..core.types import BodyPose
from ..data.motion import Motion
from ..data.virtual_trackers import NO_NOISE, TrackerNoise, synthesize_trackers
from ..estimators import create_estimator
from ..io.bagio import ESTIMATE_TOPICS, check_output, read_tracker_stream, write_estimate_bag, write_tracker_bag
from ..io.tf_guards import TfGuards


def make_bag(
    motion: Motion,
    sensors: SensorConfig,
    out: Path,
    noise: TrackerNoise = NO_NOISE,
    seed: int = 0,
    start: float = 1_700_000_000.0,
    overwrite: bool = False,
    inputs: tuple[Path, ...] = (),
) -> int:
    """Write the virtual trackers of a motion as a rosbag2 (MCAP) of /tf; returns the frame count.
    `inputs`: the files the motion came from, which the output may not replace."""
    check_output(out, overwrite, inputs)  # before the work, not after it
    stream = synthesize_trackers(motion, sensors, noise, seed)
    write_tracker_bag(out, stream, sensors, start, overwrite, inputs)
    return len(stream)


def process_bag(
    bag_in: Path,
    bag_out: Path,
    estimator: str,
    sensors: SensorConfig,
    skeleton: Skeleton,
    fps: float = 60.0,
    stale_after: float = 0.1,
    progress: bool = True,
    overwrite: bool = False,
    refused: dict | None = None,
    guards: TfGuards | None = None,
    topics: tuple[str, ...] = ESTIMATE_TOPICS,
    compression: str = "zstd",
    axis_links: bool = False,
    timings: dict | None = None,
    **options,
) -> list[BodyPose]:
    """Run an estimator over a tracker bag and write one estimate per input frame (refused
    tracker samples are counted in `refused`, reason -> count, when a dict is given; the
    seconds spent reading, estimating and writing in `timings`, likewise)."""
    import time

    check_output(bag_out, overwrite, (Path(bag_in),))  # before the estimation, not after it
    clock = time.perf_counter()
    stream = read_tracker_stream(bag_in, sensors, stale_after, refused, guards)
    read = time.perf_counter()
    never = [site for s, site in enumerate(sensors.site_names) if not stream.valid[:, s].any()]
    if never:
        import warnings

        warnings.warn(
            f"{bag_in}: the configured tracker(s) {', '.join(never)} of {sensors.name!r} never appear "
            f"with a usable pose (wrong --sensors?)",
            stacklevel=2,
        )
    est = create_estimator(estimator, sensors, skeleton, fps=fps, **options)
    frames = iter(stream)
    if progress:
        from tqdm import tqdm

        frames = tqdm(frames, total=len(stream), desc=f"{estimator} {Path(bag_in).name}", unit="frame")
    started = time.perf_counter()
    poses = est.process(frames)  # offline: an estimator that can look ahead does here
    estimated = time.perf_counter()
    write_estimate_bag(
        bag_out,
        poses,
        skeleton,
        sensors.fixed_frame,
        overwrite=overwrite,
        inputs=(Path(bag_in),),
        trackers=(sensors, stream),
        made_with=settings_record(estimator, options, sensors, skeleton, fps, topics, axis_links),
        topics=topics,
        compression=compression,
        axis_links=axis_links,
    )
    if timings is not None:
        timings.update(
            read=read - clock, start=started - read, estimate=estimated - started, write=time.perf_counter() - estimated
        )
    return poses


def settings_record(
    estimator: str,
    options: dict,
    sensors: SensorConfig,
    skeleton: Skeleton,
    fps: float,
    topics: tuple[str, ...] = ESTIMATE_TOPICS,
    axis_links: bool = False,
) -> str:
    """What an estimate bag was made with, as one JSON line (kept in the bag's metadata): two
    bags are comparable only when it is the same."""
    import hashlib
    import json

    import numpy as np

    body = hashlib.sha256(np.asarray(skeleton.offsets, np.float64).tobytes()).hexdigest()[:12]
    record = {"estimator": estimator, "options": options, "sensors": sensors.name, "fps": fps, "body": body}
    if tuple(topics) != ESTIMATE_TOPICS:  # (a bag of every topic is recorded as before topics could be chosen)
        record["topics"] = list(topics)
    if axis_links:
        record["axis_links"] = True
    return json.dumps(record, sort_keys=True, default=str)
