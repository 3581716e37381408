"""`sparse-body view`: a self-contained HTML page that plays a body in 3D: an estimate bag
(what `process` wrote), a motion file or clip (the truth), or both from `demo`.

plotly draws it: its offline HTML carries plotly.js inside the page (no network to open it),
its 3D scenes orbit and zoom with the mouse, and its animation frames, play button and
slider give play, pause and scrub with nothing written by hand but a few lines of script
(`#play` in the address starts it playing, which the browser test uses). three.js would draw
faster but needs a JavaScript build; matplotlib's GIF (demo) cannot be turned or scrubbed.

The page: the estimate in blue (joints coloured by their error in cm where the truth is
known), the truth in grey, trackers in red, a floor grid, the camera fixed on the whole
motion so the body walks through it, at the recording's real speed (at most 30 frames a
second drawn: every second frame of a 60 Hz recording, each shown twice as long)."""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from itertools import chain
from pathlib import Path

import numpy as np

from ..core.sensors import SensorConfig
from ..core.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS
from ..core.types import TrackerStream
from ..io.cdr import TfRow
from ..io.topics import ROBOT_PREFIX

MAX_FPS = 30.0  # frames drawn a second: WebGL redraws 3D scenes whole
MAX_FRAMES = 9000  # five minutes at 30 frames a second; longer recordings are drawn sparser
FOLLOW_HALF_WIDTH = 0.75  # of the body's height: the followed box reaches this far from the pelvis
FOLLOW_HEIGHT = 1.3  # of the body's height: the box's top above the floor (1.1 left the head at the edge)
ERROR_RANGE_CM = 20.0  # the colour scale's top: an error this large is fully red
BONES = [(PARENTS[j], j) for j in range(1, NUM_JOINTS)]


class ViewError(ValueError):
    """Nothing to show: the input holds no body, or no frames."""


def _lines(positions: np.ndarray) -> np.ndarray:
    """(frames, 3 * bones, 3): each bone's two ends and a gap (NaN), as one plotly line trace."""
    ends = np.full((len(positions), len(BONES), 3, 3), np.nan)
    ends[:, :, 0] = positions[:, [p for p, _ in BONES]]
    ends[:, :, 1] = positions[:, [c for _, c in BONES]]
    return ends.reshape(len(positions), -1, 3)


def _filled(xy: np.ndarray) -> np.ndarray:
    """(frames, 2) with each non-finite row replaced by the nearest finite one before it (or
    after it, at the start): where the camera stays while a body is missing."""
    xy = np.array(xy, dtype=float)
    good = np.all(np.isfinite(xy), axis=1)
    if not good.any():
        return np.zeros_like(xy)
    index = np.where(good, np.arange(len(xy)), 0)
    np.maximum.accumulate(index, out=index)
    index[: np.argmax(good)] = np.argmax(good)
    return xy[index]


def _nested(flat: dict) -> dict:
    """{"scene.xaxis.range": v} -> {"scene": {"xaxis": {"range": v}}}: a frame's layout."""
    out: dict = {}
    for key, value in flat.items():
        *parents, last = key.split(".")
        node = out
        for part in parents:
            node = node.setdefault(part, {})
        node[last] = value
    return out


def _round(a: np.ndarray) -> list:
    """Millimetres are enough on screen, and keep the page small; NaN becomes null (a gap)."""
    out = np.round(a, 3).astype(object)
    out[~np.isfinite(a)] = None
    return out.tolist()


def body_page(fps: float, **parts) -> str:
    """The page's HTML whole (body_page_parts' parts joined)."""
    head, frames, tail = body_page_parts(fps, **parts)
    return head + "".join(frames) + tail


