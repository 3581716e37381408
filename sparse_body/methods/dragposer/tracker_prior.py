"""DragPoser's tracker prior (ours, not the paper's): a GRU that reads the trackers' recent
motion and says which latent the pose probably has, so what the trackers do not pin down (the
legs without feet trackers) follows a learned guess rather than only the last frame's.

Why: the paper's temporal predictor reads only the optimiser's own past latents. Without feet
trackers those latents carry no gait, so on a walking person the legs barely move (on the
validation people DragPoser's four-point lower body was 10-16 cm on walks, LoBSTr's 5-9: the
GRU that reads the trackers' velocities knows the gait). The prior is one more pull on z in
the search, beside the previous frame's latent and the temporal predictor's, so the
constraints still decide whatever the trackers do see.

One model serves every sensor set: each site's block of inputs carries a presence flag, and
training draws the set (three-, four-, six-point) per sequence. A site without a usable
position this frame (missing, dropped, orientation-only) counts as absent.

Input per frame, in the headset's heading frame (z up, x where the head faces on the floor),
lengths on the canonical body (the caller scales by body_scale, floor at z = 0):
for head, hands, pelvis and feet: the joint's position relative to the head's ground point
(x, y) and its height (z), its rotation in 6D, its velocity in m/s (0 on its first sample),
a presence flag: 6 x 13; and the heading's rate (rad/s). 79 values.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...core.rotations import heading, matrix_to_6d, yaw_matrix
from ...estimators.base import full_target
from ...estimators.onnx_model import load_model

FILE = "dragposer_tracker_prior.onnx"
SITES = ("head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")
SITE_FEATURES = 13
FEATURES = len(SITES) * SITE_FEATURES + 1


def sequence_features(
    positions: np.ndarray,
    rotations: np.ndarray,
    present: np.ndarray,
    fps: float,
    last_positions: np.ndarray | None = None,
    last_present: np.ndarray | None = None,
    last_yaw: float | None = None,
) -> np.ndarray:
    """(T, 79) from the SITES' joint positions (T, 6, 3), rotations (T, 6, 3, 3) and presence
    (T, 6). The head must be present in every frame. last_*: the frame before the first
    (streaming: one frame at a time keeps the velocities)."""
    T = len(positions)
    yaw = heading(rotations[:, 0])
    to_head = np.swapaxes(yaw_matrix(yaw), -1, -2)  # (T, 3, 3)
    ground = positions[:, 0].copy()
    ground[:, 2] = 0.0
    rel = np.einsum("tij,tsj->tsi", to_head, positions - ground[:, None])
    rot = matrix_to_6d(to_head[:, None] @ rotations)  # (T, 6, 6)
    prev_pos = np.concatenate([positions[:1] if last_positions is None else last_positions[None], positions[:-1]])
    prev_ok = (
        np.concatenate([np.zeros((1, len(SITES)), bool) if last_present is None else last_present[None], present[:-1]])
        & present
    )
    vel = np.einsum("tij,tsj->tsi", to_head, positions - prev_pos) * fps * prev_ok[..., None]
    prev_yaw = np.concatenate([[yaw[0] if last_yaw is None else last_yaw], yaw[:-1]])
    turn = np.angle(np.exp(1j * (yaw - prev_yaw))) * fps
    site = np.concatenate([rel, rot, vel, np.ones((T, len(SITES), 1))], -1) * present[..., None]
    return np.concatenate([site.reshape(T, -1), turn[:, None]], -1)


class TrackerPrior:
    """The exported GRU step, with its state and the last frame's trackers."""

    def __init__(self, model_dir: str | Path, fps: float, threads: int = 1) -> None:
        self.session, meta = load_model(
            Path(model_dir) / FILE,
            ("part", "tracker_prior"),
            {"features": FEATURES, "state": None},
            "train one with `sparse-body train dragposer --part tracker_prior`, or set tracker_prior to 0",
            threads,
        )
        self.state_shape = meta["state_shape"]
        self.fps = fps
        self.reset()

    def reset(self) -> None:
        self._state = np.zeros(self.state_shape, np.float32)
        self._last: tuple[np.ndarray, np.ndarray, float] | None = (
            None  # (positions, present, yaw) of the previous frame
        )

    def predict(self, targets: dict) -> np.ndarray | None:
        """targets: site -> (position, rotation) of its joint on the canonical body (floor
        at 0), or None. The latent this frame probably has; None (and a fresh start) without
        a headset pose."""
        head = targets.get("head")
        if head is None or head[0] is None or head[1] is None:
            self.reset()
            return None
        positions, rotations = np.zeros((1, len(SITES), 3)), np.tile(np.eye(3), (1, len(SITES), 1, 1))
        present = np.zeros((1, len(SITES)), bool)
        for s, site in enumerate(SITES):
            target = targets.get(site)
            if full_target(target):
                positions[0, s], rotations[0, s], present[0, s] = target[0], target[1], True
        last = self._last or (None, None, None)
        x = sequence_features(positions, rotations, present, self.fps, *last)
        self._last = (positions[0], present[0], float(heading(rotations[0, 0])))
        z, self._state = self.session.run(None, {"features": x.astype(np.float32), "state": self._state})
        return z[0].astype(np.float64)
