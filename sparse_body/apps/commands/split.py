"""`sparse-body split`: its arguments (add_parser) and what it runs (run)."""

from __future__ import annotations

import sys

from .common import mocap_root


def run(args) -> int:
    from ...data.catalog import compute_split, read_index, split_path, split_yaml

    clips = read_index(mocap_root(args))
    parts = compute_split(clips)
    subjects = {part: sorted({cid.split("_")[0] for cid in ids}, key=int) for part, ids in parts.items()}
    text = split_yaml(
        parts,
        "Train / validation / test split of the CMU motion capture clips, by subject: no\n"
        "test or validation subject has a take in training, so the test figures are those of\n"
        "people the models never saw. Written by `sparse-body split --write` (the rule is in\n"
        "sparse_body/data/catalog.py: compute_split). Every estimator trains and evaluates on it.\n"
        + "".join(f"{part} subjects: {', '.join(s)}\n" for part, s in subjects.items()),
    )
    if args.write:
        split_path().write_text(text)
        print(f"written {split_path()}")
    else:
        print(text)
    for part, ids in parts.items():
        print(f"{part}: {len(ids)} clips", file=sys.stderr)
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("split", help="compute the CMU train/validation/test split (by subject)")
    p.add_argument("--write", action="store_true", help="write config/splits/cmu.yaml")
    p.add_argument("--mocap", help="the CMU folder")
    p.set_defaults(func=run)
