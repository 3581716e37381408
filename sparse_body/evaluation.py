"""`sparse-body eval`: run an estimator over a split of the CMU clips and tabulate the metrics.

By default under the field protocol (data/field_protocol.py): the estimator gets the body and
the tracker samples a user would have, not the subject's true skeleton and clean trackers;
the lab protocol (LAB) gives the papers' setting for comparison."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np

from .core.contacts import LABEL_VERSION, contact_labels, estimate_floor
from .core.kinematics import forward_kinematics
from .core.metrics import loss_metrics, per_joint_metrics, sequence_metrics
from .core.results import EvalResult
from .core.rotations import quat_to_matrix
from .core.sensors import SensorConfig
from .data import MotionFileError
from .data.catalog import DEFAULT_FPS, FLOOR, SELECTION, load_clip, split_clips
from .data.field_protocol import FIELD, Protocol, UserView, user_view
from .data.motion import Motion
from .data.motion_inputs import (
    AMC_FPS,
    MotionInput,
    balanced,
    content_digest,
    find_inputs,
    identity_seed,
    implausible,
    load_input,
)
from .data.virtual_trackers import TrackerNoise
from .estimators.base import parse_estimator_spec
from .methods.factory import create_estimator


@dataclass
class EvalItem:
    """One clip to evaluate: its name, its identity (what a resumed run matches), the field
    protocol's seed, how to load it, its group in the tables and what was read."""

    name: str
    key: str
    seed: int
    load: Callable[[], Motion]
    group: str = ""
    source: str = ""
    check_plausible: bool = False  # a user's file: say when its skeleton does not fit the motion
    subject: str = ""  # the person (a CMU clip's subject): intervals drawn by person
    category: str = ""  # the kind of motion (a CMU clip's category in clips.tsv)


def method_options(spec: str, options: dict | None = None) -> dict:
    """Every option of a spec's method as it runs ("lobstr:contact_ik=false" and the options
    given beside it over the defaults), as its options dataclass records them."""
    from .methods import METHODS, load

    name, given = parse_estimator_spec(spec)
    if name not in METHODS:
        return {}
    declared = load(METHODS[name].options)
    given = {k: v for k, v in {**given, **(options or {})}.items() if k in declared.fields()}
    return declared.parse(given, f"estimator {name!r}").as_dict()


OUT_OF_DEPTH = "Out of depth [%]"  # (a metric only of estimators that say it: upright)


@dataclass
class Estimated:
    """One estimator's run over one motion: what evaluate_motion scores and `view` draws."""

    motion: Motion  # moved so that its floor is z = 0
    view: UserView  # what the estimator was given
    positions: np.ndarray  # (T, 22, 3) the estimate's joints, placed with view.skeleton
    global_rotations: np.ndarray  # (T, 22, 3, 3)
    local_rotations: np.ndarray  # (T, 22, 3, 3)
    contacts: np.ndarray  # (T, 2) left, right
    horizon: int = 0  # frames after its own frame each pose is of (predict_ahead), scored there
    contact_probability: np.ndarray | None = None  # (T, 2) as published beside the contacts
    out_of_depth: np.ndarray | None = None  # (T,) Estimator.out_of_depth after each pose; None: it says none


def floored(motion: Motion) -> Motion:
    """The motion moved so that its floor is z = 0 (the one it says, else the toes' estimate)."""
    floor = estimate_floor(motion.positions) if motion.floor is None else motion.floor
    root = motion.root_positions - [0.0, 0.0, floor]
    return Motion(motion.name, motion.fps, motion.skeleton, motion.local_quats, root, floor=0.0)