def body_page_parts(
    fps: float,
    estimate: np.ndarray | None = None,
    truth: np.ndarray | None = None,
    trackers: np.ndarray | None = None,
    title: str = "sparse_body",
    floor: float | None = None,
    robot: np.ndarray | None = None,
    robot_bones: tuple[tuple[int, int], ...] = (),
    stands_for: int = 1,
) -> tuple[str, Iterator[str], str]:
    """The page's HTML in three parts: what comes before its animation frames, the frames'
    JSON one part a frame (made as they are taken), and the rest. estimate, truth: (frames,
    22, 3) joint positions; trackers: (frames, k, 3), NaN where a tracker has no sample;
    robot: (frames, links, 3) a robot's link origins
    (robot_bones: the (parent, child) links drawn joined); all in metres, z up. stands_for: how
    many frames of the recording each given frame stands for (a reader that decimated
    already, as bag_bodies does), said in the title."""
    import plotly.io as pio

    shown = [a for a in (estimate, truth) if a is not None]
    if not shown or not len(shown[0]):
        raise ViewError("nothing to show: no body in the input")
    frames = len(shown[0])
    if not fps > 0:
        raise ViewError(f"a frame rate must be positive, got {fps}")
    step = max(int(np.ceil(fps / MAX_FPS - 1e-6)), int(np.ceil(frames / MAX_FRAMES)))
    picks = range(0, frames, step)
    extra = [a for a in (trackers, robot) if a is not None]
    every = np.concatenate([a.reshape(-1, 3) for a in shown + extra])
    every = every[np.all(np.isfinite(every), axis=1)]
    if not len(every):
        raise ViewError("nothing to show: every position is missing or not finite")
    low, high = every.min(0), every.max(0)
    floor = float(low[2]) if floor is None else floor
    error = None
    if estimate is not None and truth is not None:
        error = 100 * np.linalg.norm(estimate - truth, axis=-1)

    def points(xyz: np.ndarray, **style) -> dict:
        # a plain trace, as plotly would serialise it: thousands of frames of plotly's objects
        # once held 475 MB for a 28 MB page (a 5-minute bag)
        return {"type": "scatter3d", "x": _round(xyz[:, 0]), "y": _round(xyz[:, 1]), "z": _round(xyz[:, 2]), **style}

    def traces(i: int) -> list:
        out = []
        if truth is not None:
            out.append(
                points(_lines(truth[i : i + 1])[0], mode="lines", line={"color": "#999999", "width": 6}, name="truth")
            )
        if estimate is not None:
            out.append(
                points(
                    _lines(estimate[i : i + 1])[0], mode="lines", line={"color": "#1f5fbf", "width": 6}, name="estimate"
                )
            )
            marker = {"size": 4, "color": "#1f5fbf"}
            if error is not None:
                marker = {
                    "size": 5,
                    "color": _round(error[i]),
                    "cmin": 0.0,
                    "cmax": ERROR_RANGE_CM,
                    "colorscale": [[0, "#1f5fbf"], [0.25, "#2ca02c"], [0.6, "#ff9f1c"], [1, "#d62728"]],
                    "colorbar": {"title": {"text": "error cm"}, "len": 0.5},
                }
            name = "joints" + (" (error)" if error is not None else "")
            out.append(points(estimate[i], mode="markers", marker=marker, text=list(JOINT_NAMES), name=name))
        if trackers is not None:
            marker = {"size": 3, "color": "#d62728"}  # small: the body is what the page shows
            out.append(points(trackers[i], mode="markers", marker=marker, name="trackers"))
        if robot is not None:
            ends = np.full((len(robot_bones), 3, 3), np.nan)
            ends[:, 0] = robot[i, [p for p, _ in robot_bones]]
            ends[:, 1] = robot[i, [c for _, c in robot_bones]]
            out.append(points(ends.reshape(-1, 3), mode="lines", line={"color": "#e07b00", "width": 5}, name="robot"))
        return out

    # The camera follows the body: each drawn frame moves the scene's box to be centred on
    # the pelvis, a box a little larger than the body (the whole path in one box left a
    # person 100 px tall at one end of a 7 m box). The path stays as a faint trail on the floor.
    body = shown[0]
    stature = float(np.nanmax(np.nanmax(body[..., 2], axis=1) - np.nanmin(body[..., 2], axis=1)))
    stature = stature if np.isfinite(stature) and stature > 0.5 else 1.7
    half = FOLLOW_HALF_WIDTH * stature
    centre = _filled(body[:, 0, :2])

    def box(i: int) -> dict:
        return {
            "scene.xaxis.range": [float(centre[i, 0] - half), float(centre[i, 0] + half)],
            "scene.yaxis.range": [float(centre[i, 1] - half), float(centre[i, 1] + half)],
        }

    margin = 0.3
    x = np.linspace(low[0] - margin, high[0] + margin, 9)
    y = np.linspace(low[1] - margin, high[1] + margin, 9)
    grid_x, grid_y = np.meshgrid(x, y)
    # the figure as plotly's JSON, plain dicts: plotly's objects validate every slider step and
    # frame (thousands), costing far more memory than the page they make
    floor_trace = {
        "type": "surface",
        "x": grid_x.tolist(),
        "y": grid_y.tolist(),
        "z": np.full_like(grid_x, floor).tolist(),
        "showscale": False,
        "opacity": 0.6,
        "colorscale": [[0, "#cfcfcf"], [1, "#cfcfcf"]],
        "contours": {"x": {"show": True, "color": "#888888"}, "y": {"show": True, "color": "#888888"}},
        "hoverinfo": "skip",
        "name": "floor",
    }
    trail = points(
        np.column_stack([centre, np.full(len(centre), floor)]),
        mode="lines",
        line={"color": "#b0b0b0", "width": 2},
        hoverinfo="skip",
        name="path",
    )
    duration = 1000.0 * step / fps  # ms a drawn frame stays: the recording's own speed
    first = traces(0)
    moving = list(range(2, 2 + len(first)))  # every trace but the floor and the trail
    figure: dict = {"data": [floor_trace, trail, *first]}
    top = floor + FOLLOW_HEIGHT * stature
    ranges = [box(0)["scene.xaxis.range"], box(0)["scene.yaxis.range"], [floor, top]]
    span = np.array([2 * half, 2 * half, top - floor])
    figure["layout"] = dict(
        title={
            "text": f"{title}: {frames / fps:.1f} s at {fps * stands_for:g} Hz"
            + (f", one frame in {step * stands_for} drawn" if step * stands_for > 1 else "")
        },
        scene={
            "xaxis": {"range": ranges[0], "title": "x (m)"},
            "yaxis": {"range": ranges[1], "title": "y (m)"},
            "zaxis": {"range": ranges[2], "title": "z (m)"},
            "aspectmode": "manual",
            "aspectratio": {k: float(v / max(span)) for k, v in zip("xyz", span, strict=True)},
            "camera": {"eye": {"x": 0.75, "y": -1.0, "z": 0.35}, "center": {"x": 0, "y": 0, "z": -0.05}},
        },
        legend={"x": 0.0, "y": 1.0},
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        updatemenus=[
            {
                "type": "buttons",
                "direction": "left",
                "x": 0.05,
                "y": 0.02,
                "xanchor": "left",
                "buttons": [
                    {
                        "label": "play",
                        "method": "animate",
                        "args": [
                            None,
                            {
                                "frame": {"duration": duration, "redraw": True},
                                "transition": {"duration": 0},
                                "fromcurrent": True,
                            },
                        ],
                    },
                    {
                        "label": "pause",
                        "method": "animate",
                        "args": [[None], {"frame": {"duration": 0, "redraw": False}, "mode": "immediate"}],
                    },
                ],
            }
        ],
        sliders=[
            {
                "x": 0.2,
                "len": 0.78,
                "y": 0.02,
                "currentvalue": {"prefix": "t = ", "suffix": " s"},
                "steps": [
                    {
                        "label": f"{i / fps:.2f}",
                        "method": "animate",
                        "args": [[str(i)], {"frame": {"duration": 0, "redraw": True}, "mode": "immediate"}],
                    }
                    for i in picks
                ],
            }
        ],
    )
    play = json.dumps({"frame": {"duration": duration, "redraw": True}, "transition": {"duration": 0}})
    # `#play` in the address plays on load (the browser test, a link to share)
    script = f"if (window.location.hash === '#play') {{ Plotly.animate('{{plot_id}}', null, {play}); }}"

    # the frames go into the page as JSON text made a frame at a time, in place of a marker:
    # thousands of frames held whole, as plotly's objects or one string, once took 475 MB
    def frames_json() -> Iterator[str]:
        for k, i in enumerate(picks):
            frame = {"data": traces(i), "traces": moving, "name": str(i), "layout": _nested(box(i))}
            yield ("[" if k == 0 else ",") + json.dumps(frame, allow_nan=False, separators=(",", ":"))
        yield "]"

    figure["frames"] = FRAMES_MARKER
    html = pio.to_html(
        figure, validate=False, include_plotlyjs=True, full_html=True, post_script=script, auto_play=False
    )
    head, found, tail = html.partition(json.dumps(FRAMES_MARKER))
    if not found or FRAMES_MARKER in tail:
        raise RuntimeError("plotly's page no longer holds the frames where this module puts them")
    return head, frames_json(), tail


