"""Compiling the per-frame kernels (numba) before the first frame needs them.

numba compiles a kernel on its first call and caches the machine code beside its source
(`__pycache__`, or NUMBA_CACHE_DIR); a later process loads it in milliseconds. Every install
path runs `compile_kernels` once, so that no node spends its first start compiling: the
setup script, and the CMake install that colcon runs (CMakeLists.txt). The estimator node
runs it again at configure, which then only loads.

It lives with the methods, because warming a kernel means running the estimator
that calls it: the body IK (every method's polish) through `ik`, DragPoser's search
through `dragposer` (skipped where its models are missing).
"""

from __future__ import annotations

import numpy as np

# estimators whose steps reach every compiled kernel between them
WARM_ESTIMATORS = ("ik", "dragposer")


def kernels_cached() -> bool:
    """Whether numba's disk cache holds this package's kernels (its index files, beside the
    sources or under NUMBA_CACHE_DIR): if not, the next start compiles them."""
    import os
    from pathlib import Path

    package = Path(__file__).resolve().parents[1]
    folders = [package]
    if os.environ.get("NUMBA_CACHE_DIR"):
        folders.append(Path(os.environ["NUMBA_CACHE_DIR"]))
    return any(next(folder.rglob("*.nbi"), None) is not None for folder in folders)


def compile_kernels(estimators: tuple[str, ...] = WARM_ESTIMATORS, say=None) -> None:
    """Compile (or load from the disk cache) every kernel of the per-frame path by running
    each of `estimators` for a few frames of a standing body. say(line): told, in one line
    each, when the kernels are not cached yet (a first start compiles for about a minute on
    two cores, with nothing else to show for it) and how long it took."""
    import time

    cold = say is not None and not kernels_cached()
    if cold:
        say("compiling the per-frame kernels once (about a minute on 2 cores; later starts load them)")
    start = time.perf_counter()
    _warm(estimators)
    if cold:
        say(f"compiled the per-frame kernels in {time.perf_counter() - start:.0f} s")


def _warm(estimators: tuple[str, ...]) -> None:
    from ..core.body_ik import LIMBS, reach
    from ..core.kinematics import LEG_JOINTS, forward_kinematics
    from ..core.rotations import sixd_to_matrix, yaw_matrix_of
    from ..core.sensors import load_sensor_config
    from ..core.skeleton import Skeleton, standing_pose
    from ..core.types import TrackerFrame
    from ..estimators.onnx_model import ModelMissing
    from .factory import create_estimator

    skeleton = Skeleton.canonical()
    local, root = standing_pose(), np.array([0.0, 0.0, 0.9])
    glob, pos = forward_kinematics(local, root, skeleton.offsets)
    forward_kinematics(local, root, skeleton.offsets, joints=LEG_JOINTS)
    sensors = load_sensor_config("six_point")
    sites = sensors.site_names
    for name in estimators:
        try:  # the filter, the joint targets, solve_body, quaternions; the method's own kernels
            estimator = create_estimator(name, sensors, skeleton)
        except ModelMissing:
            continue  # no models, no method to start: nothing of it to compile
        for t in range(3):
            ends = np.array([pos[s.joint_index] for s in sensors.sites])
            quats = np.tile([0.0, 0.0, 0.0, 1.0], (len(sites), 1))
            estimator.step(TrackerFrame(t / 60, sites, ends, quats, np.ones(len(sites), dtype=bool)))
    limb = next(iter(LIMBS.values()))
    for exact in (False, True):
        reach(local.copy(), glob[0], pos[limb.upper], skeleton.offsets, limb, pos[limb.end], None, exact)
    sixd_to_matrix(np.tile([1.0, 0.0, 0.0, 0.0, 1.0, 0.0], (4, 1)))
    yaw_matrix_of(np.eye(3))
