"""The CMU collection (allasfamc.zip from mocap.cs.cmu.edu, indexed by `sparse-body
import-mocap`): its clip index, the train/validation/test split, and a cache of retargeted
clips so that only the first load parses the text files."""

from __future__ import annotations

import csv
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.resources import config_dir
from ..core.textfile import load_yaml, read_limited
from . import MotionFileError
from .asf_amc import load_amc, load_asf, skeleton_for
from .bvh import load_bvh
from .motion import Motion
from .retarget import retarget


class MocapFolderError(ValueError):
    """A motion capture folder that is not an indexed one, or lacks clips its split names."""


DEMO_CLIP = "17_10"  # boxing, from the test split: a person no model trained on (the demo's, bench's)
DEFAULT_FPS = 60.0
# Bump when loading or retargeting changes, so stale cache entries are not used.
CACHE_VERSION = 3  # 3: absurd values refused at load (a cached motion of 2 may hold them)
SPLITS = ("train", "validation", "test")
# the validation clips whose kind of motion no train clip has: every accuracy choice is made
# on them (the person-disjoint split alone lets a choice win on motion like training's)
SELECTION = "selection"
# the selection's clips with the body lying on the floor (data/floor.py): poses off the feet,
# which training barely holds, measured as kinds of their own
FLOOR = "floor"
PARTS = (*SPLITS, SELECTION, FLOOR)

# Kinds of motion finer than the index's categories where one category holds kinds a model
# meets apart: CMU's "other" is ladder climbing and a motorcycle in training, cartwheels,
# acrobatics and one-leg balances in validation. The first word found in the description
# names the kind; a clip of any other category is of its category's kind.
OTHER_KINDS = (
    ("cartwheel", "acrobatics"),
    ("acrobatics", "acrobatics"),
    ("balance", "balance"),
    ("ladder", "climbing"),
    ("climb", "climbing"),
    ("motorcycle", "motorcycle"),
    ("range of motion", "range_of_motion"),
)


@dataclass(frozen=True)
class Clip:
    clip_id: str
    path: Path  # the motion file
    format: str  # "asf/amc", or "bvh-mb2", "bvh-daz", "bvh-max"
    fps: float
    category: str
    description: str
    seconds: float = 0.0

    @property
    def subject(self) -> str:
        """The CMU subject number: the part of the clip id before the take ("16" of "16_05")."""
        return self.clip_id.split("_")[0]

    @property
    def kind(self) -> str:
        """The kind of motion: the category, or for "other" the first of OTHER_KINDS its
        description names."""
        if self.category != "other":
            return self.category
        words = self.description.lower()
        return next((kind for word, kind in OTHER_KINDS if word in words), "other")

    @property
    def skeleton_path(self) -> Path | None:
        if self.format != "asf/amc":
            return None
        subject = self.path.parent
        return subject / f"{subject.name}.asf"


def find_mocap_root(explicit: str | os.PathLike | None = None) -> Path | None:
    """The indexed CMU folder (`sparse-body import-mocap` of CMU's allasfamc.zip): explicit
    path, $SPARSE_BODY_MOCAP, or the maintainers' data folder beside the checkout or the
    working directory. None when none exists."""
    candidates: list[str | os.PathLike | None]
    if explicit:
        candidates = [explicit]
    else:
        here = Path(__file__).resolve().parents[2]
        candidates = [
            os.environ.get("SPARSE_BODY_MOCAP"),
            here.parent / "shared" / "mocap" / "cmu",
            Path.cwd().parent / "shared" / "mocap" / "cmu",
        ]
    for c in candidates:
        if c and (Path(c) / "clips.tsv").is_file():
            return Path(c)
        if c and (Path(c) / "cmu" / "clips.tsv").is_file():
            return Path(c) / "cmu"
    if explicit:
        raise MocapFolderError(
            f"{explicit}: no clips.tsv there; index a motion capture folder first "
            f"(`sparse-body import-mocap FOLDER --out DIR`, then --mocap DIR)"
        )
    return None


def read_index(root: Path) -> list[Clip]:
    path = Path(root) / "clips.tsv"
    clips = []
    with open(path, newline="") as f:
        for n, row in enumerate(csv.DictReader(f, delimiter="\t"), 2):
            try:
                clips.append(
                    Clip(
                        row["clip"],
                        Path(root) / row["file"],
                        row["format"],
                        float(row["fps"]),
                        row["category"],
                        row["description"],
                        float(row.get("seconds") or 0.0),
                    )
                )
            except (KeyError, ValueError, TypeError) as err:
                raise MotionFileError(path, f"line {n}: malformed row ({err})") from None
    return clips


