"""`sparse-body demo`: a motion becomes a tracker bag, goes through an estimator, and comes
out as metrics and an animation of the estimate against the ground truth."""

from __future__ import annotations

from pathlib import Path
from typing import cast

import numpy as np

from ..core.contacts import contact_labels, estimate_floor
from ..core.kinematics import forward_kinematics
from ..core.metrics import sequence_metrics
from ..core.rotations import quat_to_matrix
from ..core.sensors import SensorConfig
from ..core.skeleton import JOINT_INDEX, PARENTS
from ..data.motion import Motion
from .offline import make_bag, process_bag

HEAD = JOINT_INDEX["head"]


def pick_motion(mocap_root: Path | None, motion_file: str | None, seconds: float, fps: float) -> tuple[Motion, str]:
    from ..data.catalog import DEMO_CLIP, load_clip, load_motion_file, read_index
    from ..data.synthetic import synthetic_walk

    if motion_file:
        return load_motion_file(Path(motion_file), fps), f"the motion file {motion_file}"
    if mocap_root is not None:
        clip = {c.clip_id: c for c in read_index(mocap_root)}[DEMO_CLIP]
        motion = load_clip(clip, fps)
        return motion.slice(0, int(seconds * fps)), f"CMU clip {DEMO_CLIP} ({clip.description}) from {mocap_root}"
    return (
        synthetic_walk(seconds, fps),
        "a built-in SYNTHETIC walk (no motion capture found: pass --motion FILE or --mocap DIR for real motion)",
    )


def head_tops(positions: np.ndarray, global_rot: np.ndarray, skull: float) -> np.ndarray:
    """(T, 3) tops of the heads: the 22-joint body ends mid-neck (the head joint), so the
    skull is drawn as a segment of its length up the head's own z axis."""
    return positions[:, HEAD] + global_rot[:, HEAD] @ np.array([0.0, 0.0, skull])


def gif_step(fps: float, most: float = 25.0) -> int:
    """Every how many motion frames a GIF frame is drawn: the fewest that keep the GIF at most
    `most` frames a second with a delay a whole number of centiseconds (all GIF delays are),
    so the animation plays at the motion's real speed; the nearest when none is exact."""
    steps = range(max(1, int(np.ceil(fps / most))), max(2, int(np.ceil(fps / most))) + int(fps) + 1)
    exact = [k for k in steps if abs(100 * k / fps - round(100 * k / fps)) < 1e-9]
    return exact[0] if exact else steps[0]


