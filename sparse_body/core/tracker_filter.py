"""Smoothing of tracker input: a constant-velocity Kalman filter per site, on position and
orientation, set by the tracker system's noise.

Each site carries position and velocity (per axis) and orientation and angular velocity
(an error state: the innovation is the rotation vector from the prediction to the sample);
the three axes share one 2x2 covariance, as the model is the same on each. Two numbers say
how noisy the trackers are (position_noise, rotation_noise: the system's specification), two
how hard a body part accelerates (acceleration, spin_acceleration); from them the filter's
bandwidth follows, about (acceleration / position_noise)^(1/2) rad/s: 3.6 Hz for a VR
system's millimetre, 1.1 Hz for LoBSTr's centimetre. Noisier trackers are smoothed more, on
their own. A constant velocity passes without lag; the cost is lag under acceleration
(a / bandwidth^2: 1 cm at 5 m/s^2 with the defaults) and the overshoot a sudden stop leaves
(the README's tables give what it costs each estimator, measured). The defaults were chosen
on the validation split (six-point IK, field protocol; see the README).

Why not the usual 1-euro filter: measured on the validation split (six-point IK, 1 cm /
1.5 degree noise) it cut the joints' velocity error from 154 to 111 cm/s at best; this filter
gets to 63. The 1-euro's speed-driven cutoff opens on noise as well as on motion, and a
first-order low-pass lags a moving hand by its speed times the time constant.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .types import TrackerFrame


@dataclass(frozen=True)
class FilterConfig:
    position_noise: float = 0.001       # metres: the trackers' position noise (std per axis); 0: no filter
    rotation_noise: float = 0.33        # degrees: orientation noise (std per axis)
    acceleration: float = 0.5           # m/s^2 / sqrt(Hz): how hard a tracked body part accelerates
    spin_acceleration: float = 1.5      # rad/s^2 / sqrt(Hz), the same for turning
    jump: float = 0.5                   # metres: a sample this far from the prediction starts the site over
    gap: float = 0.25                   # seconds without a sample after which a site starts over

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
                raise ValueError(f"filter {name} must be a finite number >= 0, got {value!r}")

    @property
    def enabled(self) -> bool:
        return self.position_noise > 0 or self.rotation_noise > 0


NO_FILTER = FilterConfig(position_noise=0.0, rotation_noise=0.0)


def _quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], -1)


def _rotvec_quat(v: np.ndarray) -> np.ndarray:
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    scale = np.where(angle > 1e-9, np.sin(half) / np.maximum(angle, 1e-12), 0.5)
    return np.concatenate([v * scale, np.cos(half)], -1)


def _quat_rotvec(q: np.ndarray) -> np.ndarray:
    q = np.where(q[..., 3:] < 0, -q, q)
    s = np.linalg.norm(q[..., :3], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., 3:])
    return q[..., :3] * np.where(s > 1e-9, angle / np.maximum(s, 1e-12), 2.0)


class _ConstantVelocity:
    """The steady part of the Kalman filter: a 2x2 covariance per site for value and rate."""

    def __init__(self, n: int, noise: float, accel: float) -> None:
        self.r, self.q = noise ** 2, accel ** 2
        self.P = np.zeros((n, 2, 2))

    def start(self, sites: np.ndarray) -> None:
        self.P[sites] = np.diag([self.r, 1e4 * self.r])   # value as measured, rate unknown

    def gains(self, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predict by dt (per site), then the gains (value, rate) of this sample's innovation."""
        P, q = self.P, self.q
        p00 = P[:, 0, 0] + 2 * dt * P[:, 0, 1] + dt * dt * P[:, 1, 1] + q * dt ** 3 / 3
        p01 = P[:, 0, 1] + dt * P[:, 1, 1] + q * dt ** 2 / 2
        p11 = P[:, 1, 1] + q * dt
        k0, k1 = p00 / (p00 + self.r), p01 / (p00 + self.r)
        self._next = np.stack([np.stack([(1 - k0) * p00, (1 - k0) * p01], -1),
                               np.stack([(1 - k0) * p01, p11 - k1 * p01], -1)], -2)
        return k0, k1

    def settle(self, updated: np.ndarray, fresh: np.ndarray) -> None:
        """Keep the updated sites' covariance; the fresh ones start over."""
        self.P[updated] = self._next[updated]
        self.start(fresh)


def _advance(update, fresh, corrected, sample, value, rate, rate_step):
    """(value, rate) after a sample: updated sites take the correction, fresh ones the sample
    at rest, the others keep theirs."""
    value = np.where(update[:, None], corrected, np.where(fresh[:, None], sample, value))
    rate = np.where(update[:, None], rate + rate_step, np.where(fresh[:, None], 0.0, rate))
    return value, rate