FRAMES_MARKER = "sparse_body: the frames go here"


def stream_trackers(stream: TrackerStream, sensors: SensorConfig) -> np.ndarray:
    """(frames, sites, 3) the trackers' positions to draw: NaN where a sample is missing or
    its site has no position (an IMU)."""
    shown = stream.valid & np.array([s.has_position for s in sensors.sites])
    return np.where(shown[..., None], stream.positions, np.nan)


# In every page's <head>: what proves a page is one this command wrote (and may replace).
PAGE_MARKER = '<meta name="generator" content="sparse_body view">'


def write_body_page(path: Path, fps: float, overwrite: bool = False, **parts) -> Path:  # parts: body_page's
    """body_page written to path: a new file, or with overwrite a page this command wrote
    (io/file_output.py's rules: a user's file, a link or a device is never replaced)."""
    from ..core.file_output import marker_in_head, write_file

    head, frames, tail = body_page_parts(fps, **parts)
    head = head.replace("<head>", "<head>" + PAGE_MARKER, 1)
    return write_file(
        Path(path), chain([head], frames, [tail]), marker_in_head(PAGE_MARKER.encode()), overwrite, "page"
    )


def bag_robot(
    bag: Path, retarget, beside: np.ndarray, every: int = 1
) -> tuple[np.ndarray, tuple[tuple[int, int], ...]]:
    """(link origins (frames, links, 3), the (parent, child) links) of the robot in an estimate
    bag written with `process --robot` (/robot/joint_states, its base on /tf), placed beside the
    body: each frame moved so that the robot's base stands 0.8 m to the body's left (beside:
    (frames, 3) the body's pelvis, one a /tf message as bag_bodies gives them; every: one
    frame in `every` kept, as bag_bodies kept them)."""
    from itertools import islice

    from rosbags.rosbag2 import Reader

    from ..core.rotations import quat_to_matrix
    from ..io.bagio import TF_TOPIC, typestore
    from ..io.cdr import read_tf
    from ..io.topics import ROBOT_JOINT_STATES_TOPIC

    base_frame = ROBOT_PREFIX + retarget.mapping.base
    store = typestore()
    try:
        with Reader(Path(bag)) as reader:
            joints = [c for c in reader.connections if c.topic == ROBOT_JOINT_STATES_TOPIC]
            if not joints:
                raise ViewError(f"{bag}: no {ROBOT_JOINT_STATES_TOPIC} (write it with process --robot)")
            angles = [
                store.deserialize_cdr(raw, c.msgtype).position
                for c, _, raw in islice(reader.messages(connections=joints), 0, None, every)
            ]
            tf = [c for c in reader.connections if c.topic == TF_TOPIC]
            bases = [
                next((row for row in read_tf(raw) if row[1] == base_frame), None)
                for _, _, raw in islice(reader.messages(connections=tf), 0, None, every)
            ]
    except ViewError:
        raise
    except Exception as err:  # noqa: BLE001 - rosbags raises many kinds for a broken file
        raise ViewError(f"{bag}: cannot be read as a rosbag2 ({err})") from None
    placed = [b[3] for b in bases if b is not None]
    if len(angles) != len(placed) or len(angles) != len(beside):
        raise ViewError(f"{bag}: {len(angles)} robot poses, {len(placed)} robot bases and {len(beside)} bodies")
    if len(angles[0]) != len(retarget.names):
        raise ViewError(f"{bag}: its robot has {len(angles[0])} joints, the mapping's {len(retarget.names)}")
    links = np.empty((len(angles), len(retarget.model.links), 3))
    for i, (q, values) in enumerate(zip(angles, placed, strict=True)):
        place, turn = np.asarray(values[:3]), np.asarray(values[3:])
        links[i] = retarget.link_transforms(np.asarray(q), place, quat_to_matrix(turn))[:, :3, 3]
        links[i, :, :2] += beside[i, :2] - place[:2] + [0.0, 0.8]
    bones = tuple((j.parent, j.child) for j in retarget.model.joints)
    return links, bones


