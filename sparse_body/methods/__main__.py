"""The registry for the Makefile's loops: `python -m sparse_body.methods LIST` prints one
method a line, so that no target names the methods itself.

  eval       NAME SENSORS of each method `make eval` evaluates (its record's eval_sensors)
  trainable  the methods with a trainer (`make cards`)
  benched    the methods with a runtime bench (`make bench`)"""

from __future__ import annotations

import sys

from . import METHODS


def lines(kind: str) -> list[str]:
    if kind == "eval":
        return [f"{name} {m.eval_sensors}" for name, m in METHODS.items() if m.eval_sensors]
    if kind == "trainable":
        return [name for name, m in METHODS.items() if m.training is not None]
    if kind == "benched":
        return [name for name, m in METHODS.items() if m.runtime_bench]
    raise SystemExit(f"python -m sparse_body.methods: choose eval, trainable or benched, not {kind!r}")


if __name__ == "__main__":
    print("\n".join(lines(sys.argv[1] if len(sys.argv) > 1 else "")))
