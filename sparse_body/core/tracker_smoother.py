"""Offline smoothing of a whole recording of tracker input (`sparse-body process --smooth`,
the estimator option `smooth=true`): the tracker filter's constant-velocity model run forwards
over each site's samples and then backwards (a Rauch-Tung-Striebel smoother), so each sample
is estimated from the samples on both sides of it.

Why: a live filter only has the past, and under a centimetre of noise it must choose between
lag and shake (the README's noise tables). A recording has the future as well. Measured on the
six-point trackers of the test split with LoBSTr's noise (1 cm per axis at 60 Hz,
scripts/noise_floor.py): the best live setting leaves 51.5 cm/s of velocity error (jitter 36),
this smoother with its defaults 22.9 (jitter 1.4).

The smoother uses the filter's noise levels (FilterConfig.position_noise, rotation_noise) and
its own accelerations (smooth_acceleration, smooth_spin_acceleration): a two-sided estimate
has no lag to trade, so it follows harder accelerations best. Orientations are smoothed in the
filter's error state (world-frame rotation vectors about the forward estimate). A site's
samples split into runs where the filter would start over (a gap longer than config.gap, time
going back, a jump of more than config.jump); invalid and non-finite samples pass untouched.
"""

from __future__ import annotations

import math

import numpy as np

from .tracker_filter import FilterConfig, _qmul, _quat_rotvec, _rotvec_quat, covariance_step
from .types import TrackerFrame


def _inverse(q):
    return (-q[0], -q[1], -q[2], q[3])


class _Vector:
    """Positions: plain vectors."""

    @staticmethod
    def usable(value) -> bool:
        """Whether the filter takes this sample (the live filter's test; else it passes untouched)."""
        return bool(np.isfinite(value).all())

    @staticmethod
    def advance(value, rate, dt):
        return value + rate * dt

    @staticmethod
    def plus(value, delta):
        return value + delta

    @staticmethod
    def minus(a, b):
        return a - b


class _Rotation:
    """Orientations (x, y, z, w), moved by world-frame rotation vectors."""

    @staticmethod
    def usable(value) -> bool:
        """Finite and near unit length (the live filter's test)."""
        return bool(np.isfinite(value).all() and 0.81 < value @ value < 1.21)

    @staticmethod
    def advance(value, rate, dt):
        return np.array(_qmul(_rotvec_quat(*(rate * dt)), value))

    @staticmethod
    def plus(value, delta):
        q = np.array(_qmul(_rotvec_quat(*delta), value))
        return q / np.linalg.norm(q)

    @staticmethod
    def minus(a, b):
        return np.array(_quat_rotvec(_qmul(a, _inverse(b))))


def _smooth_run(stamps: np.ndarray, samples: np.ndarray, q: float, r: float, space) -> np.ndarray:
    """The smoothed values of one run of samples (n, 3 or 4)."""
    n = len(stamps)
    values, rates, covs = [samples[0]], [np.zeros(3)], [(r, 0.0, 1e4 * r)]  # as _Track.start
    # (value, rate, covariance) before each sample
    predicted: list[tuple[np.ndarray, np.ndarray, tuple[float, float, float]]] = []
    for k in range(1, n):  # forwards: the live filter's recursion, every state kept
        dt = stamps[k] - stamps[k - 1]
        value, rate = space.advance(values[-1], rates[-1], dt), rates[-1]
        cov, (k0, k1), updated = covariance_step(covs[-1], dt, q, r)
        e = space.minus(samples[k], value)
        predicted.append((value, rate, cov))
        values.append(space.plus(value, k0 * e))
        rates.append(rate + k1 * e)
        covs.append(updated)
    out = [None] * n
    out[-1], rate = values[-1], rates[-1]
    for k in range(n - 2, -1, -1):  # backwards: each state corrected by what came after it
        dt = stamps[k + 1] - stamps[k]
        out[k], rate = rts_step((values[k], rates[k], covs[k]), predicted[k], dt, (out[k + 1], rate), space)
    return np.array(out)


def rts_step(filtered, predicted, dt: float, smoothed_next, space):
    """One backward step of the smoother: a state as the forward filter left it (value, rate,
    covariance), the prediction made from it for the next sample (dt later), and the next
    sample's smoothed (value, rate) -> this sample's smoothed (value, rate)."""
    value, rate, (p00, p01, p11) = filtered
    pred_value, pred_rate, (a, b, c) = predicted
    # C = P F^T inv(P predicted), F = [[1, dt], [0, 1]]
    gain = np.array([[p00 + dt * p01, p01], [p01 + dt * p11, p11]]) @ np.array([[c, -b], [-b, a]]) / (a * c - b * b)
    d_value, d_rate = space.minus(smoothed_next[0], pred_value), smoothed_next[1] - pred_rate
    return (
        space.plus(value, gain[0, 0] * d_value + gain[0, 1] * d_rate),
        rate + gain[1, 0] * d_value + gain[1, 1] * d_rate,
    )


def _runs(stamps: np.ndarray, samples: np.ndarray, config: FilterConfig, jump: bool) -> list[slice]:
    """Where the live filter would start a site over: runs of samples between those places."""
    dt = np.diff(stamps)
    cut = (dt <= 0) | (dt > config.gap)
    if jump:
        cut |= np.linalg.norm(np.diff(samples, axis=0), axis=-1) > config.jump
    edges = [0, *(np.flatnonzero(cut) + 1).tolist(), len(stamps)]
    return [slice(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]


def smooth_frames(frames: list[TrackerFrame], config: FilterConfig) -> list[TrackerFrame]:
    """The frames of a recording with each site's usable samples smoothed (one frame out per
    frame in; what is not smoothed is as it came)."""
    if not config.enabled or not frames:
        return list(frames)
    positions = [np.array(f.positions, dtype=float) for f in frames]
    orientations = [np.array(f.orientations, dtype=float) for f in frames]
    stamps = np.array([f.stamp for f in frames], dtype=float)
    quantities: list[tuple] = []  # (values, sample variance, process noise, space, cut at jumps)
    if config.position_noise > 0:
        quantities.append(
            (
                positions,
                config.position_noise**2,
                config.smooth_acceleration**2,
                _Vector,
                True,
            )
        )
    if config.rotation_noise > 0:
        quantities.append(
            (
                orientations,
                math.radians(config.rotation_noise) ** 2,
                config.smooth_spin_acceleration**2,
                _Rotation,
                False,
            )
        )
    for site in dict.fromkeys(s for f in frames for s in f.sites):
        rows = [(k, f.sites.index(site)) for k, f in enumerate(frames) if site in f.sites]
        rows = [(k, i) for k, i in rows if frames[k].valid[i]]
        for arrays, r, q, space, jump in quantities:
            kept = [(k, s) for k, s in rows if space.usable(arrays[k][s])]
            if len(kept) < 2:
                continue
            times = stamps[[k for k, _ in kept]]
            samples = np.array([arrays[k][s] for k, s in kept])
            if space is _Rotation:
                samples /= np.linalg.norm(samples, axis=-1, keepdims=True)
            for run in _runs(times, samples, config, jump):
                smoothed = _smooth_run(times[run], samples[run], q, r, space)
                for (k, s), value in zip(kept[run], smoothed, strict=True):
                    arrays[k][s] = value
    return [
        TrackerFrame(f.stamp, f.sites, p, o, f.valid) for f, p, o in zip(frames, positions, orientations, strict=True)
    ]