def animate(
    path: Path,
    truth: np.ndarray,
    estimate: np.ndarray,
    trackers: np.ndarray,
    fps: float,
    title: str,
    tops: tuple[np.ndarray, np.ndarray] | None = None,
    size_px: int = 560,
) -> None:
    """A GIF at the motion's real speed: ground truth in grey, the estimate in blue, trackers
    as red dots where they are mounted (a mounting offset away from their joints), over a
    floor grid, seen by a fixed camera the body moves through, with equal axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.lines import Line2D
    from mpl_toolkits.mplot3d.axes3d import Axes3D
    from PIL import Image

    step = gif_step(fps)
    idx = np.arange(0, len(truth), step)
    floor = float(np.nanmin(truth[..., 2]))
    centres, top = follow_box(truth, floor)
    extent = np.array([2 * FOLLOW_HALF, 2 * FOLLOW_HALF, top - floor])  # metres along x, y, z: the box's shape
    fig = plt.figure(figsize=(size_px / 100, size_px / 100), dpi=100)
    ax = cast(Axes3D, fig.add_axes((0.0, 0.02, 0.98, 0.9), projection="3d"))
    canvas = cast(FigureCanvasAgg, fig.canvas)  # Agg, chosen above
    legend = [
        Line2D([], [], color="0.6", lw=2, label="truth"),
        Line2D([], [], color="tab:blue", lw=2, label="estimate"),
        Line2D([], [], color="tab:red", marker="o", lw=0, label="trackers (as mounted)"),
    ]
    frames = []
    for i in idx:
        ax.cla()
        low = np.array([centres[i, 0] - FOLLOW_HALF, centres[i, 1] - FOLLOW_HALF, floor])
        high = np.array([centres[i, 0] + FOLLOW_HALF, centres[i, 1] + FOLLOW_HALF, top])
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        ax.set_zlim(low[2], high[2])
        # equal axes (a metre is a metre): the box follows the body (a walk's whole path in one
        # box left it 100 px tall in 560), zoomed so that the labels stay inside the picture
        ax.set_box_aspect(tuple(extent), zoom=0.98)
        ax.grid(False)  # the floor grid below is the scale
        for k, setter in enumerate((ax.set_xticks, ax.set_yticks, ax.set_zticks)):
            setter(np.arange(np.ceil(low[k] * 2) / 2, high[k] + 1e-9, 0.5 if k < 2 else 1.0))
        ax.set_xlabel("x [m]", fontsize=8, labelpad=4)
        ax.set_ylabel("y [m]", fontsize=8, labelpad=4)
        ax.set_zlabel("z [m]", fontsize=8, labelpad=2)
        ax.tick_params(labelsize=7, pad=0)
        grid = (np.arange(np.ceil(low[0] * 2) / 2, high[0], 0.5), np.arange(np.ceil(low[1] * 2) / 2, high[1], 0.5))
        for x in grid[0]:  # the floor, 0.5 m squares
            ax.plot([x, x], [low[1], high[1]], [floor, floor], color="0.85", lw=0.6)
        for y in grid[1]:
            ax.plot([low[0], high[0]], [y, y], [floor, floor], color="0.85", lw=0.6)
        for n, (pos, colour) in enumerate(((truth[i], "0.6"), (estimate[i], "tab:blue"))):
            for j in range(1, len(PARENTS)):
                ax.plot(*zip(pos[PARENTS[j]], pos[j], strict=True), color=colour, lw=2)
            if tops is not None:  # the head, a ball between the head joint and the skull's top
                ball = (pos[HEAD] + tops[n][i]) / 2
                ax.scatter(*ball, color=colour, s=110, depthshade=False)
        tr = trackers[i][np.all(np.isfinite(trackers[i]), axis=1)]
        ax.scatter(tr[:, 0], tr[:, 1], tr[:, 2], color="tab:red", s=20)
        ax.legend(handles=legend, loc="upper left", fontsize=7, frameon=False)
        fig.suptitle(f"{title}   t = {i / fps:5.2f} s", fontsize=9, y=0.97)
        canvas.draw()
        frames.append(Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3]).quantize(colors=64))
    plt.close(fig)
    delay_ms = round(1000 * step / fps)  # whole centiseconds (gif_step)
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=delay_ms, loop=0)


FOLLOW_HALF = 1.25  # m: the picture's box reaches this far from the pelvis (2.5 m across)
FOLLOW_SMOOTH = 0.5  # s: the box's centre is the pelvis averaged over this long (it does not shake)


def follow_box(truth: np.ndarray, floor: float) -> tuple[np.ndarray, float]:
    """(each frame's box centre (frames, 2), the box's top): centred on the pelvis, smoothed
    over FOLLOW_SMOOTH at 60 Hz, the top a margin above the highest head."""
    pelvis = np.asarray(truth[:, 0, :2], float)
    width = max(1, int(FOLLOW_SMOOTH * 60) | 1)
    padded = np.pad(pelvis, ((width // 2, width // 2), (0, 0)), mode="edge")
    kernel = np.ones(width) / width
    centres = np.stack([np.convolve(padded[:, k], kernel, mode="valid") for k in (0, 1)], axis=1)
    top = max(float(np.nanmax(truth[..., 2])) + 0.35, floor + 2.0)
    return centres, top


# Why a metric has no value, when the motion gives it none.
NO_VALUE = {
    "Skate [cm/s]": "no frame of the motion has a foot in contact with the floor",
    "Contact acc [%]": "the estimator reports no contacts",
    "End-effector PE [cm]": "no tracked joint",
    "Jitter [100m/s3]": "the motion is too short",
    "MPJVE [cm/s]": "the motion is too short",
}


def run_demo(
    out_dir: Path,
    sensors: SensorConfig,
    estimator: str,
    mocap_root: Path | None,
    motion_file: str | None = None,
    seconds: float = 6.0,
    fps: float = 60.0,
    gif: bool = True,
) -> dict:
    from ..io.bagio import read_tracker_stream

    motion, source = pick_motion(mocap_root, motion_file, seconds, fps)  # a bad motion file: before the folder
    out_dir.mkdir(parents=True, exist_ok=True)
    print(f"motion: {source}, {len(motion)} frames at {motion.fps:g} Hz")
    trackers, estimates = out_dir / "trackers", out_dir / "estimates"
    # an earlier demo's bags are replaced; anything else there is refused (bagio.check_output)
    make_bag(motion, sensors, trackers, overwrite=True)
    print(f"tracker bag ({sensors.name}): {trackers}")
    poses = process_bag(
        trackers,
        estimates,
        estimator,
        sensors,
        motion.skeleton,
        motion.fps,
        progress=False,
        overwrite=True,
        keep_poses=True,
    ).poses
    assert poses is not None  # keep_poses
    print(f"estimate bag ({estimator}): {estimates}, {len(poses)} estimates")
    local = quat_to_matrix(np.stack([p.local_quats for p in poses]))
    glob, pos = forward_kinematics(local, np.stack([p.root_position for p in poses]), motion.skeleton.offsets)
    floor = estimate_floor(motion.positions)
    metrics = sequence_metrics(
        pos,
        glob,
        local,
        motion.positions,
        motion.global_rotations,
        motion.local_rotations,
        motion.fps,
        floor,
        contact_labels(motion.positions, motion.fps),
        np.stack([p.contact for p in poses]),
        sorted({s.joint_index for s in sensors.sites}),
    )
    for key, value in metrics.items():
        print(
            f"  {key:<24}{value:8.2f}"
            if np.isfinite(value)
            else f"  {key:<24}     n/a  ({NO_VALUE.get(key, 'undefined')})"
        )
    if gif:
        stream = read_tracker_stream(trackers, sensors)
        animation = out_dir / "demo.gif"
        skull = 0.1 * motion.skeleton.height() / 1.75
        tops = (head_tops(motion.positions, motion.global_rotations, skull), head_tops(pos, glob, skull))
        animate(
            animation, motion.positions, pos, stream.positions, motion.fps, f"{estimator} / {sensors.name}", tops=tops
        )
        print(f"animation: {animation}")
        from .viewer import stream_trackers, write_body_page

        page = write_body_page(
            out_dir / "demo.html",
            motion.fps,
            True,  # an earlier demo's page is replaced; any other file there is refused
            estimate=pos,
            truth=motion.positions,
            trackers=stream_trackers(stream, sensors),
            title=f"{estimator} / {sensors.name}",
            floor=floor,
        )
        print(f"interactive: {page} (open it in a browser: turn, zoom, play, scrub)")
    return metrics