def estimate_motion(
    motion: Motion,
    estimator_name: str,
    sensors: SensorConfig,
    protocol: Protocol = FIELD,
    seed: int = 0,
    horizon: float | None = None,
    **options,
) -> Estimated:
    """The estimate of one motion from its own virtual trackers as the protocol hands them to
    a user's estimator (its body, mounting, noise).

    The motion is first moved so that its floor is z = 0, as in a calibrated VR play space:
    estimators that need the floor (IK contacts, LoBSTr's reference height) find it there.
    The estimate's joints are placed with the body the estimator was given, as a user's
    avatar or robot would show them. Each pose is scored against the body `horizon` seconds
    after its frame (None: the estimator's predict_ahead): `horizon` without predict_ahead is
    the baseline a forecast must beat, the present pose given as the later one."""
    motion = floored(motion)
    view = user_view(motion, sensors, protocol, seed)
    options = {**filter_options(protocol.noise), **options}
    estimator = create_estimator(estimator_name, view.sensors, view.skeleton, fps=motion.fps, **options)
    poses, depth = [], []
    for pose in estimator.stream(view.stream):  # (process(), with what it says after each pose)
        poses.append(pose)
        share = estimator.out_of_depth()
        depth.append(np.nan if share is None else share[0])
    local = quat_to_matrix(np.stack([p.local_quats for p in poses]))
    root = np.stack([p.root_position for p in poses])
    glob, pos = forward_kinematics(local, root, view.skeleton.offsets)
    ahead = round((estimator.ahead if horizon is None else horizon) * motion.fps)
    if ahead and not ahead < len(motion) - 1:  # (a pose on time always has its body)
        raise ValueError(f"a horizon of {ahead} frames does not fit the {len(motion)}-frame motion {motion.name}")
    contacts = np.stack([p.contact for p in poses])
    probability = np.stack([p.contact_probability for p in poses])
    depths = np.array(depth) if np.isfinite(depth).any() else None
    return Estimated(motion, view, pos, glob, local, contacts, ahead, probability, depths)


def evaluate_motion(*args, per_joint: bool = False, **options) -> dict[str, float]:
    """Metrics of estimate_motion(*args, **options) against the motion itself. per_joint:
    each joint's errors as well (core/metrics.py: per_joint_metrics)."""
    return score(estimate_motion(*args, **options), per_joint)


def score(run: Estimated, per_joint: bool = False) -> dict[str, float]:
    """The metrics of an estimate against the motion it was made from."""
    motion, floor = run.motion, 0.0
    # pose t against the body at t + horizon: the first frames have no pose of their time
    made, true = slice(0, len(motion) - run.horizon), slice(run.horizon, len(motion))
    gt_pos = motion.positions[true]
    gt_contacts = contact_labels(motion.positions, motion.fps)[true]
    tracked = sorted({s.joint_index for s in run.view.sensors.sites})
    metrics = sequence_metrics(
        run.positions[made],
        run.global_rotations[made],
        run.local_rotations[made],
        gt_pos,
        motion.global_rotations[true],
        motion.local_rotations[true],
        motion.fps,
        floor,
        gt_contacts,
        run.contacts[made],
        tracked,
    )
    if run.out_of_depth is not None:  # the share of frames the estimator said lay mostly outside what it knows
        metrics[OUT_OF_DEPTH] = float(np.mean(np.nan_to_num(run.out_of_depth[made]) > 0.5) * 100)
    lost = run.view.stream.lost
    if lost is not None:  # a protocol that takes trackers out of view (--hand-loss)
        joints = [site.joint_index for site in run.view.sensors.sites]
        metrics.update(loss_metrics(run.positions[made], gt_pos, lost[made], joints, motion.fps))
    if per_joint:
        metrics.update(
            per_joint_metrics(run.positions[made], gt_pos, run.local_rotations[made], motion.local_rotations[true])
        )
    return metrics


def filter_options(noise: TrackerNoise) -> dict[str, float]:
    """The tracker filter set for this noise, as a user sets it from their system's
    specification (no noise: no filter)."""
    # a rotation by an angle up to M about a random axis has a rotation vector of std M/3 per axis
    return {"filter_position_noise": noise.position_std, "filter_rotation_noise": noise.rotation_max_deg / 3}


def estimated_clips(mocap_root: Path, split: str, estimator: str, sensors_name: str, limit: int | None = None):
    """Each clip of a split as a user's stack would estimate it, one at a time: (item, motion
    moved so that its floor is z = 0, the user's view of it, the estimator's poses), under the
    field protocol with the filter set for its noise (what the forecast's tools read)."""
    from .core.sensors import load_sensor_config

    sensors = load_sensor_config(sensors_name)
    for item in split_items(mocap_root, split, limit=limit):
        motion = item.load()
        motion = floored(motion)
        view = user_view(motion, sensors, FIELD, item.seed)
        est = create_estimator(estimator, view.sensors, view.skeleton, fps=motion.fps, **filter_options(FIELD.noise))
        yield item, motion, view, est.process(view.stream)


