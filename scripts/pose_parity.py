"""A digest of every registered estimator's poses on one motion, for a parity check between two
commits (a refactor must leave every pose bit-identical, issue 76).

Usage: .venv/bin/python scripts/pose_parity.py [--seconds 4] --output FILE
Run it on both commits (a git worktree for the other) and compare the files: each line is one
(estimator, sensor configuration) with the SHA-256 of its joint positions and contacts.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path


def main() -> int:
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.data.field_protocol import FIELD
    from sparse_body.data.synthetic import synthetic_walk
    from sparse_body.evaluation import estimate_motion
    from sparse_body.methods import METHODS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument("--output", type=Path, required=True)
    args = parser.parse_args()
    motion = synthetic_walk(args.seconds)
    digests = {}
    for name in [*sorted(METHODS), "auto"]:
        for sensors_name in ("three_point", "four_point", "six_point"):
            try:
                est = estimate_motion(motion, name, load_sensor_config(sensors_name), FIELD, seed=7)
            except ValueError as err:  # a method that cannot run on these sensors
                digests[f"{name} {sensors_name}"] = f"refused: {err}"
                continue
            digest = hashlib.sha256(est.positions.tobytes() + est.contacts.tobytes()).hexdigest()
            digests[f"{name} {sensors_name}"] = digest
            print(name, sensors_name, digest[:16], file=sys.stderr)
    args.output.write_text(json.dumps(digests, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
