"""Figures by kind of motion from `sparse-body eval` results: each kind's frame-weighted metric
and its share of the first result's (IK's), the worst kind's share, and all kinds together.

    python scripts/kind_table.py --clips FOLDER/clips.tsv [--metric "Lower PE [cm]"] RESULTS.json ...

Each clip's kind is its category in the clips.tsv of the folder evaluated (the clip's name, its
file name less .amc.gz / .bvh.gz, looked up there); the first results file is the reference.
Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path


def kinds_of(clips_tsv: Path) -> dict[str, str]:
    with open(clips_tsv, newline="") as f:
        return {row["clip"]: row["category"] for row in csv.DictReader(f, delimiter="\t")}


def by_kind(result: dict, kinds: dict[str, str], metric: str) -> dict[str, tuple[float, int]]:
    """kind -> (frame-weighted mean of the metric, frames), and "all"."""
    sums: dict[str, list[float]] = {}
    for clip in result["clips"]:
        name = clip["clip"].split(".")[0]
        value = clip.get(metric)
        if value is None or value != value:  # NaN: the clip has no such figure
            continue
        for kind in (kinds.get(name, "unknown"), "all"):
            total = sums.setdefault(kind, [0.0, 0])
            total[0] += value * clip["frames"]
            total[1] += clip["frames"]
    return {k: (s / n, int(n)) for k, (s, n) in sums.items() if n}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", nargs="+", type=Path, help="eval results files; the first is the reference")
    parser.add_argument("--clips", type=Path, required=True, help="the clips.tsv of the folder evaluated")
    parser.add_argument("--metric", default="Lower PE [cm]", help="the figure compared")
    args = parser.parse_args(argv)
    kinds = kinds_of(args.clips)
    tables = []
    for path in args.results:
        for result in json.loads(path.read_text()):
            tables.append((f"{result['estimator']} ({result['sensors']})", by_kind(result, kinds, args.metric)))
    reference = tables[0][1]
    columns = sorted(k for k in reference if k != "all")
    print(f"{args.metric}, and its share of {tables[0][0]}'s, by kind (frames):")
    print("| estimator | all | worst kind | " + " | ".join(f"{k} ({reference[k][1]})" for k in columns) + " |")
    print("| --- " * (len(columns) + 3) + "|")
    for name, table in tables:
        shares = {k: table[k][0] / reference[k][0] for k in columns if k in table}
        worst = max(shares, key=shares.get) if shares else "-"
        cells = [f"{table[k][0]:.2f} ({shares[k]:.2f}x)" if k in table else "-" for k in columns]
        all_cell = f"{table['all'][0]:.2f} ({table['all'][0] / reference['all'][0]:.2f}x)"
        worst_cell = f"{worst} {shares[worst]:.2f}x" if shares else "-"
        print(f"| {name} | {all_cell} | {worst_cell} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