def split_items(mocap_root: Path, split: str, fps: float = DEFAULT_FPS, limit: int | None = None) -> list[EvalItem]:
    """The clips of a part of the CMU split (or of an imported folder's), seeded by their place
    in the split (the split's order is fixed, so the draws are too); a selection clip by its
    place in validation, so that it meets the same draws in both. "floor": the selection's
    clips lying on the floor, on the back, the side and the front in turn (data/floor.py), each
    lying kind a kind of motion of its own."""
    if split == FLOOR:
        from .data.floor import LYING

        ways = list(LYING)
        return [
            replace(
                item,
                name=f"{item.name}_{ways[k % len(ways)].split()[-1]}",
                key=f"{item.key}:{ways[k % len(ways)]}",
                load=partial(_lying, item.load, ways[k % len(ways)]),
                category=ways[k % len(ways)],
            )
            for k, item in enumerate(split_items(mocap_root, SELECTION, fps, limit))
        ]
    seeds = {c.clip_id: k for k, c in enumerate(split_clips(mocap_root, "validation" if split == SELECTION else split))}
    return [
        EvalItem(
            c.clip_id,
            c.clip_id,
            seeds[c.clip_id],
            partial(load_clip, c, fps),
            c.subject,
            str(c.path),
            subject=c.subject,
            category=c.kind,
        )
        for c in split_clips(mocap_root, split, limit)
    ]


def part_items(split: str, motion: str | None = None, limit: int | None = None) -> list[EvalItem]:
    """The clips a measuring script reads: a folder of motion files (motion), else a part of
    the indexed CMU split (find_mocap_root); MocapFolderError, in one line, where there is none."""
    from .data.catalog import MocapFolderError, find_mocap_root

    if motion:
        return file_items(find_inputs([motion]))
    root = find_mocap_root()
    if root is None:
        raise MocapFolderError("no motion capture folder found (sparse-body import-mocap, or a folder of motion files)")
    return split_items(root, split, limit=limit)


def _lying(load: Callable[[], Motion], how: str) -> Motion:
    from .data.floor import lying

    return lying(load(), how)


def untrained_categories(mocap_root: Path, categories: list[str]) -> dict[str, str]:
    """A note for each kind of motion of which no training clip has one: on those, a learned
    estimator meets motion it never saw (the split is by person, not by motion)."""
    trained = {c.kind for c in split_clips(mocap_root, "train")}
    return {c: ", not in training" for c in set(categories) if c and c not in trained}


def file_items(inputs: list[MotionInput], fps: float = DEFAULT_FPS, amc_fps: float = AMC_FPS) -> list[EvalItem]:
    """A user's motion files, each identified and seeded by its name and content, so the field
    protocol's draws for a clip do not move when files are added, removed or reordered."""
    items = []
    for inp in inputs:
        source = str(inp.path) + (f" with {inp.skeleton} ({inp.how})" if inp.skeleton else "")
        try:
            digest = content_digest(inp)
        except OSError as err:

            def fail(err=err):
                raise err

            items.append(EvalItem(inp.path.name, str(inp.path), 0, fail, inp.group, source))
            continue
        load = lambda inp=inp, digest=digest: load_input(inp, fps, amc_fps, digest)  # noqa: E731
        items.append(
            EvalItem(
                inp.path.name,
                f"{inp.path.name}:{digest[:16]}",
                identity_seed(inp.path.name, digest),
                load,
                inp.group,
                source,
                check_plausible=True,
            )
        )
    return items


def evaluate(
    estimator_spec: str,
    sensors: SensorConfig,
    mocap_root: Path | None,
    split: str = "test",
    fps: float = DEFAULT_FPS,
    protocol: Protocol = FIELD,
    limit: int | None = None,
    progress: bool = True,
    motions: list[Path] | None = None,
    per_joint: bool = False,
    **options,
) -> EvalResult:
    """estimator_spec: a name, optionally with options ("lobstr:contact_ik=false"). The clips
    of a split of the CMU catalogue, or the motion files given (a user's own: BVH or ASF/AMC
    of a known layout, sparse_body .npz)."""
    if motions is not None:
        items, split = file_items(balanced(find_inputs(motions), limit), fps), "files"
    elif mocap_root is None:
        raise ValueError("no motion capture folder to take the split's clips from (import-mocap, or --motion files)")
    else:
        items = split_items(mocap_root, split, fps, limit)
    return run_evaluation(
        [estimator_spec], sensors, items, split, fps, protocol, per_joint, progress=progress, **options
    )[0]


