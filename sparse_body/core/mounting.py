"""Mounting translations from movement: where on its segment each tracker really sits.

A tracker rigid on a body segment is at p(t) = x(t) + R(t) m: x the segment's joint, R the
joint's orientation (the tracker's, its T-pose rotation offset undone) and m the mounting
translation in the joint's frame. While the segment turns about its joint and the joint
stays put (a head turned, a wrist or an ankle circled, the hips rolled), p(t) - R(t) m is
constant: m is the translation that makes it so, a linear least squares (the pivot
calibration of tracked tools, here a sensor-to-segment calibration).

No one holds a joint still, and a tracker is also carried when another joint turns (the
hand when the hips roll). So the movement is cut into short windows, each fitted about its
own mean and trend (a joint drifting steadily within one, a slow sway, drops out), and a
window counts only when its segment turned enough to say something, its pivot stayed put (a
small residual) and its translation is one a strap could have (within MAX_SHIFT of the
configuration's: a tracker carried about another joint fits a pivot there, tens of
centimetres away). The counted windows are solved
together; what no window turned about (the component along the only axis a segment turned
about) keeps the configuration's value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

WINDOW_SECONDS = 1.0  # short enough that a joint barely drifts, long enough for half a turn
MIN_TURN_DEG = 5.0  # a window whose segment turned less (rms) says nothing about m
MAX_RESIDUAL = 0.01  # metres rms: more, and the pivot moved within the window
MAX_SHIFT = 0.10  # metres from the configuration's translation: further is another joint's pivot
PRIOR_WEIGHT = 1e-4  # per frame, pulls an unobserved component to the configuration's value


class MountingError(ValueError):
    pass


@dataclass(frozen=True)
class MountingFit:
    """One tracker's mounting translation found from movement."""

    translation: np.ndarray  # (3,) metres, in its joint's frame
    nominal: np.ndarray  # (3,) the configuration's
    windows: int  # windows that counted
    turn_deg: float  # rms turn about the least turned axis, over the counted windows
    residual: float  # metres rms of p - R m about each window's pivot

    @property
    def shift(self) -> np.ndarray:
        return self.translation - self.nominal


def _windows(times: np.ndarray, seconds: float) -> list[np.ndarray]:
    """Frame indices of overlapping windows (half a window apart)."""
    if len(times) < 2:
        return []
    starts = np.arange(times[0], max(times[-1] - seconds, times[0]) + 1e-9, seconds / 2)
    return [np.flatnonzero((times >= s) & (times < s + seconds)) for s in starts]


def _detrended(times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """values (n, ...) less their least-squares line in time: a pivot drifting steadily is
    one that stays put."""
    t = times - times.mean()
    design = np.stack([np.ones_like(t), t / max(np.abs(t).max(), 1e-9)], axis=1)
    flat = values.reshape(len(values), -1)
    return (flat - design @ np.linalg.lstsq(design, flat, rcond=None)[0]).reshape(values.shape)


def fit_mounting(
    times: np.ndarray,
    positions: np.ndarray,
    quats: np.ndarray,
    nominal: np.ndarray,
    window: float = WINDOW_SECONDS,
) -> MountingFit:
    """The mounting translation of one tracker from samples of free movement.

    times (n,) seconds, positions (n, 3), quats (n, 4) x y z w: the joint's orientation (the
    T-pose calibration applied); nominal (3,): the configuration's translation. Non-finite
    samples are skipped."""
    times, positions, quats = (np.asarray(a, dtype=float) for a in (times, positions, quats))
    nominal = np.asarray(nominal, dtype=float)
    ok = np.all(np.isfinite(positions), axis=1) & np.all(np.isfinite(quats), axis=1) & np.isfinite(times)
    ok[ok] = np.linalg.norm(quats[ok], axis=1) > 0.5
    times, positions, quats = times[ok], positions[ok], quats[ok]
    order = np.argsort(times, kind="stable")
    times, positions = times[order], positions[order]
    rotations = Rotation.from_quat(quats[order]).as_matrix() if len(order) else np.zeros((0, 3, 3))
    min_turn = np.deg2rad(MIN_TURN_DEG)
    A, b, frames, residuals = np.zeros((3, 3)), np.zeros(3), 0, []
    for idx in _windows(times, window):
        if len(idx) < 10:
            continue
        # each window's trend over its samples in the order received, not their stamps: a starved
        # machine stamps samples late and in bursts (many at one instant after a stall), which
        # bent the trend; the movement advances with the samples
        received = np.arange(len(idx), dtype=float)
        dp, dr = _detrended(received, positions[idx]), _detrended(received, rotations[idx])
        Aw, bw = np.einsum("tki,tkj->ij", dr, dr), np.einsum("tki,tk->i", dr, dp)
        if np.sqrt(np.linalg.eigvalsh(Aw)[-1] / len(idx)) < min_turn:
            continue  # the segment held still: nothing to learn
        prior = PRIOR_WEIGHT * len(idx) * np.eye(3)
        m = nominal + np.linalg.solve(Aw + prior, bw - Aw @ nominal)
        residual = float(np.sqrt(np.mean(np.sum((dp - dr @ m) ** 2, axis=1))))
        if residual > MAX_RESIDUAL or np.linalg.norm(m - nominal) > MAX_SHIFT:
            continue  # its pivot moved, or it was carried about another joint
        A, b, frames = A + Aw, b + bw, frames + len(idx)
        residuals.append(residual)
    if not frames:
        return MountingFit(nominal.copy(), nominal.copy(), 0, 0.0, float("nan"))
    m = nominal + np.linalg.solve(A + PRIOR_WEIGHT * frames * np.eye(3), b - A @ nominal)
    turn = float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(A)[0], 0.0) / frames)))
    return MountingFit(m, nominal.copy(), len(residuals), turn, float(np.sqrt(np.mean(np.square(residuals)))))
