"""Offline processing without ROS: motion -> tracker bag, and tracker bag -> estimate bag."""

from __future__ import annotations

from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.sensors import SensorConfig
from ..core.skeleton import Skeleton
from ..core.types import BodyPose, BodyPoses, TrackerStream
from ..data.motion import Motion
from ..data.virtual_trackers import NO_NOISE, TrackerNoise, synthesize_trackers
from ..io.bagio import (
    ESTIMATE_TOPICS,
    bag_folder,
    check_compression,
    check_output,
    interrupts_held,
    tracker_frame_count,
    write_tracker_bag,
)
from ..io.estimate_bag import check_topics
from ..io.tf_guards import TfGuards
from ..methods.factory import create_estimator
from ..methods.kernels import compile_kernels
from .pipeline import ForkedReader, ForkedWriter, Reader, Writer, can_fork


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


@dataclass
class Processed:
    """What process_bag made: how many estimates, how many of them invalid, and with
    keep_poses the poses themselves (else None: a long recording's would fill memory)."""

    frames: int = 0
    invalid: int = 0
    poses: list[BodyPose] | None = None
    never_usable: tuple[str, ...] = ()  # configured trackers that never had a usable pose


DETECT_SECONDS = 10.0  # the start of a bag read to find which trackers it holds


def sensors_for_bag(bag: Path, given: str | None) -> tuple[SensorConfig, str]:
    """The sensor configuration to read a tracker bag with, and a line saying how it was
    chosen. given None: the shipped configuration with the most trackers whose every frame
    moves on the bag's /tf in its first DETECT_SECONDS. given: that configuration, refused
    (BagError, one line) when one of its trackers never moves in the bag."""
    from ..core.resources import config_dir
    from ..core.sensors import load_sensor_config
    from ..io.bagio import BagError, tf_frames

    if given is not None:
        sensors = load_sensor_config(given)
        check_bag_trackers(bag, sensors)
        return sensors, f"trackers: {sensors.name} (as given)"
    found = tf_frames(bag, seconds=DETECT_SECONDS)
    shipped = [load_sensor_config(p.stem) for p in sorted((config_dir() / "sensors").glob("*.yaml"))]
    fitting = [c for c in shipped if {site.frame_id for site in c.sites} <= found]
    if not fitting:
        raise BagError(
            f"{bag}: no shipped sensor configuration's trackers are all on its /tf (its first "
            f"{DETECT_SECONDS:g} s hold {', '.join(sorted(found)) or 'no frames'}); give --sensors (a YAML for yours)"
        )
    chosen = max(fitting, key=lambda c: len(c.sites))  # (first of a tie: by name)
    frames = ", ".join(site.frame_id for site in chosen.sites)
    return chosen, f"trackers found in the bag: {frames}: reading it as {chosen.name} (--sensors to choose)"


