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

from .mat3 import njit
from .options import Options, option
from .types import TrackerFrame

MAX_LAG = 0.5  # seconds: past this a live pose is too late to steer anything; offline, use smooth=true


@dataclass(frozen=True)
class FilterConfig(Options):
    """The tracker filter's options: estimator options and node parameters filter_<field>."""

    owner = "filter"
    position_noise: float = option(
        0.001,
        "the trackers' position noise (std per axis) the filter is set for; 0 with rotation_noise 0: no filtering",
        0.0,
        0.1,
        "metres",
    )
    rotation_noise: float = option(0.33, "the trackers' orientation noise (std per axis)", 0.0, 10.0, "degrees")
    acceleration: float = option(
        0.5,
        "how hard a tracked body part accelerates: higher follows faster motion with less lag and smooths less",
        0.01,
        1000.0,
        "m/s^2/sqrt(Hz)",
    )
    spin_acceleration: float = option(1.5, "the same for turning", 0.01, 1000.0, "rad/s^2/sqrt(Hz)")
    jump: float = option(0.5, "a sample this far from the prediction starts the site over", 0.0, 100.0, "metres")
    gap: float = option(0.25, "seconds without a sample after which a site starts over", 0.0, 60.0, "seconds")
    # the offline smoother's (core/tracker_smoother.py, estimator option smooth=true): with the
    # future in view there is no lag to trade, so it follows harder accelerations
    smooth_acceleration: float = option(0.7, "acceleration, for the offline smoother (smooth=true)", 0.01, 1000.0)
    smooth_spin_acceleration: float = option(2.0, "spin_acceleration, for the offline smoother", 0.01, 1000.0)
    # live smoothing (core/fixed_lag.py)
    lag: float = option(
        0.0,
        "latency traded for steadiness: each estimate is of the trackers this long before the newest, smoothed by "
        "the samples since, and stamped with their time; 0: none",
        0.0,
        MAX_LAG,
        "seconds",
    )
    # 2 m/s: of 0.5, 1 and 2, the lowest MPJPE and the shortest settle for every method, with
    # hands lost (validation, docs/methods.md#lost-trackers)
    reacquire_speed: float = option(
        2.0,
        "a tracker that comes back starts where the estimate had its joint and catches up at this speed (no "
        "snap); 0: at once",
        0.0,
        100.0,
        "m/s",
    )
    # 2 s: a controller out of the cameras' view is back within that
    carry_lost: float = option(
        2.0,
        "how long a lost tracker's last pose is carried with the head (position and heading), so the estimate "
        "goes on; 0: a lost tracker is missing",
        0.0,
        10.0,
        "seconds",
    )
    # Off by default: a still IMU whose output is quantised repeats its sample, and would be
    # carried with the head as it turns
    frozen_after: float = option(
        0.0,
        "a tracker sample repeated bit for bit this long counts as lost (a runtime that freezes a lost "
        "controller); 0: repeated samples are believed",
        0.0,
        10.0,
        "seconds",
    )
    # Off by default: a boxer's punch passes 11 m/s and CMU's wrists glitch at 40 (validation
    # and test clips), and an occluded foot's report at the origin, eased, looked like a
    # plausible foot to DTP, fine-tuned to recognise it (docs/methods.md)
    leap_speed: float = option(
        0.0,
        "a tracker sample leaping faster than this between two frames has come back (a frozen controller "
        "resuming) and is eased like a return; 0: a leap is given as it is",
        0.0,
        1000.0,
        "m/s",
    )

    def __post_init__(self) -> None:
        for name, field in self.fields().items():
            field.check(self.owner, getattr(self, name))

    @property
    def enabled(self) -> bool:
        return self.position_noise > 0 or self.rotation_noise > 0


# filter=false: the samples as they come, none carried or eased either
NO_FILTER = FilterConfig(position_noise=0.0, rotation_noise=0.0, reacquire_speed=0.0, carry_lost=0.0)
PREFIX = "filter_"  # how estimator options and node parameters name the fields


