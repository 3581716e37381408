"""`sparse-body eval`: run an estimator over a split of the CMU clips and tabulate the metrics.

By default under the field protocol (data/field_protocol.py): the estimator gets the body and
the tracker samples a user would have, not the subject's true skeleton and clean trackers;
the lab protocol (LAB) gives the papers' setting for comparison."""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .core.contacts import contact_labels, estimate_floor
from .core.kinematics import forward_kinematics
from .core.metrics import per_joint_metrics, sequence_metrics, weighted_mean
from .core.rotations import quat_to_matrix
from .core.sensors import SensorConfig
from .data.catalog import DEFAULT_FPS, load_clip, load_motion_file, split_clips
from .data.motion import Motion
from .data.field_protocol import FIELD, Protocol, user_view
from .data.virtual_trackers import TrackerNoise
from .estimators import create_estimator
from .estimators.base import parse_estimator_spec  # noqa: F401 - the CLI's import


@dataclass
class EvalResult:
    estimator: str
    sensors: str
    split: str
    clips: list[str] = field(default_factory=list)
    frames: list[int] = field(default_factory=list)
    per_clip: list[dict[str, float]] = field(default_factory=list)
    seconds: float = 0.0
    protocol: str = "field"

    @property
    def summary(self) -> dict[str, float]:
        return weighted_mean(self.per_clip, self.frames) if self.per_clip else {}

    def to_json(self) -> dict:
        return {"estimator": self.estimator, "sensors": self.sensors, "split": self.split, "protocol": self.protocol,
                "frames": int(sum(self.frames)), "seconds": self.seconds, "summary": self.summary,
                "clips": [{"clip": c, "frames": n, **m} for c, n, m in zip(self.clips, self.frames, self.per_clip)]}


def evaluate_motion(motion: Motion, estimator_name: str, sensors: SensorConfig,
                    protocol: Protocol = FIELD, seed: int = 0, per_joint: bool = False,
                    **options) -> dict[str, float]:
    """Metrics of one estimator on one motion, from the motion's own virtual trackers as the
    protocol hands them to a user's estimator (its body, mounting, noise).

    The motion is first moved so that its floor is z = 0, as in a calibrated VR play space:
    estimators that need the floor (IK contacts, LoBSTr's reference height) find it there.
    The estimate's joints are placed with the body the estimator was given, as a user's
    avatar or robot would show them. per_joint: each joint's errors as well
    (core/metrics.py: per_joint_metrics)."""
    floor = estimate_floor(motion.positions)
    motion = Motion(motion.name, motion.fps, motion.skeleton, motion.local_quats,
                    motion.root_positions - [0.0, 0.0, floor])
    view = user_view(motion, sensors, protocol, seed)
    options = {**filter_options(protocol.noise), **options}
    estimator = create_estimator(estimator_name, view.sensors, view.skeleton, fps=motion.fps, **options)
    poses = estimator.process(view.stream)
    local = quat_to_matrix(np.stack([p.local_quats for p in poses]))
    root = np.stack([p.root_position for p in poses])
    glob, pos = forward_kinematics(local, root, view.skeleton.offsets)
    pred_contacts = np.stack([p.contact for p in poses])
    floor = 0.0
    gt_contacts = contact_labels(motion.positions, motion.fps, floor)
    tracked = sorted({s.joint_index for s in sensors.sites})
    metrics = sequence_metrics(pos, glob, local, motion.positions, motion.global_rotations, motion.local_rotations,
                               motion.fps, floor, gt_contacts, pred_contacts, tracked)
    if per_joint:
        metrics.update(per_joint_metrics(pos, motion.positions, local, motion.local_rotations))
    return metrics


def filter_options(noise: TrackerNoise) -> dict[str, float]:
    """The tracker filter set for this noise, as a user sets it from their system's
    specification (no noise: no filter)."""
    # a rotation by an angle up to M about a random axis has a rotation vector of std M/3 per axis
    return {"filter_position_noise": noise.position_std, "filter_rotation_noise": noise.rotation_max_deg / 3}


