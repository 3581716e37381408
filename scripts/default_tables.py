"""The tables behind the default estimator (docs/methods.md, "The default estimator") from their
per-clip runs (docs/default_estimator_runs.json): each set's figure by kind of motion, and its
share of IK's, with the worst kind.

    python scripts/default_tables.py add SET RESULTS [--clips CLIPS.tsv]   # eval results into the runs
    python scripts/default_tables.py show [--metric "Lower PE [cm]"]       # the Markdown tables

`add` keeps each clip's figures and kind (its category, or its row of the clips.tsv of the
folder evaluated) and replaces a run of the same set, estimator and sensors.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

RUNS = Path(__file__).resolve().parent.parent / "docs" / "default_estimator_runs.json"
METRICS = ("MPJPE [cm]", "Lower PE [cm]", "Skate [cm/s]", "Contact acc [%]", "Jitter [100m/s3]")
HEADLINE = {"three_point": "MPJPE [cm]"}  # else "Lower PE [cm]"


def add(runs: dict, set_name: str, results: Path, clips_tsv: Path | None) -> None:
    kinds = {}
    if clips_tsv is not None:
        with open(clips_tsv, newline="") as f:
            kinds = {row["clip"]: row["category"] for row in csv.DictReader(f, delimiter="\t")}
    for result in json.loads(results.read_text()):
        clips = [
            {
                "clip": c["clip"],
                "kind": c.get("category") or kinds.get(c["clip"].split(".")[0], "unknown"),
                "frames": c["frames"],
                **{m: c[m] for m in METRICS if m in c},
            }
            for c in result["clips"]
        ]
        key = (set_name, result["estimator"], result["sensors"])
        runs["runs"] = [r for r in runs["runs"] if (r["set"], r["estimator"], r["sensors"]) != key]
        runs["runs"].append(
            {"set": set_name, "estimator": result["estimator"], "sensors": result["sensors"],
             "protocol": result["protocol"], "clips": clips}
        )  # fmt: skip


def by_kind(run: dict, metric: str) -> dict[str, float]:
    sums: dict[str, list[float]] = {}
    for clip in run["clips"]:
        value = clip.get(metric)
        if value is None or value != value:
            continue
        for kind in (clip["kind"], "all"):
            total = sums.setdefault(kind, [0.0, 0.0])
            total[0] += value * clip["frames"]
            total[1] += clip["frames"]
    return {k: s / n for k, (s, n) in sums.items() if n}


def show(runs: dict, metric: str | None) -> None:
    groups: dict[tuple[str, str], list[dict]] = {}
    for run in runs["runs"]:
        groups.setdefault((run["sensors"], run["set"]), []).append(run)
    for (sensors, set_name), group in groups.items():
        name = metric or HEADLINE.get(sensors, "Lower PE [cm]")
        ik = next((by_kind(r, name) for r in group if r["estimator"] == "ik"), None)
        if ik is None:
            continue
        kinds = sorted(k for k in ik if k != "all")
        print(f"\n{sensors}, {set_name}: {name}, and its share of IK's\n")
        print("| estimator | all | worst kind | " + " | ".join(kinds) + " |")
        print("| --- " * (len(kinds) + 3) + "|")
        for run in sorted(group, key=lambda r: r["estimator"] != "ik"):  # IK first
            table = by_kind(run, name)
            shares = {k: table[k] / ik[k] for k in kinds if k in table}
            worst = max(shares, key=lambda k: shares[k])
            cells = [f"{table[k]:.2f} ({shares[k]:.2f}x)" for k in kinds if k in table]
            print(
                f"| `{run['estimator']}` | {table['all']:.2f} ({table['all'] / ik['all']:.2f}x) | "
                f"{shares[worst]:.2f}x ({worst}) | " + " | ".join(cells) + " |"
            )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    a = sub.add_parser("add", help="eval results into the runs")
    a.add_argument("set", help="the set's name in the tables (selection, floor, cmu-extra ...)")
    a.add_argument("results", type=Path, help="a results file of sparse-body eval")
    a.add_argument("--clips", type=Path, help="the clips.tsv of the folder evaluated, for its kinds")
    s = sub.add_parser("show", help="the Markdown tables")
    s.add_argument("--metric", help="the figure (default: MPJPE three-point, lower-body PE otherwise)")
    args = parser.parse_args(argv)
    runs = json.loads(RUNS.read_text())
    if args.command == "add":
        add(runs, args.set, args.results, args.clips)
        RUNS.write_text(json.dumps(runs, indent=0) + "\n")
    else:
        show(runs, args.metric)


if __name__ == "__main__":
    main()
