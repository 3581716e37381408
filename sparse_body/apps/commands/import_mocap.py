"""`sparse-body import-mocap`: its arguments (add_parser) and what it runs (run)."""

from __future__ import annotations

import sys
from pathlib import Path


def run(args) -> int:
    from ...data.user_mocap import import_motion

    progress = None
    if not args.quiet:
        from tqdm import tqdm

        progress = lambda files: tqdm(files, desc="reading motion files", unit="file")  # noqa: E731
    clips, skipped = import_motion(args.sources, Path(args.out), progress)
    for path, why in skipped:
        print(f"left out {path}: {why}", file=sys.stderr)
    subjects = len({c.subject for c in clips})
    minutes = sum(c.seconds for c in clips) / 60
    print(
        f"written {args.out}/clips.tsv and split.yaml: {len(clips)} clips of {subjects} subjects, "
        f"{minutes:.1f} minutes ({len(skipped)} files left out)\n"
        f"use it with --mocap {args.out} (or SPARSE_BODY_MOCAP={args.out}): "
        f"sparse-body eval --mocap {args.out} --estimator ik --sensors six_point"
    )
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser(
        "import-mocap",
        help="index a CMU download or any folder of BVH / ASF+AMC files for eval, "
        "train and make-bag --clip (nothing is copied or changed)",
    )
    p.add_argument("sources", nargs="+", help="folders (searched recursively) or motion files")
    p.add_argument("--out", required=True, help="a new folder for clips.tsv and split.yaml")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
