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

import math
from dataclasses import dataclass

import numpy as np

from .types import TrackerFrame


@dataclass(frozen=True)
class FilterConfig:
    position_noise: float = 0.001  # metres: the trackers' position noise (std per axis); 0: no filter
    rotation_noise: float = 0.33  # degrees: orientation noise (std per axis)
    acceleration: float = 0.5  # m/s^2 / sqrt(Hz): how hard a tracked body part accelerates
    spin_acceleration: float = 1.5  # rad/s^2 / sqrt(Hz), the same for turning
    jump: float = 0.5  # metres: a sample this far from the prediction starts the site over
    gap: float = 0.25  # seconds without a sample after which a site starts over
    # the offline smoother's (core/tracker_smoother.py, estimator option smooth=true): with the
    # future in view there is no lag to trade, so it follows harder accelerations
    smooth_acceleration: float = 0.7
    smooth_spin_acceleration: float = 2.0

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
                raise ValueError(f"filter {name} must be a finite number >= 0, got {value!r}")

    @property
    def enabled(self) -> bool:
        return self.position_noise > 0 or self.rotation_noise > 0


NO_FILTER = FilterConfig(position_noise=0.0, rotation_noise=0.0)
PREFIX = "filter_"  # how estimator options and node parameters name the fields


def filter_config(options: dict) -> FilterConfig:
    """The filter that options ask for, taking them out: filter=false, or filter_<field>
    values over the defaults (estimator options, node parameters)."""
    on = options.pop("filter", True)
    if not isinstance(on, bool):
        raise ValueError(f"filter must be true or false, got {on!r}")
    given = {k.removeprefix(PREFIX): options.pop(k) for k in list(options) if k.startswith(PREFIX)}
    unknown = [PREFIX + k for k in given if k not in FilterConfig.__dataclass_fields__]
    if unknown:
        fields = ", ".join(PREFIX + f for f in FilterConfig.__dataclass_fields__)
        raise ValueError(f"unknown filter option {', '.join(unknown)}; the filter's options are {fields}")
    return FilterConfig(**given) if on else NO_FILTER


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
    """One step of the constant-velocity model's shared 2x2 covariance (p00, p01, p11): the
    prediction by dt (process noise q), the gains (value, rate) of a sample with variance r,
    and the covariance after it. The live filter and the offline smoother both step this way."""
    p00, p01, p11 = p
    a = p00 + 2 * dt * p01 + dt * dt * p11 + q * dt**3 / 3
    b = p01 + dt * p11 + q * dt * dt / 2
    c = p11 + q * dt
    k0, k1 = a / (a + r), b / (a + r)
    return (a, b, c), (k0, k1), ((1 - k0) * a, (1 - k0) * b, c - k1 * b)


class _Track:
    """One site's constant-velocity Kalman state for one quantity (a position or an
    orientation): the value, its rate per axis, the 2x2 covariance the axes share."""

    __slots__ = ("value", "rate", "p00", "p01", "p11", "stamp")

    def __init__(self) -> None:
        self.value, self.stamp = None, -math.inf
        self.p00 = self.p01 = self.p11 = 0.0  # set by start()

    def gains(self, dt: float, q: float, r: float) -> tuple[float, float]:
        """Predict the covariance by dt; the gains (value, rate) of this sample's innovation."""
        _, gains, (self.p00, self.p01, self.p11) = covariance_step((self.p00, self.p01, self.p11), dt, q, r)
        return gains

    def start(self, value, stamp: float, r: float) -> None:
        """From this sample: the value as measured, the rate unknown (zero, wide)."""
        self.value, self.rate, self.stamp = value, (0.0, 0.0, 0.0), stamp
        self.p00, self.p01, self.p11 = r, 0.0, 1e4 * r


class TrackerFilter:
    """Filters the samples of a stream of TrackerFrames, site by site.

    Invalid or non-finite samples pass through untouched and leave the state as it was; a
    site silent for longer than config.gap, a stamp that goes back or a jump of more than
    config.jump starts that site over from its sample."""

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
