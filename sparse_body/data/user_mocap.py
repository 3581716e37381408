"""A user's own motion capture in the layout `eval`, `train` and `make-bag --clip` read: a
folder with clips.tsv (one row per motion file, naming it where it lies: nothing is copied or
changed) and split.yaml (train / validation / test by subject, the rule of compute_split).

A CMU download unpacks as subjects/NN/NN.asf with NN_MM.amc beside it; the clip ids are then
CMU's (subject NN). Any other folder of BVH or ASF/AMC files works too: a file's subject is
its folder's name, so keep each person's takes in a folder of their own."""

from __future__ import annotations

import csv
import re
from pathlib import Path

from . import MotionFileError
from .catalog import DEFAULT_FPS, MOTION_SUFFIXES, Clip, compute_split, load_motion_file, split_yaml
from .motion_inputs import AMC_FPS

INDEX_COLUMNS = ("file", "clip", "format", "fps", "frames", "seconds", "category", "description")
CMU_NAME = re.compile(r"^(\d+)_(\d+)$")


def _clip_id(path: Path, stem: str) -> str:
    """CMU's own id for NN_MM files; else SUBJECT_STEM with the folder as the subject."""
    if CMU_NAME.match(stem):
        return stem
    subject = re.sub(r"[^0-9A-Za-z]+", "", path.parent.name) or "subject"
    return f"{subject}_{re.sub(r'[^0-9A-Za-z.-]+', '-', stem)}"


def find_motion_files(sources) -> list[Path]:
    """Every BVH and AMC file (optionally .gz) under the folders or among the files given."""
    found = []
    for source in map(Path, sources):
        if not source.exists():
            raise MotionFileError(source, "no such file or folder")
        candidates = sorted(source.rglob("*")) if source.is_dir() else [source]
        found += [
            p for p in candidates if p.is_file() and p.name.lower().removesuffix(".gz").endswith(MOTION_SUFFIXES[:2])
        ]
    if not found:
        raise MotionFileError(Path(", ".join(map(str, sources))), "no .bvh or .amc files there")
    return found


def import_motion(sources, out: Path, progress=None) -> tuple[list[Clip], list[tuple[Path, str]]]:
    """Index the motion files under sources into a new folder out; returns the clips and the
    files left out with the reason (unreadable, an unknown skeleton layout)."""
    from ..io.bagio import OutputError

    out = Path(out)
    if out.is_symlink() or (out.exists() and (not out.is_dir() or any(out.iterdir()))):
        raise OutputError(f"{out}: exists and is not an empty folder; choose a new one")
    if not out.absolute().parent.is_dir():
        raise OutputError(f"{out}: {out.absolute().parent} is not an existing folder")
    clips, skipped, seen = [], [], set()
    files = find_motion_files(sources)
    for path in progress(files) if progress else files:
        stem = path.name.removesuffix(".gz").rsplit(".", 1)[0]
        clip_id = _clip_id(path, stem)
        if clip_id in seen:
            skipped.append((path, f"a second file with the clip id {clip_id}"))
            continue
        is_amc = path.name.lower().removesuffix(".gz").endswith(".amc")
        try:
            motion = load_motion_file(path, DEFAULT_FPS)
        except (MotionFileError, ValueError, OSError) as err:
            skipped.append((path, " ".join(str(err).split())))
            continue
        seen.add(clip_id)
        seconds = len(motion) / motion.fps
        clips.append(
            Clip(
                clip_id,
                path.resolve(),
                "file",
                AMC_FPS if is_amc else motion.fps,
                "unknown",
                str(path),
                round(seconds, 2),
            )
        )
    if not clips:
        raise MotionFileError(
            Path(", ".join(map(str, sources))),
            "no readable motion file: " + "; ".join(f"{p.name}: {why}" for p, why in skipped[:3]),
        )
    out.mkdir(exist_ok=True)
    with open(out / "clips.tsv", "w", newline="") as f:
        writer = csv.writer(f, delimiter="\t", lineterminator="\n")
        writer.writerow(INDEX_COLUMNS)
        for c in clips:
            writer.writerow(
                [
                    str(c.path),
                    c.clip_id,
                    c.format,
                    f"{c.fps:g}",
                    round(c.seconds * c.fps),
                    f"{c.seconds:g}",
                    c.category,
                    c.description,
                ]
            )
    parts = compute_split(clips)
    text = split_yaml(
        parts,
        "Train / validation / test split by subject of the clips in clips.tsv (written by\n"
        "`sparse-body import-mocap`; the rule is sparse_body/data/catalog.py: compute_split)",
    )
    (out / "split.yaml").write_text(text)
    return clips, skipped
