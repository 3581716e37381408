"""Write test/fixtures/cmu: the first seconds of four CMU clips (ASF/AMC), indexed with its own
split, so that the trainers' tests run for anyone (CMU's terms allow it; cited in its README).

    python scripts/make_test_fixtures.py CMU_FOLDER     (an indexed folder: clips.tsv, asfamc/)
"""

from __future__ import annotations

import csv
import gzip
import shutil
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "test" / "fixtures" / "cmu"
# clip -> (seconds kept, split): two train clips of one person (a walk, strikes), a validation
# person's dance (a kind training lacks: the selection), a test person's walk
CLIPS = {"02_01": (3.0, "train"), "02_05": (6.0, "train"), "05_02": (4.0, "validation"), "16_17": (4.5, "test")}


def main(source: Path) -> None:
    with open(source / "clips.tsv", newline="") as f:
        rows = {r["clip"]: r for r in csv.DictReader(f, delimiter="\t")}
    if OUT.exists():
        shutil.rmtree(OUT)
    kept = []
    for clip, (seconds, _) in CLIPS.items():
        row = dict(rows[clip])
        subject = clip.split("_")[0]
        folder = OUT / "asfamc" / "subjects" / subject
        folder.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source / "asfamc" / "subjects" / subject / f"{subject}.asf", folder / f"{subject}.asf")
        frames = min(int(float(row["fps"]) * seconds), int(row["frames"]))
        lines, frame = [], 0
        with gzip.open(source / row["file"], "rt") as f:
            for line in f:
                if line.strip().isdigit():
                    frame = int(line)
                    if frame > frames:
                        break
                lines.append(line)
        with gzip.GzipFile(folder / f"{clip}.amc.gz", "wb", mtime=0) as out:  # the same bytes each run
            out.write("".join(lines).encode())
        row.update(frames=str(frames), last_frame=str(frames), seconds=f"{frames / float(row['fps']):.2f}")
        kept.append(row)
    with open(OUT / "clips.tsv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(kept[0]), delimiter="\t", lineterminator="\n")
        writer.writeheader()
        writer.writerows(kept)
    split = "# the fixtures' own split: one person trains, one validates, one tests\n"
    for part in ("train", "validation", "test"):
        split += f"{part}:\n" + "".join(f'  - "{c}"\n' for c, (_, p) in CLIPS.items() if p == part)
    (OUT / "split.yaml").write_text(split)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