def filter_config(options: dict) -> FilterConfig:
    """The filter that options ask for, taking them out: filter=false, or filter_<field>
    values over the defaults (estimator options, node parameters)."""
    on = options.pop("filter", True)
    if not isinstance(on, bool):
        raise ValueError(f"filter must be true or false, got {on!r}")
    given = {k.removeprefix(PREFIX): options.pop(k) for k in list(options) if k.startswith(PREFIX)}
    unknown = [PREFIX + k for k in given if k not in FilterConfig.fields()]
    if unknown:
        fields = ", ".join(PREFIX + f for f in FilterConfig.fields())
        raise ValueError(f"unknown filter option {', '.join(unknown)}; the filter's options are {fields}")
    return FilterConfig.parse(given) if on else NO_FILTER


# The filter runs on every frame of every estimator: its per-site arithmetic is compiled
# (numba, core/mat3.py), one call a frame, where as plain Python it was a third of the IK's step.


@njit
def _qmul(a, b):
    ax, ay, az, aw = a[0], a[1], a[2], a[3]
    bx, by, bz, bw = b[0], b[1], b[2], b[3]
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


@njit
def _rotvec_quat(x, y, z):
    angle = math.sqrt(x * x + y * y + z * z)
    scale = math.sin(0.5 * angle) / angle if angle > 1e-9 else 0.5
    return (x * scale, y * scale, z * scale, math.cos(0.5 * angle))


@njit
def _quat_rotvec(q):
    sign = 1.0 if q[3] >= 0 else -1.0
    x, y, z, w = sign * q[0], sign * q[1], sign * q[2], sign * q[3]
    s = math.sqrt(x * x + y * y + z * z)
    scale = 2.0 * math.atan2(s, w) / s if s > 1e-9 else 2.0
    return (x * scale, y * scale, z * scale)


@njit
def covariance_step(p, dt: float, q: float, r: float):
    """One step of the constant-velocity model's shared 2x2 covariance (p00, p01, p11): the
    prediction by dt (process noise q), the gains (value, rate) of a sample with variance r,
    and the covariance after it. The live filter and the offline smoother both step this way."""
    p00, p01, p11 = p[0], p[1], p[2]
    a = p00 + 2 * dt * p01 + dt * dt * p11 + q * dt**3 / 3
    b = p01 + dt * p11 + q * dt * dt / 2
    c = p11 + q * dt
    k0, k1 = a / (a + r), b / (a + r)
    return (a, b, c), (k0, k1), ((1 - k0) * a, (1 - k0) * b, c - k1 * b)


class _Tracks:
    """Every site's constant-velocity Kalman state for one quantity (positions or
    orientations): the value, its rate per axis, the 2x2 covariance the axes share (p00,
    p01, p11), the stamp of the last sample; started is False until a site's first sample."""

    def __init__(self, sites: int, width: int) -> None:
        self.value, self.rate = np.zeros((sites, width)), np.zeros((sites, 3))
        self.cov, self.stamp = np.zeros((sites, 3)), np.full(sites, -math.inf)
        self.started = np.zeros(sites, dtype=np.bool_)


@njit
def _start(value, rate, cov, stamp, started, i, z, t, r) -> None:
    """Site i from this sample: the value as measured, the rate unknown (zero, wide)."""
    value[i] = z
    rate[i] = 0.0
    cov[i, 0], cov[i, 1], cov[i, 2] = r, 0.0, 1e4 * r
    stamp[i], started[i] = t, True


@njit
def _gains(cov, i, dt, q, r):
    """Predict site i's covariance by dt; the gains (value, rate) of this sample's innovation."""
    _, gains, updated = covariance_step((cov[i, 0], cov[i, 1], cov[i, 2]), dt, q, r)
    cov[i, 0], cov[i, 1], cov[i, 2] = updated
    return gains


@njit
def _position(value, rate, cov, stamp, started, i, z, t, q, r, gap, jump) -> None:
    dt = t - stamp[i]
    if started[i] and 0 < dt <= gap:
        pred = value[i] + rate[i] * dt
        e = z - pred
        if e[0] * e[0] + e[1] * e[1] + e[2] * e[2] <= jump * jump:
            k0, k1 = _gains(cov, i, dt, q, r)
            value[i] = pred + k0 * e
            rate[i] = rate[i] + k1 * e
            stamp[i] = t
            return
    _start(value, rate, cov, stamp, started, i, z, t, r)


