"""The parity reference of core/tracker_filter.py's TrackerFilter: the live filter as it was
in plain Python (sparse_body 9209f2c), before its arithmetic was compiled. test_field_protocol
requires the compiled filter to give the same frames within 1e-9; the documentation of the
filter is in core/tracker_filter.py.
"""

from __future__ import annotations

import math

import numpy as np

from sparse_body.core.tracker_filter import FilterConfig
from sparse_body.core.types import TrackerFrame

# Plain floats from here: on 3- and 4-vectors of six trackers numpy's per-call cost is most
# of the work (measured: 0.22 ms a frame vectorised, against the IK step's 0.3).


def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _rotvec_quat(x, y, z):
    angle = math.sqrt(x * x + y * y + z * z)
    scale = math.sin(0.5 * angle) / angle if angle > 1e-9 else 0.5
    return (x * scale, y * scale, z * scale, math.cos(0.5 * angle))


def _quat_rotvec(q):
    x, y, z, w = q if q[3] >= 0 else (-q[0], -q[1], -q[2], -q[3])
    s = math.sqrt(x * x + y * y + z * z)
    scale = 2.0 * math.atan2(s, w) / s if s > 1e-9 else 2.0
    return (x * scale, y * scale, z * scale)


def covariance_step(p: tuple[float, float, float], dt: float, q: float, r: float):
    """As in core/tracker_filter.py."""
    p00, p01, p11 = p
    a = p00 + 2 * dt * p01 + dt * dt * p11 + q * dt**3 / 3
    b = p01 + dt * p11 + q * dt * dt / 2
    c = p11 + q * dt
    k0, k1 = a / (a + r), b / (a + r)
    return (a, b, c), (k0, k1), ((1 - k0) * a, (1 - k0) * b, c - k1 * b)


class _Track:
    """As in core/tracker_filter.py."""

    __slots__ = ("value", "rate", "p00", "p01", "p11", "stamp")

    def __init__(self) -> None:
        self.value, self.stamp = None, -math.inf
        self.p00 = self.p01 = self.p11 = 0.0  # set by start()

    def gains(self, dt: float, q: float, r: float) -> tuple[float, float]:
        """As in core/tracker_filter.py."""
        _, gains, (self.p00, self.p01, self.p11) = covariance_step((self.p00, self.p01, self.p11), dt, q, r)
        return gains

    def start(self, value, stamp: float, r: float) -> None:
        """As in core/tracker_filter.py."""
        self.value, self.rate, self.stamp = value, (0.0, 0.0, 0.0), stamp
        self.p00, self.p01, self.p11 = r, 0.0, 1e4 * r


class TrackerFilter:
    """As in core/tracker_filter.py."""

    def __init__(self, config: FilterConfig, sites: tuple[str, ...]) -> None:
        self.config = config
        self.sites = tuple(sites)
        c = config
        self._pos_r, self._pos_q = max(c.position_noise, 1e-9) ** 2, c.acceleration**2
        self._rot_r, self._rot_q = max(math.radians(c.rotation_noise), 1e-9) ** 2, c.spin_acceleration**2
        self.reset()

    def reset(self) -> None:
        self._pos = [_Track() for _ in self.sites]
        self._rot = [_Track() for _ in self.sites]

    def __call__(self, frame: TrackerFrame) -> TrackerFrame:
        c = self.config
        if not c.enabled:
            return frame
        if tuple(frame.sites) != self.sites:  # another site set: filter it on its own terms
            self.sites = tuple(frame.sites)
            self.reset()
        positions = np.array(frame.positions, dtype=float)
        orientations = np.array(frame.orientations, dtype=float)
        valid = frame.valid.tolist()
        stamp = float(frame.stamp)
        for i, (p, q) in enumerate(zip(positions.tolist(), orientations.tolist(), strict=True)):
            if not valid[i]:
                continue
            if c.position_noise > 0 and math.isfinite(p[0] + p[1] + p[2]):
                positions[i] = self._position(self._pos[i], p, stamp)
            n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
            if c.rotation_noise > 0 and math.isfinite(n2) and 0.81 < n2 < 1.21:
                n = math.sqrt(n2)
                orientations[i] = self._orientation(self._rot[i], (q[0] / n, q[1] / n, q[2] / n, q[3] / n), stamp)
        return TrackerFrame(frame.stamp, frame.sites, positions, orientations, frame.valid)

    def _position(self, t: _Track, z, stamp: float):
        dt = stamp - t.stamp
        if t.value is not None and 0 < dt <= self.config.gap:
            x, v = t.value, t.rate
            pred = (x[0] + v[0] * dt, x[1] + v[1] * dt, x[2] + v[2] * dt)
            e = (z[0] - pred[0], z[1] - pred[1], z[2] - pred[2])
            if e[0] * e[0] + e[1] * e[1] + e[2] * e[2] <= self.config.jump**2:
                k0, k1 = t.gains(dt, self._pos_q, self._pos_r)
                t.value = (pred[0] + k0 * e[0], pred[1] + k0 * e[1], pred[2] + k0 * e[2])
                t.rate = (v[0] + k1 * e[0], v[1] + k1 * e[1], v[2] + k1 * e[2])
                t.stamp = stamp
                return t.value
        t.start(tuple(z), stamp, self._pos_r)
        return t.value

    def _orientation(self, t: _Track, z, stamp: float):
        dt = stamp - t.stamp
        if t.value is None or not 0 < dt <= self.config.gap:
            t.start(z, stamp, self._rot_r)
            return z
        w = t.rate
        pred = _qmul(_rotvec_quat(w[0] * dt, w[1] * dt, w[2] * dt), t.value)
        e = _quat_rotvec(_qmul(z, (-pred[0], -pred[1], -pred[2], pred[3])))  # world-frame rotation vector
        k0, k1 = t.gains(dt, self._rot_q, self._rot_r)
        x, y, zz, ww = _qmul(_rotvec_quat(k0 * e[0], k0 * e[1], k0 * e[2]), pred)
        n = math.sqrt(x * x + y * y + zz * zz + ww * ww)
        t.value = (x / n, y / n, zz / n, ww / n)
        t.rate = (w[0] + k1 * e[0], w[1] + k1 * e[1], w[2] + k1 * e[2])
        t.stamp = stamp
        return t.value
