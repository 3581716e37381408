"""`sparse-body demo`: a motion becomes a tracker bag, goes through an estimator, and comes
out as metrics and an animation of the estimate against the ground truth."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .core.contacts import contact_labels, estimate_floor
from .core.kinematics import forward_kinematics
from .core.metrics import sequence_metrics
from .core.rotations import quat_to_matrix
from .core.sensors import SensorConfig
from .core.skeleton import JOINT_INDEX, PARENTS
from .data.motion import Motion
from .offline import make_bag, process_bag

HEAD = JOINT_INDEX["head"]

DEMO_CLIP = "17_10"   # boxing, from the test split: a person no model trained on


def pick_motion(mocap_root: Path | None, motion_file: str | None, seconds: float, fps: float) -> tuple[Motion, str]:
    from .data.catalog import load_clip, load_motion_file, read_index
    from .data.synthetic import synthetic_walk
    if motion_file:
        return load_motion_file(Path(motion_file), fps), f"the motion file {motion_file}"
    if mocap_root is not None:
        clip = {c.clip_id: c for c in read_index(mocap_root)}[DEMO_CLIP]
        motion = load_clip(clip, fps)
        return motion.slice(0, int(seconds * fps)), f"CMU clip {DEMO_CLIP} ({clip.description}) from {mocap_root}"
    return (synthetic_walk(seconds, fps),
            "a built-in SYNTHETIC walk (no motion capture found: pass --motion FILE or --mocap DIR for real motion)")


def head_tops(positions: np.ndarray, global_rot: np.ndarray, skull: float) -> np.ndarray:
    """(T, 3) tops of the heads: the 22-joint body ends mid-neck (the head joint), so the
    skull is drawn as a segment of its length up the head's own z axis."""
    return positions[:, HEAD] + global_rot[:, HEAD] @ np.array([0.0, 0.0, skull])


def animate(path: Path, truth: np.ndarray, estimate: np.ndarray, trackers: np.ndarray, fps: float,
            title: str, out_fps: float = 15.0, tops: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """A GIF following the body: ground truth in grey, the estimate in blue, trackers as red
    dots where they are mounted (a mounting offset away from their joints)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    step = max(1, int(round(fps / out_fps)))
    idx = np.arange(0, len(truth), step)
    fig = plt.figure(figsize=(5, 5))
    ax = fig.add_subplot(projection="3d")
    # the view follows the pelvis and is just larger than the body, which then fills it
    half = 0.55 * (truth[..., 2].max() - truth[..., 2].min()) + 0.1
    floor = truth[..., 2].min()

    def draw(k):
        i = idx[k]
        ax.cla()
        centre = truth[i, 0]
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(floor, floor + 2 * half)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
        ax.set_title(f"{title}\nframe {i}: grey truth, blue estimate,\nred trackers as mounted (offset from their joints)",
                     fontsize=8)
        for n, (pos, colour) in enumerate(((truth[i], "0.6"), (estimate[i], "tab:blue"))):
            for j in range(1, len(PARENTS)):
                p = PARENTS[j]
                ax.plot(*zip(pos[p], pos[j]), color=colour, lw=2)
            if tops is not None:
                ax.plot(*zip(pos[HEAD], tops[n][i]), color=colour, lw=5)
        tr = trackers[i][np.all(np.isfinite(trackers[i]), axis=1)]
        ax.scatter(tr[:, 0], tr[:, 1], tr[:, 2], color="tab:red", s=20)

    anim = FuncAnimation(fig, draw, frames=len(idx))
    anim.save(path, writer=PillowWriter(fps=out_fps))
    plt.close(fig)


def run_demo(out_dir: Path, sensors: SensorConfig, estimator: str, mocap_root: Path | None,
             motion_file: str | None = None, seconds: float = 6.0, fps: float = 60.0, gif: bool = True) -> dict:
    from .bagio import read_tracker_stream
    out_dir.mkdir(parents=True, exist_ok=True)
    motion, source = pick_motion(mocap_root, motion_file, seconds, fps)
    print(f"motion: {source}, {len(motion)} frames at {motion.fps:g} Hz")
    trackers, estimates = out_dir / "trackers", out_dir / "estimates"
    for bag in (trackers, estimates):
        if bag.exists():
            import shutil
            shutil.rmtree(bag)
    make_bag(motion, sensors, trackers)
    print(f"tracker bag ({sensors.name}): {trackers}")
    poses = process_bag(trackers, estimates, estimator, sensors, motion.skeleton, motion.fps, progress=False)
    print(f"estimate bag ({estimator}): {estimates}, {len(poses)} estimates")
    local = quat_to_matrix(np.stack([p.local_quats for p in poses]))
    glob, pos = forward_kinematics(local, np.stack([p.root_position for p in poses]), motion.skeleton.offsets)
    floor = estimate_floor(motion.positions)
    metrics = sequence_metrics(pos, glob, local, motion.positions, motion.global_rotations, motion.local_rotations,
                               motion.fps, floor, contact_labels(motion.positions, motion.fps, floor),
                               np.stack([p.contact for p in poses]), sorted({s.joint_index for s in sensors.sites}))
    for key, value in metrics.items():
        print(f"  {key:<24}{value:8.2f}")
    if gif:
        stream = read_tracker_stream(trackers, sensors)
        animation = out_dir / "demo.gif"
        skull = 0.1 * motion.skeleton.height() / 1.75
        tops = (head_tops(motion.positions, motion.global_rotations, skull), head_tops(pos, glob, skull))
        animate(animation, motion.positions, pos, stream.positions, motion.fps, f"{estimator} / {sensors.name}",
                tops=tops)
        print(f"animation: {animation}")
    return metrics