class TrackerFilter:
    """Filters the samples of a stream of TrackerFrames, site by site.

    Invalid or non-finite samples pass through untouched and leave the state as it was; a
    site silent for longer than config.gap, a stamp that goes back or a jump of more than
    config.jump starts that site over from its sample."""

    def __init__(self, config: FilterConfig, sites: tuple[str, ...]) -> None:
        self.config = config
        self.sites = tuple(sites)
        self.reset()

    def reset(self) -> None:
        S, c = len(self.sites), self.config
        self._pos, self._vel = np.zeros((S, 3)), np.zeros((S, 3))
        self._quat, self._spin = np.tile([0.0, 0.0, 0.0, 1.0], (S, 1)), np.zeros((S, 3))
        self._pos_cov = _ConstantVelocity(S, max(c.position_noise, 1e-9), c.acceleration)
        self._rot_cov = _ConstantVelocity(S, max(np.deg2rad(c.rotation_noise), 1e-9), c.spin_acceleration)
        self._pos_stamp = np.full(S, -np.inf)
        self._rot_stamp = np.full(S, -np.inf)

    def __call__(self, frame: TrackerFrame) -> TrackerFrame:
        if not self.config.enabled:
            return frame
        if tuple(frame.sites) != self.sites:       # another site set: filter it on its own terms
            self.sites = tuple(frame.sites)
            self.reset()
        pos = np.asarray(frame.positions, float)
        quat = np.asarray(frame.orientations, float)
        has_pos = frame.valid & np.isfinite(pos).all(axis=1)
        norm = np.linalg.norm(np.where(np.isfinite(quat), quat, 0.0), axis=1)
        has_rot = frame.valid & np.isfinite(quat).all(axis=1) & (np.abs(norm - 1) < 0.1)
        positions, orientations = frame.positions, frame.orientations
        if self.config.position_noise > 0 and has_pos.any():
            positions = np.where(has_pos[:, None], self._positions(frame.stamp, pos, has_pos), frame.positions)
        if self.config.rotation_noise > 0 and has_rot.any():
            unit = quat / np.where(has_rot, norm, 1.0)[:, None]
            orientations = np.where(has_rot[:, None], self._orientations(frame.stamp, unit, has_rot),
                                    frame.orientations)
        return TrackerFrame(frame.stamp, frame.sites, positions, orientations, frame.valid)

    def _fresh(self, stamps: np.ndarray, stamp: float, present: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dt = stamp - stamps
        fresh = present & ~((dt > 0) & (dt <= self.config.gap))
        return fresh, np.where((dt > 0) & np.isfinite(dt), dt, 0.0)

    def _positions(self, stamp: float, pos: np.ndarray, present: np.ndarray) -> np.ndarray:
        fresh, dt = self._fresh(self._pos_stamp, stamp, present)
        predicted = self._pos + self._vel * dt[:, None]
        innovation = pos - predicted
        fresh |= present & (np.linalg.norm(innovation, axis=1) > self.config.jump)
        k0, k1 = self._pos_cov.gains(dt)
        update = present & ~fresh
        self._pos, self._vel = _advance(update, fresh, predicted + k0[:, None] * innovation, pos, self._pos,
                                        self._vel, k1[:, None] * innovation)
        self._pos_cov.settle(update, fresh)
        self._pos_stamp = np.where(present, stamp, self._pos_stamp)
        return self._pos

    def _orientations(self, stamp: float, quat: np.ndarray, present: np.ndarray) -> np.ndarray:
        fresh, dt = self._fresh(self._rot_stamp, stamp, present)
        predicted = _quat_multiply(_rotvec_quat(self._spin * dt[:, None]), self._quat)
        conj = predicted * [-1.0, -1.0, -1.0, 1.0]
        innovation = _quat_rotvec(_quat_multiply(quat, conj))      # world-frame rotation vector
        k0, k1 = self._rot_cov.gains(dt)
        update = present & ~fresh
        corrected = _quat_multiply(_rotvec_quat(k0[:, None] * innovation), predicted)
        corrected /= np.linalg.norm(corrected, axis=1, keepdims=True)
        self._quat, self._spin = _advance(update, fresh, corrected, quat, self._quat, self._spin,
                                          k1[:, None] * innovation)
        self._rot_cov.settle(update, fresh)
        self._rot_stamp = np.where(present, stamp, self._rot_stamp)
        return self._quat
