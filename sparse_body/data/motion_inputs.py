"""A user's motion files for `eval --motion`: which files, the ASF skeleton of each AMC file,
the group (folder or name prefix) each belongs to, a seed from its identity, and a parse
cache keyed by content. (The ASF of an AMC file is found by asf_amc.skeleton_for, which the
loader uses too; its rule is here.)

Distributions lay ASF/AMC out in two ways: CMU's, a folder per actor with its one ASF
(16/16.asf beside 16_05.amc), and by motion class, a folder per class holding every actor's
ASF beside the AMC files (walk/actorA.asf, walk/actorB.asf, walk/actorA_walk01.AMC). The
skeleton of an AMC file is, in this order: the one paired with it on the command line
(AMC=ASF); --skeleton-file; the ASF beside it whose name is the longest prefix of the AMC
file's name (case ignored); the only ASF beside it. Anything else is an error that lists the
ASFs found and states the rule.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import MotionFileError
from .asf_amc import plain_name, skeleton_for
from .catalog import CACHE_VERSION, MOTION_SUFFIXES, cache_dir, cached_motion, load_motion_file
from .motion import Motion

AMC_FPS = 120.0  # an AMC file names no rate; CMU's and most labs' systems capture at 120 Hz
GROUP_BY = ("folder", "prefix", "none")
# The lowest foot joint (ankle or ball) of a standing person is a few centimetres above the
# floor (CMU: 2-7 cm in 5 % of frames, the median 3-7 cm). Outside these bounds the skeleton
# does not fit the motion: another actor's bones, or another length unit.
FEET_BELOW_FLOOR, FEET_ABOVE_FLOOR = -0.03, 0.25  # metres: median below / 5th percentile above


@dataclass(frozen=True)
class MotionInput:
    path: Path
    skeleton: Path | None = None  # the ASF of an AMC file
    how: str = ""  # how the skeleton was chosen (said in the results)
    group: str = ""

    @property
    def is_amc(self) -> bool:
        return plain_name(self.path).endswith(".amc")


def _is_motion(path: Path) -> bool:
    return path.is_file() and not path.name.startswith(".") and plain_name(path).endswith(MOTION_SUFFIXES)


def _group(path: Path, root: Path | None, group_by: str) -> str:
    if group_by == "prefix":
        stem = path.name.removesuffix(".gz").rsplit(".", 1)[0]
        return re.split(r"[_\- .]", stem, maxsplit=1)[0] or stem
    if group_by == "folder":
        if root is not None and path.parent != root:
            return path.parent.relative_to(root).as_posix()
        return path.parent.name or "."
    return ""


def find_inputs(specs, skeleton_file: str | None = None, group_by: str = "folder") -> list[MotionInput]:
    """The motion files of --motion arguments: a file, a folder (searched recursively; hidden
    and other files are left out) or AMC=ASF. Each AMC file gets its skeleton here, so a
    missing or ambiguous one is said before any work."""
    if group_by not in GROUP_BY:
        raise ValueError(f"group by {group_by!r}: one of {', '.join(GROUP_BY)}")
    given = Path(skeleton_file) if skeleton_file else None
    if given is not None and not given.is_file():
        raise MotionFileError(given, "no such skeleton file")
    out: list[MotionInput] = []
    for spec in map(str, specs):
        pair = None
        if "=" in spec and not Path(spec).exists():
            spec, pair = spec.split("=", 1)
            if not Path(pair).is_file():
                raise MotionFileError(Path(pair), "no such skeleton file (of --motion AMC=ASF)")
        path = Path(spec)
        if path.is_dir():
            files, root = sorted(p for p in path.rglob("*") if _is_motion(p)), path
        elif path.is_file():
            files, root = [path], None
        else:
            raise MotionFileError(path, "no such file or folder")
        if pair is not None and (len(files) != 1 or not plain_name(path).endswith(".amc")):
            raise MotionFileError(path, "AMC=ASF pairs one AMC file with its skeleton")
        for f in files:
            if not plain_name(f).endswith(MOTION_SUFFIXES):
                raise MotionFileError(f, "unknown motion format (expected .bvh, .amc, .npz, optionally .gz)")
            skeleton, how = (
                skeleton_for(f, Path(pair) if pair else given) if plain_name(f).endswith(".amc") else (None, "")
            )
            out.append(MotionInput(f, skeleton, "paired" if pair else how, _group(f, root, group_by)))
    if not out:
        raise MotionFileError(Path(", ".join(map(str, specs))), "no motion files (.bvh, .amc, .npz) there")
    return out


def balanced(inputs: list[MotionInput], limit: int | None) -> list[MotionInput]:
    """The first `limit` inputs taken in turn from each group (in the groups' order), so a
    sample spans every folder or actor instead of the first one only."""
    if not limit or limit >= len(inputs):
        return list(inputs)
    groups: dict[str, list[MotionInput]] = {}
    for inp in inputs:
        groups.setdefault(inp.group, []).append(inp)
    queues = [list(reversed(g)) for _, g in sorted(groups.items())]
    out: list[MotionInput] = []
    while len(out) < limit:
        for q in queues:
            if q and len(out) < limit:
                out.append(q.pop())
    return out


def content_digest(inp: MotionInput) -> str:
    """SHA-1 of what is read: the motion file's bytes and its skeleton's."""
    h = hashlib.sha1()
    for path in (inp.path, inp.skeleton):
        if path is None:
            continue
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
        h.update(b"\0")
    return h.hexdigest()


def identity_seed(name: str, digest: str) -> int:
    """The field protocol's seed of a clip from its name and content: the same draws however
    the file set around it changes."""
    return int(hashlib.sha1(f"{name}\0{digest}".encode()).hexdigest()[:8], 16)


def load_input(
    inp: MotionInput, fps: float, amc_fps: float = AMC_FPS, digest: str | None = None, use_cache: bool = True
) -> Motion:
    """The motion retargeted at fps, from a cache keyed by the content read (so a renamed or
    copied file is not parsed again, and an edited one is)."""
    digest = digest or content_digest(inp)
    key = hashlib.sha1(f"{CACHE_VERSION}:{digest}:{fps}:{amc_fps if inp.is_amc else ''}".encode()).hexdigest()[:20]
    return cached_motion(
        cache_dir() / "motions" / f"file-{key}.npz" if use_cache else None,
        lambda: load_motion_file(inp.path, fps, inp.skeleton, amc_fps),
        inp.path.name,
    )


def implausible(motion: Motion) -> str | None:
    """Why the motion does not look like a person on a floor at height 0, or None: the feet
    through the floor or never near it, as another actor's skeleton or another length unit
    gives (the capture's floor is taken as z = 0, as capture systems calibrate it)."""
    from ..core.skeleton import JOINT_NAMES

    feet = [JOINT_NAMES.index(n) for n in ("left_ankle", "right_ankle", "left_foot", "right_foot")]
    lowest = motion.positions[:, feet, 2].min(axis=1)
    median, low = float(np.median(lowest)), float(np.percentile(lowest, 5))
    if median < FEET_BELOW_FLOOR:
        return f"the feet are {-median * 100:.0f} cm below the floor in half the frames"
    if low > FEET_ABOVE_FLOOR:
        return f"the feet are {low * 100:.0f} cm or more above the floor in 95 % of the frames"
    return None