def run_evaluation(
    specs: list[str],
    sensors: SensorConfig,
    items: list[EvalItem],
    split: str,
    fps: float = DEFAULT_FPS,
    protocol: Protocol = FIELD,
    per_joint: bool = False,
    out: Path | None = None,
    progress: bool = True,
    warn=None,
    **options,
) -> list[EvalResult]:
    """Every estimator on every clip, a clip at a time: each clip is read once for all
    estimators, and the results are written to `out` after each (so a stopped run keeps what
    it did, and the same command resumes: clips already in `out` under the same settings are
    not evaluated again). A file that cannot be read or evaluated is recorded in the results'
    `skipped` with the reason and the run goes on; warn(text) hears of motions that do not fit
    their skeleton."""
    results = []
    for spec in specs:
        settings: dict[str, object] = {"fps": fps, "per_joint": per_joint, "contact_labels": LABEL_VERSION}
        settings.update({k: str(v) for k, v in options.items()})
        results.append(
            EvalResult(
                spec,
                sensors.name,
                split,
                protocol=protocol.label,
                settings=settings,
                protocol_spec=protocol.to_json(),
                options=method_options(spec, options),
            )
        )
    if out is not None:
        results = _resumed(results, out)
    iterator = items
    if progress:
        from tqdm import tqdm

        iterator = tqdm(items, desc=f"eval {'+'.join(specs)}/{sensors.name}", unit="clip")
    done = [set(r.keys) | {s["key"] for s in r.skipped} for r in results]  # what a resumed run has
    for item in iterator:
        todo = [r for r, keys in zip(results, done, strict=True) if item.key not in keys]
        if not todo:
            continue
        try:
            motion = item.load()
        except (MotionFileError, ValueError, OSError) as err:
            for r in todo:
                r.skipped.append({"clip": item.name, "key": item.key, "reason": " ".join(str(err).split())})
            todo = []
        if todo and item.check_plausible and warn is not None and (why := implausible(motion)):
            warn(f"{item.source}: {why}: does the skeleton fit the motion (the actor's ASF, its length unit)?")
        for r in todo:
            start = time.perf_counter()
            name, spec_options = parse_estimator_spec(r.estimator)
            try:
                metrics = evaluate_motion(
                    motion, name, sensors, protocol, seed=item.seed, per_joint=per_joint, **{**spec_options, **options}
                )
            except (MotionFileError, ValueError) as err:
                r.skipped.append({"clip": item.name, "key": item.key, "reason": " ".join(str(err).split())})
                continue
            r.add(item, len(motion), metrics)
            r.seconds += time.perf_counter() - start
        if out is not None and any(r.clips for r in results):  # nothing but failures: nothing written
            write_json(results, out, intervals=False)
    if out is not None and any(r.clips for r in results):
        write_json(results, out)
    return results


def _resumed(results: list[EvalResult], out: Path) -> list[EvalResult]:
    """The results already in `out` for the same estimator, sensors, split, protocol and
    settings (a run stopped or extended); fresh results for the others."""
    if not is_results_file(out):
        return results
    earlier = [EvalResult.from_json(d) for d in json.loads(Path(out).read_text())]

    def same(a, b) -> bool:
        return (a.estimator, a.sensors, a.split, a.protocol, a.settings) == (
            b.estimator,
            b.sensors,
            b.split,
            b.protocol,
            b.settings,
        )

    # a file written before results kept their protocol_spec gets it from the run that extends it
    return [
        next((replace(e, protocol_spec=e.protocol_spec or r.protocol_spec) for e in earlier if same(e, r)), r)
        for r in results
    ]


RESULT_KEYS = {"estimator", "sensors", "split", "clips"}
RESULTS_LIMIT = 256 << 20  # bytes: a results file of every CMU clip is a few MB


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
    return isinstance(data, list) and bool(data) and all(isinstance(r, dict) and r.keys() >= RESULT_KEYS for r in data)


def check_results_path(path: Path) -> Path:
    """Refuse, before any evaluation, a results path that is not ours to write: an existing
    file other than an earlier results file, a folder, a link, a device; its folder must exist."""
    from .core.file_output import check_target

    return check_target(Path(path), is_results_file, True, "results file")


def write_json(results: list[EvalResult], path: Path, intervals: bool = True) -> None:
    """The results as JSON, written through io/file_output.py: only an earlier results file
    is replaced (each write after a clip replaces the one before)."""
    from .core.file_output import write_file

    text = json.dumps([r.to_json(intervals) for r in results], indent=1, allow_nan=True)
    write_file(path, text, is_results_file, overwrite=True, what="results file")