def split_path(mocap_root: Path | None = None) -> Path:
    """The split of a motion folder: its own split.yaml (`sparse-body import-mocap` writes
    one), else the package's split of the CMU collection."""
    if mocap_root is not None and (Path(mocap_root) / "split.yaml").is_file():
        return Path(mocap_root) / "split.yaml"
    return config_dir() / "splits" / "cmu.yaml"


# Shares of the recorded time the held-out parts are filled to (and may not pass).
HELD_OUT_SHARE, HELD_OUT_CAP = 0.10, 0.15


def compute_split(clips: list[Clip]) -> dict[str, list[str]]:
    """Deterministic split by subject: no test or validation subject has a take in training.

    Subjects are taken in the order of their number's SHA-1; each goes to the test part, else
    the validation part, while that part holds under 10 % of the recorded time and would stay
    within 15 % with it; the rest train. A subject's size decides nothing but whether it fits,
    so the held-out people are as arbitrary as a clip-wise hash would make them."""
    seconds: dict[str, float] = {}
    for c in clips:
        seconds[c.subject] = seconds.get(c.subject, 0.0) + c.seconds
    total = sum(seconds.values())
    held: dict[str, list[str]] = {"test": [], "validation": []}
    filled = {"test": 0.0, "validation": 0.0}
    for subject in sorted(seconds, key=lambda s: hashlib.sha1(s.encode()).hexdigest()):
        for part in held:
            if filled[part] < HELD_OUT_SHARE * total and filled[part] + seconds[subject] <= HELD_OUT_CAP * total:
                held[part].append(subject)
                filled[part] += seconds[subject]
                break
    parts: dict[str, list[str]] = {s: [] for s in SPLITS}
    for c in sorted(clips, key=lambda c: c.clip_id):
        part = next((p for p, subjects in held.items() if c.subject in subjects), "train")
        parts[part].append(c.clip_id)
    return parts


def split_yaml(parts: dict[str, list[str]], header: str) -> str:
    """A split as the YAML load_split reads, after a comment header (one '# ' line each)."""
    text = "".join(f"# {line}\n" for line in header.splitlines())
    for part in SPLITS:  # quoted: YAML 1.1 would read 08_01 as a number
        text += f"{part}:\n" + "".join(f'  - "{c}"\n' for c in parts[part])
    return text


def load_split(path: Path | None = None) -> dict[str, list[str]]:
    path = Path(path or split_path())
    data = load_yaml(read_limited(path, "yaml"))
    if not isinstance(data, dict) or not all(isinstance(data.get(s), list) for s in SPLITS):
        raise ValueError(f"{path}: a split file needs the lists {', '.join(SPLITS)}")
    return {s: [str(c) for c in data[s]] for s in SPLITS}


def split_clips(mocap_root: Path, split: str, limit: int | None = None) -> list[Clip]:
    """The clips of one part of the committed split, in its order (only the first `limit`);
    "selection": the validation clips of the kinds of motion no train clip has."""
    index = {c.clip_id: c for c in read_index(mocap_root)}
    parts = load_split(split_path(mocap_root))
    if split == SELECTION:
        trained = {index[c].kind for c in parts["train"] if c in index}
        wanted = [c for c in parts["validation"] if c in index and index[c].kind not in trained]
    else:
        wanted = parts[split]
    missing = [c for c in wanted if c not in index]
    if missing:
        raise MocapFolderError(f"{mocap_root}: clips of the {split} split are missing: {', '.join(missing[:5])}")
    return [index[c] for c in (wanted[:limit] if limit else wanted)]


def cache_dir() -> Path:
    return Path(os.environ.get("SPARSE_BODY_CACHE", Path.home() / ".cache" / "sparse_body"))


def _cache_file(clip: Clip, fps: float) -> Path:
    st = clip.path.stat()
    key = f"{CACHE_VERSION}:{clip.path.resolve()}:{st.st_size}:{st.st_mtime_ns}:{fps}"
    digest = hashlib.sha1(key.encode()).hexdigest()[:16]
    return cache_dir() / "motions" / f"{clip.clip_id}-{digest}.npz"