def check_bag_trackers(bag: Path, sensors: SensorConfig) -> None:
    """BagError (one line) when a tracker of the configuration never moves on the bag's /tf
    (read until each has: a wrong configuration once gave straight, still legs and exit 0)."""
    from ..io.bagio import BagError, tf_frames

    wanted = {site.frame_id for site in sensors.sites}
    found = tf_frames(bag, wanted)
    missing = sorted(wanted - found)
    if missing:
        raise BagError(
            f"{bag}: {sensors.name}'s tracker frames {', '.join(missing)} never appear on its /tf "
            f"(it holds {', '.join(sorted(found)) or 'none'}); leave --sensors out to choose from them"
        )


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
    keep_poses: bool = False,
    parallel: bool | None = None,
    robot: tuple[str, str] | None = None,
    **options,
) -> Processed:
    """Run an estimator over a tracker bag and write one estimate per input frame, a chunk of
    frames at a time (apps/pipeline.py): with `parallel` (None: wherever this process may
    fork) the reading and the writing run in child processes beside the estimation. Refused
    tracker samples are counted in `refused` (reason -> count) when a dict is given; the
    seconds spent reading, estimating and writing (each in its own process when parallel) and
    the whole run's go into `timings`, likewise. `robot` (a mapping YAML and its URDF, empty:
    the mapping's) adds the humanoid robot's joints (/robot/joint_states, robot/ on /tf)."""
    import time
    from collections import deque

    clock = time.perf_counter()
    check_topics(topics)
    check_compression(compression)
    parallel = can_fork() if parallel is None else parallel
    made_with = settings_record(estimator, options, sensors, skeleton, fps, topics, axis_links, robot)
    bag = dict(
        skeleton=skeleton,
        fixed_frame=sensors.fixed_frame,
        sensors=sensors,
        topics=topics,
        axis_links=axis_links,
        robot=robot,
    )
    if robot is not None:  # its files are checked before any work (the writer reads them again)
        from ..robot.retarget import load_retarget

        load_retarget(robot[0], robot[1], skeleton)
    done = Processed(poses=[] if keep_poses else None)
    seen = np.zeros(len(sensors.sites), bool)  # each tracker: ever usable?
    with ExitStack() as stack:  # left in reverse: the children end before the folder goes
        tmp = stack.enter_context(bag_folder(bag_out, overwrite, (Path(bag_in),)))  # checked before any work
        reader: Reader | ForkedReader
        writer: Writer | ForkedWriter
        if parallel:  # forked before the estimator starts threads (ONNX Runtime's)
            # A child made but not yet in the stack would outlive a Ctrl-C (it ignores signals)
            # and hold the exit forever: the two are one step (a Ctrl-C 1.5 s in did it).
            # The threads that feed the pipes start once both children are forked, in the same
            # step: a stop landing inside Thread.start left a started thread that Python had
            # already written off (a traceback on stderr, CI beside burners); started with the
            # signals held, they keep them held, so a signal always finds the main thread.
            with interrupts_held():
                reader = stack.enter_context(ForkedReader(bag_in, sensors, stale_after, guards))
                writer = stack.enter_context(ForkedWriter(tmp, made_with, compression, (reader.conn,), **bag))
                reader.start()
                writer.start()
        else:
            reader = stack.enter_context(Reader(bag_in, sensors, stale_after, guards))
            writer = stack.enter_context(Writer(tmp, made_with, compression, **bag))
        started = time.perf_counter()
        est = create_estimator(estimator, sensors, skeleton, fps=fps, **options)
        # numba loads (or compiles) the per-frame kernels here, with Ctrl-C held until they are
        # in: one landing inside numba's LLVM callback was swallowed there ("Exception ignored"),
        # and the run went on to the end (1 in 32 beside 4 burners)
        with interrupts_held():
            compile_kernels(say=print if progress else None)
        ready = time.perf_counter()
        pending: deque[TrackerStream] = deque()  # read chunks whose poses are not all made

        def frames():
            for chunk in reader:
                pending.append(chunk)
                seen[:] |= chunk.valid.any(axis=0)
                yield from chunk

        stream = frames()
        if progress:
            from tqdm import tqdm

            total = tracker_frame_count(bag_in)
            stream = tqdm(stream, total=total, desc=f"{estimator} {Path(bag_in).name}", unit="frame")
        made: list[BodyPose] = []
        waiting = 0.0  # seconds the loop waited for chunks (the reader's time, not the estimator's)
        for pose in est.stream(stream):  # offline: an estimator that can look ahead does here
            made.append(pose)
            if len(made) == len(pending[0]):
                waited = time.perf_counter()
                writer.write(BodyPoses.of(made), pending.popleft())
                waiting += time.perf_counter() - waited
                done.frames += len(made)
                done.invalid += sum(not p.valid for p in made)
                if done.poses is not None:
                    done.poses += made
                made = []
        estimated = time.perf_counter()
        writer.finish()
        if not parallel:
            waiting += reader.busy  # the reading happened inside the loop
    if refused is not None:
        for reason, count in reader.refused.items():
            refused[reason] = refused.get(reason, 0) + count
    done.never_usable = tuple(site for s, site in enumerate(sensors.site_names) if not seen[s])
    if timings is not None:
        timings.update(
            read=reader.busy,
            start=ready - started,
            estimate=max(0.0, estimated - ready - waiting),
            write=writer.busy,
            wall=time.perf_counter() - clock,
            parallel=float(parallel),
        )
    return done


def settings_record(
    estimator: str,
    options: dict,
    sensors: SensorConfig,
    skeleton: Skeleton,
    fps: float,
    topics: tuple[str, ...] = ESTIMATE_TOPICS,
    axis_links: bool = False,
    robot: tuple[str, str] | None = None,
) -> str:
    """What an estimate bag was made with, as one JSON line (kept in the bag's metadata): two
    bags are comparable only when it is the same."""
    import hashlib
    import json

    body = hashlib.sha256(np.asarray(skeleton.offsets, np.float64).tobytes()).hexdigest()[:12]
    record = {"estimator": estimator, "options": options, "sensors": sensors.name, "fps": fps, "body": body}
    if tuple(topics) != ESTIMATE_TOPICS:  # (a bag of every topic is recorded as before topics could be chosen)
        record["topics"] = list(topics)
    if axis_links:
        record["axis_links"] = True
    if robot is not None:  # the robot by its files' contents, not their paths
        texts = [Path(robot[0]).read_bytes()] + ([Path(robot[1]).read_bytes()] if robot[1] else [])
        record["robot"] = hashlib.sha256(b"".join(texts)).hexdigest()[:12]
    return json.dumps(record, sort_keys=True, default=str)