def bag_robot_links(
    bag: Path, beside: np.ndarray, every: int = 1
) -> tuple[np.ndarray, tuple[tuple[int, int], ...]] | None:
    """bag_robot's answer from the robot's links on the bag's /tf alone (`process --robot`
    puts every link there under robot/), no mapping or URDF needed; None where the bag's /tf
    has no robot links (a bag written without --robot, or before its links were written)."""
    from itertools import islice

    from rosbags.rosbag2 import Reader

    from ..core.rotations import quat_to_matrix
    from ..io.bagio import TF_TOPIC
    from ..io.cdr import read_tf

    names: list[str] = []
    bones: list[tuple[int, int]] = []
    frames: list[np.ndarray] = []
    try:
        with Reader(Path(bag)) as reader:
            tf = [c for c in reader.connections if c.topic == TF_TOPIC]
            for _, _, raw in islice(reader.messages(connections=tf), 0, None, every):
                rows = [r for r in read_tf(raw) if r[1].startswith(ROBOT_PREFIX)]
                if not rows:
                    return None
                if not names:
                    names = [child for _, child, _, _ in rows]
                    index = {n: k for k, n in enumerate(names)}
                    bones = [(index[parent], index[child]) for parent, child, _, _ in rows if parent in index]
                placed: dict[str, np.ndarray] = {}
                for parent, child, _, values in rows:  # each parent comes before its children
                    local = np.eye(4)
                    local[:3, :3], local[:3, 3] = quat_to_matrix(np.asarray(values[3:])), values[:3]
                    placed[child] = placed[parent] @ local if parent in placed else local
                frames.append(np.array([placed[n][:3, 3] for n in names]))
    except Exception as err:  # noqa: BLE001 - rosbags raises many kinds for a broken file
        raise ViewError(f"{bag}: cannot be read as a rosbag2 ({err})") from None
    if len(frames) != len(beside):
        raise ViewError(f"{bag}: {len(frames)} robot poses on /tf and {len(beside)} bodies")
    links = np.array(frames)
    links[:, :, :2] += (beside[:, None, :2] - links[:, :1, :2]) + [0.0, 0.8]
    return links, tuple(bones)