# Published figures printed beside an estimator's results, by (estimator, sensors[, faulty %])
# (the papers' own data and protocols: a guide rather than a like-for-like comparison).
PAPER_FIGURES = {
    ("lobstr", "four_point"): {"LoBSTr paper": {"Contact acc [%]": 85.77, "Lower RE [deg]": 8.53, "Toe PE [cm]": 6.63}},
    # DragPoser, Table 2: joint position, rotation, velocity error and end-effector error
    ("dragposer", "six_point"): {"DragPoser paper": {"MPJPE [cm]": 2.18, "MPJRE [deg]": 7.66, "MPJVE [cm/s]": 10.7,
                                                     "End-effector PE [cm]": 1.02},
                                 # Table 3: the optimiser without the temporal predictor
                                 "paper, no predictor": {"MPJPE [cm]": 3.05, "MPJRE [deg]": 10.5,
                                                         "MPJVE [cm/s]": 13.1, "End-effector PE [cm]": 1.36}},
    ("dragposer", "four_point"): {"DragPoser paper": {"MPJPE [cm]": 7.86, "MPJRE [deg]": 10.6, "MPJVE [cm/s]": 20.0,
                                                      "End-effector PE [cm]": 1.12}},
    ("dragposer", "three_point"): {"DragPoser paper": {"MPJPE [cm]": 15.5, "MPJRE [deg]": 22.0, "MPJVE [cm/s]": 34.0,
                                                       "End-effector PE [cm]": 16.1}},
    ("dragposer", "hip_hands"): {"DragPoser paper": {"MPJPE [cm]": 9.95, "MPJRE [deg]": 14.1, "MPJVE [cm/s]": 23.1,
                                                     "End-effector PE [cm]": 1.77}},
    # DTP, Table 2 (online, TotalCapture): mean joint position error, global rotation error, jerk
    ("dtp", "six_point"): {"DTP paper": {"MPJPE [cm]": 1.04, "MPJRE [deg]": 4.22, "Jitter [100m/s3]": 2.31}},
    # AvatarJLM, Table 1 (AMASS Protocol 1: 90 % of CMU, BMLrub, HDM05 for training)
    ("avatarjlm", "three_point"): {"AvatarJLM paper": {"MPJPE [cm]": 3.35, "MPJRE [deg]": 2.90, "MPJVE [cm/s]": 20.79}},
    ("avatarjlm", "four_point"): {"AvatarJLM paper": {"MPJPE [cm]": 2.09, "MPJRE [deg]": 2.40, "MPJVE [cm/s]": 17.82}},
    ("dragposer", "six_point", 1.0): {"DragPoser paper": {"MPJPE [cm]": 6.55, "MPJRE [deg]": 12.0,
                                                          "MPJVE [cm/s]": 21.1, "End-effector PE [cm]": 10.2}},
}


def paper_figures(estimator: str, sensors: str, faulty_percent: float = 0.0, occluded_percent: float = 0.0) -> dict:
    if occluded_percent:          # the DTP paper's occluded test set has no stated share: no like to compare
        return {}
    key = (estimator, sensors, faulty_percent) if faulty_percent else (estimator, sensors)
    return PAPER_FIGURES.get(key, {})


# What `sparse-body eval` runs beside a learned estimator unless told not to.
COMPARE_WITH = {
    "lobstr": ["lobstr:contact_ik=false", "ik"],
    "dragposer": ["dragposer:temporal_weight=0", "ik"],   # the paper's Table 3 ablation, the baseline
    "dtp": ["dtp:model=pretrained", "dtp:model=lookahead", "dragposer", "lobstr", "ik"],
    "avatarjlm": ["avatarjlm:polish=false", "dragposer", "ik"],
}


