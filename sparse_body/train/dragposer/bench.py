"""`sparse-body bench --runtime dragposer` (the record's runtime_bench): the search, ONNX Runtime
Gauss-Newton against the torch autograd reference."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ...core.sensors import load_sensor_config
from ...data.synthetic import synthetic_walk
from ...data.virtual_trackers import synthesize_trackers


def percentiles(times) -> str:
    ms = np.asarray(times) * 1000
    return f"p50 {np.percentile(ms, 50):6.3f} ms   p99 {np.percentile(ms, 99):6.3f} ms"


def bench_dragposer(
    frames: int = 600,
    max_iterations: int = 20,
    tolerance: float = 0.01,
    rotation_tolerance: float = 0.087,
    torch_frames: int = 10,
) -> None:
    """DragPoser's pose optimiser, six-point, on the demo's CMU test clip (the synthetic walk
    where no motion capture is indexed: `sparse-body import-mocap`): milliseconds per frame and
    iterations until the trackers are met (1 cm, 5 degrees), for the ONNX Runtime Gauss-Newton
    runtime and the torch autograd reference
    (Adam, the paper's kind of step), both starting each frame from the runtime's previous
    solution."""
    import torch

    from ...data.catalog import DEMO_CLIP, find_mocap_root, load_clip, read_index
    from ...methods.dragposer.estimator import END_JOINTS, DragPoserEstimator
    from .torch_reference import load_vae, optimise

    torch.set_num_threads(1)
    root = find_mocap_root()
    if root is not None:
        motion, where = load_clip({c.clip_id: c for c in read_index(root)}[DEMO_CLIP]).slice(0, frames), DEMO_CLIP
    else:
        motion, where = synthetic_walk(frames / 60.0), "synthetic walk"
    config = load_sensor_config("six_point")
    stream = synthesize_trackers(motion, config)
    # the search alone, as the reference does it: no temporal prior, no IK polish
    est = DragPoserEstimator(
        config,
        motion.skeleton,
        iterations=max_iterations,
        tolerance=tolerance,
        rotation_tolerance=rotation_tolerance,
        temporal_weight=0.0,
        polish=False,
    )
    times, states = [], []
    for frame in stream:
        states.append(est._state)
        t0 = time.perf_counter()
        est.step(frame)
        times.append(time.perf_counter() - t0)
    its = np.array(est.iterations_used[1:])
    print(
        f"DragPoser optimiser, six-point, {where}, {len(stream)} frames, trackers met within "
        f"{tolerance * 100:g} cm / {np.degrees(rotation_tolerance):.0f} deg, 1 thread"
    )
    print(
        f"  onnxruntime Gauss-Newton: {percentiles(times[1:])} per frame; iterations to converge: mean "
        f"{its.mean():.2f}, p99 {np.percentile(its, 99):.0f} (cap {max_iterations}); "
        f"{1000 * np.mean(times[1:]) / its.mean():.2f} ms per iteration"
    )
    vae = load_vae(est.vae.dir)
    picks = np.linspace(10, len(stream) - 1, torch_frames).astype(int)
    t_iters, t_ms = [], []
    for i in picks:
        z, root, yaw = states[i]
        frame = stream.frame(i)
        constraints = est.tracker_constraints(frame)
        for c in est.constraints:
            constraints.add(c)
        stats: dict[str, float] = {}
        t0 = time.perf_counter()
        optimise(
            vae,
            constraints,
            motion.skeleton.offsets,
            z,
            root,
            yaw,
            z,
            iterations=2000,
            lr=0.01,
            tolerance=tolerance,
            rotation_tolerance=rotation_tolerance,
            stats=stats,
            skip_orientation=END_JOINTS,
        )
        t_ms.append((time.perf_counter() - t0) * 1000)
        t_iters.append(stats["iterations"])
    print(
        f"  torch autograd (Adam):    {np.mean(t_ms):8.1f} ms per frame over {torch_frames} frames; iterations to "
        f"converge: mean {np.mean(t_iters):.1f} (cap 2000); {np.sum(t_ms) / np.sum(t_iters):.2f} ms per iteration"
    )
    runs: list[tuple[str, dict[str, Any]]] = [
        ("live defaults", {}),
        ("without the temporal predictor", {"temporal_weight": 0.0}),
        ("without the IK polish", {"polish": False}),
    ]
    for label, options in runs:
        live = DragPoserEstimator(config, motion.skeleton, **options)
        times = []
        for frame in stream:
            t0 = time.perf_counter()
            live.step(frame)
            times.append(time.perf_counter() - t0)
        print(f"  estimator step, {label} ({live.iterations} iterations): {percentiles(times[1:])} per frame")