def load_clip(clip: Clip, fps: float = DEFAULT_FPS, use_cache: bool = True) -> Motion:
    """A clip retargeted onto the 22-joint body at fps, from the cache when it is there."""

    def parse() -> Motion:
        if clip.format == "file":  # a user's file (import-mocap): its skeleton found beside it
            return load_motion_file(clip.path, fps)
        if clip.format == "asf/amc" and (asf := clip.skeleton_path) is not None:
            return retarget(load_amc(clip.path, load_asf(asf), fps=clip.fps), fps)
        if clip.format.startswith("bvh"):
            return retarget(load_bvh(clip.path), fps)
        raise MotionFileError(clip.path, f"unknown format {clip.format!r}")

    return cached_motion(_cache_file(clip, fps) if use_cache else None, parse, clip.clip_id)


def cached_motion(cached: Path | None, parse, name: str) -> Motion:
    """The motion in the cache file `cached`, else parse() stored there (None: no cache)."""
    if cached is not None and cached.is_file():
        try:
            return Motion.load(cached)
        except MotionFileError:
            cached.unlink(missing_ok=True)  # a half-written entry: parse again
    motion = parse()
    # Exactly what the cache holds (float32 quaternions), so a clip gives bit-identical results
    # parsed or cached: the latent optimiser's accept/refuse decisions grow 1e-7 differences
    # into metric changes of a few hundredths (seen as two evaluations of one configuration).
    motion = Motion(
        name,
        motion.fps,
        motion.skeleton,
        motion.local_quats.astype(np.float32).astype(np.float64),
        motion.root_positions,
    )
    if cached is not None:
        cached.parent.mkdir(parents=True, exist_ok=True)
        # a name of this process's own: two trainers filling the cache at once must not
        # move each other's half-written files
        tmp = cached.with_name(f"{cached.stem}.{os.getpid()}.tmp.npz")
        try:
            motion.save(tmp)
            os.replace(tmp, cached)
        finally:
            tmp.unlink(missing_ok=True)
    return motion


MOTION_SUFFIXES = (".bvh", ".amc", ".npz")


# metres: no capture volume is near this; a value beyond (1e308 in a file) is not a motion
MAX_COORDINATE = 1e5


def _retargeted(path: Path, source, fps: float) -> Motion:
    import warnings

    if not all(
        np.all(np.isfinite(v)) and np.all(np.abs(v) <= MAX_COORDINATE * 100)  # (cm and other units)
        for v in (source.positions, source.rest_positions)
    ):
        raise MotionFileError(
            path, f"holds positions that are not finite or beyond {MAX_COORDINATE:g} m (an overflow, or not a motion)"
        )
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # overflow of absurd values, refused below
            motion = retarget(source, fps)
    except ValueError as err:  # a skeleton layout with no joint map: say which file
        raise MotionFileError(path, str(err)) from None
    values = (motion.root_positions, motion.local_quats, motion.skeleton.offsets)
    if not all(np.all(np.isfinite(v)) and np.all(np.abs(v) <= MAX_COORDINATE) for v in values):
        raise MotionFileError(
            path, f"holds values that are not finite or beyond {MAX_COORDINATE:g} m (an overflow, or not a motion)"
        )
    return motion


def load_motion_file(
    path: Path, fps: float = DEFAULT_FPS, skeleton: Path | None = None, amc_fps: float = 120.0
) -> Motion:
    """Any supported motion file: .bvh, .amc (captured at amc_fps, with its .asf: given, or
    found beside it by the rule of asf_amc.skeleton_for), AMASS .npz (needs an SMPL
    model, see amass.py) or a sparse_body motion .npz."""
    path = Path(path)
    name = path.name.lower().removesuffix(".gz")  # .AMC, .BVH: the same formats
    if name.endswith(".bvh"):
        return _retargeted(path, load_bvh(path), fps)
    if name.endswith(".amc"):
        if skeleton is None:
            skeleton, _ = skeleton_for(path)
        return _retargeted(path, load_amc(path, load_asf(skeleton), fps=amc_fps), fps)
    if name.endswith(".npz"):
        import numpy as np

        from ..core.textfile import NPZ_ERRORS

        try:
            with np.load(path, allow_pickle=False) as z:  # the directory only: no member is read
                keys = set(z.files)
        except NPZ_ERRORS as err:
            raise MotionFileError(path, f"not a readable .npz ({err})") from None
        if {"local_quats", "root_positions"} <= keys:
            return Motion.load(path).resampled(fps)
        raise MotionFileError(path, "an AMASS .npz needs the SMPL model: use sparse_body.data.amass.load_amass")
    raise MotionFileError(path, "unknown motion format (expected .bvh, .amc, .npz, optionally .gz)")