def bag_bodies(bag: Path, drawn: bool = False) -> tuple[np.ndarray, np.ndarray | None, float, int]:
    """tf_bodies of an estimate bag's /tf, and how many of its frames each one returned stands
    for: with drawn=True, only the frames a page draws (at most MAX_FPS a second and MAX_FRAMES
    in all, judged from the bag's message count and duration) are kept while reading."""
    from rosbags.rosbag2 import Reader

    from ..io.bagio import TF_TOPIC
    from ..io.cdr import MalformedMessage, read_tf

    try:
        with Reader(Path(bag)) as reader:
            tf = [c for c in reader.connections if c.topic == TF_TOPIC]
            count = sum(c.msgcount for c in tf)
            every = 1
            if drawn and count > 1 and reader.duration > 0:
                rate = (count - 1) / (reader.duration * 1e-9)
                every = max(int(np.ceil(rate / MAX_FPS - 1e-3)), int(np.ceil(count / MAX_FRAMES)), 1)
            # one message at a time: a recording's rows held whole cost 3 kB a frame (a
            # 5-minute bag reached 982 MB), its bodies a few hundred bytes
            messages = (read_tf(raw) for _, _, raw in reader.messages(connections=tf))
            return (*tf_bodies(messages, str(bag), every, count // every + 1), every)
    except ViewError:
        raise
    except MalformedMessage as err:
        raise ViewError(f"{bag}: a /tf message that is not a TFMessage ({err})") from None
    except Exception as err:  # noqa: BLE001 - rosbags raises many kinds for a broken file
        raise ViewError(f"{bag}: cannot be read as a rosbag2 ({err})") from None


def tf_bodies(
    messages: Iterable[list[TfRow]], source: str, every: int = 1, expected: int = 0
) -> tuple[np.ndarray, np.ndarray | None, float]:
    """(joint positions (frames, 22, 3), trackers (frames, k, 3) or None, frame rate) of the
    /tf messages of an estimate (a bag, the live view): a frame per message with every body
    link (fixed frame -> pelvis -> ...); the trackers are the other frames directly under the
    fixed frame, from that message or those since the previous body (the live view sends
    them apart), NaN where a tracker was not seen. every=N keeps one body in N (the first,
    then each Nth), dropping the others as they are read; the frame rate is the kept ones'.
    expected: about how many bodies will be kept (room is made for them at once)."""
    names = {name: j for j, name in enumerate(JOINT_NAMES)}
    # each kept body written into arrays as it comes (one row a frame: Python lists of small
    # arrays and dicts once cost 3 kB a frame)
    # (float32 holds every bit of a bag's poses: they are published at float32 precision)
    store = _Rows({"stamp": ((), np.float64), "pose": ((NUM_JOINTS, 7), np.float32)}, expected)
    tracker_names: list[str] = []
    tracker_rows = _Rows({"trackers": ((0, 3), np.float32)}, expected)
    offsets = None
    loose: list[TfRow] = []  # rows since the last body
    seen = 0  # bodies read
    for rows in messages:
        by_child = {child: (parent, stamp, numbers) for parent, child, stamp, numbers in rows}
        if not all(n in by_child for n in JOINT_NAMES):
            loose += rows  # not a body message (trackers, or a body of another prefix)
            continue
        seen += 1
        if (seen - 1) % every:  # not drawn: nor are the trackers sent before it
            loose = []
            continue
        fixed, stamp, _ = by_child[JOINT_NAMES[0]]
        numbers = np.array([by_child[name][2] for name in names])  # x y z, qx qy qz qw
        store.append(stamp=stamp, pose=numbers)
        offsets = numbers[:, :3].copy() if offsets is None else offsets
        row: dict[str, tuple] = {}
        for parent, child, _, values in loose + rows:
            if parent == fixed and child != JOINT_NAMES[0] and not child.startswith(ROBOT_PREFIX):  # (a robot's base)
                row[child] = tuple(values[:3])
                if child not in tracker_names:
                    tracker_names.append(child)
                    tracker_rows.widen("trackers", len(tracker_names))
        placed = np.full((len(tracker_names), 3), np.nan)
        for k, name in enumerate(tracker_names):
            if name in row:
                placed[k] = row[name]
        tracker_rows.append(trackers=placed)
        loose = []
    if not len(store) or offsets is None:
        raise ViewError(f"{source}: no body on /tf (a bag `sparse-body process` wrote has one)")
    offsets[0] = 0.0
    poses, stamps = store.array("pose"), store.array("stamp")
    positions = _positions(poses[:, :, 3:], poses[:, 0, :3], offsets.astype(np.float64))
    trackers = tracker_rows.array("trackers").astype(np.float64) if tracker_names else None
    gaps = np.diff(stamps)
    gaps = gaps[gaps > 0]
    fps = round(float(1.0 / np.median(gaps)), 3) if len(gaps) else 60.0  # stamps are rounded to ns
    return positions, trackers, fps


class _Rows:
    """Rows of named arrays appended one at a time into arrays that double as they fill."""

    def __init__(self, kinds: dict[str, tuple[tuple[int, ...], type]], expected: int = 0) -> None:
        """kinds: each array's row shape and type; expected: how many rows to make room for at first."""
        start = max(64, expected)
        self.data: dict[str, np.ndarray] = {
            name: np.full((start, *shape), np.nan, dtype) for name, (shape, dtype) in kinds.items()
        }
        self.count = 0

    def __len__(self) -> int:
        return self.count

    def widen(self, name: str, width: int) -> None:
        """Its second axis grown to `width` (NaN in the rows that had less)."""
        old = self.data[name]
        new = np.full((len(old), width, *old.shape[2:]), np.nan, old.dtype)
        new[:, : old.shape[1]] = old
        self.data[name] = new

    def append(self, **row) -> None:
        if self.count == len(next(iter(self.data.values()))):
            for name, old in self.data.items():
                new = np.full((2 * len(old), *old.shape[1:]), np.nan, old.dtype)
                new[: len(old)] = old
                self.data[name] = new
        for name, value in row.items():
            self.data[name][self.count] = value
        self.count += 1

    def array(self, name: str) -> np.ndarray:
        return self.data[name][: self.count]


def _positions(quats: np.ndarray, roots: np.ndarray, offsets: np.ndarray, block: int = 1024) -> np.ndarray:
    """Joint positions (frames, 22, 3) of local rotations (frames, 22, 4) and roots, a block of
    frames at a time (the rotation matrices of a whole recording are 14 MB per 9,000 frames)."""
    from ..core.kinematics import forward_kinematics
    from ..core.rotations import quat_to_matrix

    out = np.empty((len(quats), NUM_JOINTS, 3))
    for start in range(0, len(quats), block):
        part = slice(start, start + block)
        turns = quat_to_matrix(quats[part].astype(np.float64))
        out[part] = forward_kinematics(turns, roots[part].astype(np.float64), offsets)[1]
    return out
