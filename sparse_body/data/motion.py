"""A motion of the 22-joint body: per-frame local rotations and root position."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..core.kinematics import forward_kinematics
from ..core.rotations import quat_to_matrix, slerp_resample
from ..core.skeleton import NUM_JOINTS, Skeleton
from . import MotionFileError


@dataclass
class Motion:
    name: str
    fps: float
    skeleton: Skeleton
    local_quats: np.ndarray  # (T, 22, 4) x y z w, the root's global
    root_positions: np.ndarray  # (T, 3) metres, REP-103
    # the floor's height where it is known (a body laid on a floor we placed); None: a motion
    # capture's own, which the evaluation estimates from the toes (core/contacts.estimate_floor)
    floor: float | None = None

    def __post_init__(self) -> None:
        T = len(self.root_positions)
        if self.local_quats.shape != (T, NUM_JOINTS, 4) or self.root_positions.shape != (T, 3):
            raise ValueError(
                f"motion {self.name}: shapes {self.local_quats.shape} and "
                f"{self.root_positions.shape} do not describe {T} frames of {NUM_JOINTS} joints"
            )

    def __len__(self) -> int:
        return len(self.root_positions)

    @property
    def duration(self) -> float:
        return (len(self) - 1) / self.fps

    @cached_property
    def local_rotations(self) -> np.ndarray:
        return quat_to_matrix(self.local_quats)

    @cached_property
    def _fk(self):
        return forward_kinematics(self.local_rotations, self.root_positions, self.skeleton.offsets)

    @property
    def global_rotations(self) -> np.ndarray:
        """(T, 22, 3, 3)"""
        return self._fk[0]

    @property
    def positions(self) -> np.ndarray:
        """(T, 22, 3) joint positions in metres."""
        return self._fk[1]

    def slice(self, start: int, stop: int) -> Motion:
        return Motion(
            self.name,
            self.fps,
            self.skeleton,
            self.local_quats[start:stop].copy(),
            self.root_positions[start:stop].copy(),
            self.floor,
        )

    def resampled(self, fps: float) -> Motion:
        """The motion at another frame rate: slerp for rotations, linear for the root."""
        if fps <= 0:
            raise ValueError(f"frame rate must be positive, got {fps}")
        if abs(fps - self.fps) < 1e-9 or len(self) < 2:
            return self
        src_t = np.arange(len(self)) / self.fps
        n = int(np.floor(src_t[-1] * fps + 1e-9)) + 1
        dst_t = np.arange(n) / fps
        root = np.stack([np.interp(dst_t, src_t, self.root_positions[:, k]) for k in range(3)], -1)
        quats = slerp_resample(self.local_quats, src_t, dst_t)
        return Motion(self.name, fps, self.skeleton, quats, root, self.floor)

    def save(self, path: Path) -> None:
        np.savez(
            path,
            name=np.array(self.name),
            fps=np.array(self.fps),
            offsets=self.skeleton.offsets,
            local_quats=self.local_quats.astype(np.float32),
            root_positions=self.root_positions,
        )

    @classmethod
    def load(cls, path: Path) -> Motion:
        from ..core.textfile import NPZ_ERRORS, FileTooLarge, open_npz, too_large

        try:
            with open_npz(path) as z:
                return cls(
                    str(z["name"]),
                    float(z["fps"]),
                    Skeleton(z["offsets"]),
                    z["local_quats"].astype(np.float64),
                    z["root_positions"],
                )
        except FileTooLarge as err:
            raise too_large(MotionFileError)(path, str(err).removeprefix(f"{path}: ")) from None
        except NPZ_ERRORS as err:
            raise MotionFileError(path, f"not a sparse_body motion file, or damaged ({err})") from None