@njit
def _orientation(value, rate, cov, stamp, started, i, z, t, q, r, gap) -> None:
    dt = t - stamp[i]
    if not started[i] or not 0 < dt <= gap:
        _start(value, rate, cov, stamp, started, i, z, t, r)
        return
    w = rate[i]
    pred = _qmul(_rotvec_quat(w[0] * dt, w[1] * dt, w[2] * dt), value[i])
    e = _quat_rotvec(_qmul(z, (-pred[0], -pred[1], -pred[2], pred[3])))  # world-frame rotation vector
    k0, k1 = _gains(cov, i, dt, q, r)
    x, y, zz, ww = _qmul(_rotvec_quat(k0 * e[0], k0 * e[1], k0 * e[2]), pred)
    n = math.sqrt(x * x + y * y + zz * zz + ww * ww)
    value[i, 0], value[i, 1], value[i, 2], value[i, 3] = x / n, y / n, zz / n, ww / n
    rate[i, 0], rate[i, 1], rate[i, 2] = w[0] + k1 * e[0], w[1] + k1 * e[1], w[2] + k1 * e[2]
    stamp[i] = t


@njit
def _filter_frame(positions, orientations, valid, t, noise, gap, jump, pos, rot):
    """One frame through the filter: (positions, orientations) filtered, the states updated.
    noise: (position r, q, rotation r, q, filter positions, filter orientations); pos and rot
    the two _Tracks' arrays."""
    pos_r, pos_q, rot_r, rot_q, on_pos, on_rot = noise
    out_p, out_q = positions.copy(), orientations.copy()
    for i in range(len(valid)):
        if not valid[i]:
            continue
        p = positions[i]
        if on_pos > 0 and math.isfinite(p[0] + p[1] + p[2]):
            _position(pos[0], pos[1], pos[2], pos[3], pos[4], i, p, t, pos_q, pos_r, gap, jump)
            out_p[i] = pos[0][i]
        o = orientations[i]
        n2 = o[0] * o[0] + o[1] * o[1] + o[2] * o[2] + o[3] * o[3]
        if on_rot > 0 and math.isfinite(n2) and 0.81 < n2 < 1.21:
            _orientation(rot[0], rot[1], rot[2], rot[3], rot[4], i, o / math.sqrt(n2), t, rot_q, rot_r, gap)
            out_q[i] = rot[0][i]
    return out_p, out_q


class TrackerFilter:
    """Filters the samples of a stream of TrackerFrames, site by site.

    Invalid or non-finite samples pass through untouched and leave the state as it was; a
    site silent for longer than config.gap, a stamp that goes back or a jump of more than
    config.jump starts that site over from its sample."""

    def __init__(self, config: FilterConfig, sites: tuple[str, ...]) -> None:
        self.config = config
        self.sites = tuple(sites)
        c = config
        pos_r, pos_q = max(c.position_noise, 1e-9) ** 2, c.acceleration**2
        rot_r, rot_q = max(math.radians(c.rotation_noise), 1e-9) ** 2, c.spin_acceleration**2
        self._noise = (pos_r, pos_q, rot_r, rot_q, float(c.position_noise > 0), float(c.rotation_noise > 0))
        self.reset()

    def reset(self) -> None:
        self._pos, self._rot = _Tracks(len(self.sites), 3), _Tracks(len(self.sites), 4)

    def stream(self, frames):
        """A recording's frames filtered, one out for each one in."""
        return (self(frame) for frame in frames)

    def __call__(self, frame: TrackerFrame) -> TrackerFrame:
        c = self.config
        if not c.enabled:
            return frame
        if tuple(frame.sites) != self.sites:  # another site set: filter it on its own terms
            self.sites = tuple(frame.sites)
            self.reset()
        pos, rot = self._pos, self._rot
        positions, orientations = _filter_frame(
            np.ascontiguousarray(frame.positions, dtype=float),
            np.ascontiguousarray(frame.orientations, dtype=float),
            np.ascontiguousarray(frame.valid, dtype=np.bool_),
            float(frame.stamp),
            self._noise,
            float(c.gap),
            float(c.jump),
            (pos.value, pos.rate, pos.cov, pos.stamp, pos.started),
            (rot.value, rot.rate, rot.cov, rot.stamp, rot.started),
        )
        return TrackerFrame(frame.stamp, frame.sites, positions, orientations, frame.valid)
