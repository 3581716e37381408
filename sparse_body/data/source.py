"""A motion on its source skeleton, as a loader reads it, before retargeting."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import MotionFileError

# A skeleton of more joints is no body (CMU's have 31 to 38, with hands and toes about 70):
# the loaders refuse it while reading the hierarchy, before a frame is parsed.
MAX_JOINTS = 1000


@dataclass
class SourceMotion:
    """Joint positions and rotations of a source skeleton, in the source's axes, in metres.

    A joint's position is where its rotation acts; rotations are global and relative to the
    rest pose (identity at rest), so a child's position is parent + R_parent @ rest offset.
    """

    name: str
    layout: str  # key of the joint map in retarget.py ("cmu_asf", "cmu_bvh", ...)
    joint_names: list[str]
    parents: list[int]
    rest_positions: np.ndarray  # (J, 3)
    positions: np.ndarray  # (T, J, 3)
    rotations: np.ndarray  # (T, J, 3, 3)
    fps: float
    up_axis: int = 1  # index of the source's up axis (CMU data: y)

    def index(self, name: str) -> int:
        return self.joint_names.index(name)


def read_text(path: Path) -> str:
    """The text of a motion file, gzip-compressed (.gz) or plain, within the motion size limit
    (core/textfile.py); bytes that are not UTF-8 are replaced (comments in other encodings)."""
    from ..core.textfile import FileTooLarge, read_limited, too_large

    path = Path(path)
    if not path.is_file():
        raise MotionFileError(path, "no such file")
    try:
        with_replacement = read_limited(path, "motion")
    except UnicodeDecodeError as err:
        with_replacement = err.object.decode("utf-8", errors="replace")
    except FileTooLarge as err:
        raise too_large(MotionFileError)(path, str(err).removeprefix(f"{path}: ")) from None
    except (OSError, EOFError) as err:  # a truncated .gz raises EOFError
        raise MotionFileError(path, f"cannot be read ({err})") from None
    return with_replacement


def stem(path: Path) -> str:
    name = Path(path).name
    for suffix in (".gz", ".amc", ".bvh", ".npz"):
        name = name.removesuffix(suffix)
    return name