def evaluate(estimator_spec: str, sensors: SensorConfig, mocap_root: Path | None, split: str = "test",
             fps: float = DEFAULT_FPS, protocol: Protocol = FIELD, limit: int | None = None,
             progress: bool = True, motions: list[Path] | None = None, per_joint: bool = False,
             **options) -> EvalResult:
    """estimator_spec: a name, optionally with options ("lobstr:contact_ik=false"). The clips
    of a split of the CMU catalogue, or the motion files given (a user's own: BVH or ASF/AMC
    of a known layout, sparse_body .npz)."""
    estimator_name, spec_options = parse_estimator_spec(estimator_spec)
    options = {**spec_options, **options}
    if motions is not None:
        items = [(Path(p).name, lambda p=p: load_motion_file(Path(p), fps)) for p in motions[:limit]]
        split = "files"
    else:
        items = [(c.clip_id, lambda c=c: load_clip(c, fps)) for c in split_clips(mocap_root, split, limit)]
    result = EvalResult(estimator_spec, sensors.name, split, protocol=protocol.label)
    start = time.perf_counter()
    iterator = items
    if progress:
        from tqdm import tqdm
        iterator = tqdm(items, desc=f"eval {estimator_spec}/{sensors.name}", unit="clip")
    for k, (name, load) in enumerate(iterator):
        motion = load()
        result.clips.append(name)
        result.frames.append(len(motion))
        result.per_clip.append(evaluate_motion(motion, estimator_name, sensors, protocol, seed=k,
                                               per_joint=per_joint, **options))
    result.seconds = time.perf_counter() - start
    return result


def format_table(results: list[EvalResult], reference: dict[str, dict[str, float]] | None = None,
                 max_width: int = 100) -> str:
    """Metrics as rows, one column per result (and per paper figure given in reference).
    Columns whose names would make the table wider than max_width are numbered, and the
    numbers named below the table, so it fits a normal terminal."""
    mixed = len({r.protocol for r in results}) > 1
    columns = [f"{r.estimator}/{r.sensors}" + (f" ({r.protocol})" if mixed else "") for r in results] + list(reference or {})
    values = [r.summary for r in results] + list((reference or {}).values())
    keys = list(results[0].summary)
    width = max(len(k) for k in keys) + 2
    colw = max(12, *(len(c) + 2 for c in columns))
    legend = []
    if width + colw * len(columns) > max_width:
        legend = [f"  [{k + 1}] {c}" for k, c in enumerate(columns)]
        columns = [f"[{k + 1}]" for k in range(len(columns))]
        colw = 9
    lines = ["".ljust(width) + "".join(c.rjust(colw) for c in columns)]
    for key in keys:
        cells = []
        for v in values:
            x = v.get(key, float("nan"))
            cells.append(("-" if not np.isfinite(x) else f"{x:.2f}").rjust(colw))
        lines.append(key.ljust(width) + "".join(cells))
    frames = sum(results[0].frames)
    where = "the motion files given" if results[0].split == "files" else f"the {results[0].split} split"
    protocol = "protocols as named" if mixed else f"{results[0].protocol} protocol"
    lines.append(f"({len(results[0].clips)} clips of {where}, {frames} frames; {protocol})")
    return "\n".join(lines + legend)


RESULT_KEYS = {"estimator", "sensors", "split", "clips"}
RESULTS_LIMIT = 256 << 20      # bytes: a results file of every CMU clip is a few MB


def is_results_file(path: Path) -> bool:
    """Whether path is a results file `write_json` wrote (a JSON list of results): the only
    existing file an evaluation replaces."""
    path = Path(path)
    try:
        if path.is_symlink() or not path.is_file() or path.stat().st_size > RESULTS_LIMIT:
            return False
        data = json.loads(path.read_text())
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(data, list) and bool(data) and all(isinstance(r, dict) and RESULT_KEYS <= r.keys() for r in data)


def check_results_path(path: Path) -> Path:
    """Refuse, before any evaluation, a results path that is not ours to write: an existing
    file other than an earlier results file, a folder, a device; its folder must exist."""
    from .bagio import OutputError
    path = Path(path)
    if (path.exists() or path.is_symlink()) and not is_results_file(path):
        raise OutputError(f"{path}: exists and is not a results file of `sparse-body eval`; it is never "
                          f"replaced, choose another --output")
    if not path.absolute().parent.is_dir():
        raise OutputError(f"{path}: {path.absolute().parent} is not an existing folder")
    return path


def write_json(results: list[EvalResult], path: Path) -> None:
    """The results as JSON, written under a temporary name and moved into place."""
    import os
    path = check_results_path(path)
    tmp = path.with_name(f".{path.name}.partial-{os.getpid()}")
    try:
        tmp.write_text(json.dumps([r.to_json() for r in results], indent=1, allow_nan=True))
        check_results_path(path)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
