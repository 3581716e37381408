"""What trackers would report for a motion: each site's joint pose composed with its
mounting offset, with optional noise, dropped samples and occlusion."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from ..core.sensors import SensorConfig
from ..core.types import TrackerStream
from .motion import Motion

OCCLUSION_MODES = ("origin", "bounded", "either")
LOSS_MODES = ("lost", "frozen")


@dataclass(frozen=True)
class TrackerNoise:
    position_std: float = 0.0  # metres, Gaussian per axis
    rotation_max_deg: float = 0.0  # uniform random axis, angle up to this
    drop_probability: float = 0.0  # per sample: no sample at all (valid = False)
    # Occlusion (DTP): a foot tracker loses the base stations and keeps reporting garbage.
    # In each frame without an occlusion, one starts with this probability and lasts
    # occlusion_frames frames; it takes one of the configured occlusion_sites or all of them
    # (equal chances) and reads as the origin with the identity rotation ("origin"), as
    # noise within a leg's length of the joint with a random rotation ("bounded"), or
    # either of the two, chosen per occlusion ("either").
    occlusion_probability: float = 0.0
    occlusion_frames: int = 30
    occlusion_sites: tuple[str, ...] = ("left_foot", "right_foot")
    occlusion_mode: str = "origin"
    # Faulty sensors (DragPoser): each frame, with this probability, one random tracker
    # disconnects (valid = False, no values) for fault_frames frames.
    fault_probability: float = 0.0
    fault_frames: int = 100
    # Lost controllers (a headset's inside-out tracking): a hand leaves the cameras' view
    # (behind the back, close to the body). In each frame it is tracked, it is lost with this
    # probability, for a time uniform in loss_seconds, and reported as lost (valid = False,
    # no values) or frozen at its last sample (valid, as some runtimes report it).
    loss_probability: float = 0.0
    loss_seconds: tuple[float, float] = (0.2, 2.0)
    loss_sites: tuple[str, ...] = ("left_hand", "right_hand")
    loss_mode: str = "lost"
    # Reflections (Lighthouse): a tracked position jumps a distance uniform in jump_size (metres,
    # a random direction) for a number of frames uniform in jump_frames; a jump starts in each
    # frame of each tracker with a position with jump_probability.
    jump_probability: float = 0.0
    jump_size: tuple[float, float] = (0.02, 0.08)
    jump_frames: tuple[int, int] = (2, 8)
    # Heading drift (an IMU without a magnetometer): an orientation-only sensor's heading turns
    # about the vertical at a steady rate uniform in +-yaw_drift (degrees per minute), drawn per
    # sensor and clip.
    yaw_drift: float = 0.0

    def __post_init__(self) -> None:
        if self.occlusion_mode not in OCCLUSION_MODES:
            raise ValueError(f"occlusion_mode must be one of {', '.join(OCCLUSION_MODES)}, got {self.occlusion_mode!r}")
        if self.loss_mode not in LOSS_MODES:
            raise ValueError(f"loss_mode must be one of {', '.join(LOSS_MODES)}, got {self.loss_mode!r}")
        if not 0.0 < self.loss_seconds[0] <= self.loss_seconds[1]:
            raise ValueError(f"loss_seconds must be (shortest, longest) above 0, got {self.loss_seconds!r}")
        if not 0.0 <= self.jump_size[0] <= self.jump_size[1] or not 1 <= self.jump_frames[0] <= self.jump_frames[1]:
            raise ValueError(
                f"jump_size and jump_frames must be (least, most), got {self.jump_size}, {self.jump_frames}"
            )

    def jumping(self, per_minute: float) -> TrackerNoise:
        """This noise with about `per_minute` reflection jumps a minute on each tracked position
        (`sparse-body eval --jumps`), at 60 Hz, the catalogue's rate."""
        if not 0.0 <= per_minute <= 600.0:
            raise ValueError(f"jumps per minute must be from 0 to 600, got {per_minute!r}")
        return replace(self, jump_probability=per_minute / 3600.0)

    def drifting(self, deg_per_minute: float) -> TrackerNoise:
        """This noise with orientation-only sensors drifting in heading at up to
        `deg_per_minute` (`sparse-body eval --yaw-drift`)."""
        if not 0.0 <= deg_per_minute <= 360.0:
            raise ValueError(f"the yaw drift must be from 0 to 360 degrees a minute, got {deg_per_minute!r}")
        return replace(self, yaw_drift=deg_per_minute)

    def losing_hands(self, percent: float, mode: str = "lost") -> TrackerNoise:
        """This noise with each hand lost in about `percent` % of the frames (`sparse-body eval
        --hand-loss`), for loss_seconds at a time, reported as `mode`."""
        if not 0.0 <= percent < 100.0:
            raise ValueError(f"the lost share must be from 0 to under 100 %, got {percent!r}")
        share = percent / 100
        mean_frames = 60.0 * sum(self.loss_seconds) / 2  # at 60 Hz, the catalogue's rate
        return replace(self, loss_probability=share / (mean_frames * (1.0 - share)), loss_mode=mode)

    @property
    def lost_percent(self) -> float:
        """The share of frames each hand is lost (%), as losing_hands() sets it."""
        p, n = self.loss_probability, 60.0 * sum(self.loss_seconds) / 2
        return 100 * p * n / (1 + p * n)

    def occluding(self, percent: float, frames: int = 30) -> TrackerNoise:
        """This noise with feet occluded in about `percent` % of the frames, for `frames`
        frames at a time, both ways of failing (`sparse-body eval --occlusion`)."""
        if not 0.0 <= percent < 100.0:
            raise ValueError(f"the occluded share must be from 0 to under 100 %, got {percent!r}")
        share = percent / 100
        # an occlusion starts in a free frame with probability p: the occluded share is pL / (1 + pL)
        return replace(
            self,
            occlusion_probability=share / (frames * (1.0 - share)),
            occlusion_frames=frames,
            occlusion_mode="either",
        )

    @property
    def occluded_percent(self) -> float:
        """The share of frames with an occluded foot (%), as occluding() sets it."""
        p, n = self.occlusion_probability, self.occlusion_frames
        return 100 * p * n / (1 + p * n)


NO_NOISE = TrackerNoise()
LOBSTR_NOISE = TrackerNoise(position_std=0.01, rotation_max_deg=1.5)
# A VR system in use (Lighthouse base stations, a headset's inside-out tracking): about a
# millimetre of position jitter and half a degree of orientation jitter on average.
VR_NOISE = TrackerNoise(position_std=0.001, rotation_max_deg=1.0)
NOISE_MODELS = {"vr": VR_NOISE, "lobstr": LOBSTR_NOISE, "none": NO_NOISE}
FAULTY_1PCT = TrackerNoise(fault_probability=0.01)  # DragPoser's faulty-sensor protocol


def _random_rotations(rng: np.random.Generator, n: int, max_deg: float) -> Rotation:
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(0.0, np.deg2rad(max_deg), size=(n, 1))
    return Rotation.from_rotvec(axis * angle)


def _occlusions(T: int, sites: list[str], noise: TrackerNoise, rng: np.random.Generator):
    """site -> (occluded (T,), bounded (T,)): which frames each site is occluded in, and
    which of those read as bounded noise rather than the origin."""
    if not sites or noise.occlusion_probability <= 0:
        return {}
    out = {site: (np.zeros(T, dtype=bool), np.zeros(T, dtype=bool)) for site in sites}
    subsets = [[site] for site in sites] + ([sites] if len(sites) > 1 else [])
    t = 0
    while t < T:
        if rng.random() < noise.occlusion_probability:
            span = slice(t, t + noise.occlusion_frames)
            bounded = noise.occlusion_mode == "bounded" or (noise.occlusion_mode == "either" and rng.random() < 0.5)
            for site in subsets[rng.integers(len(subsets))]:
                out[site][0][span] = True
                out[site][1][span] = bounded
            t += noise.occlusion_frames
        else:
            t += 1
    return out


def _losses(T: int, fps: float, noise: TrackerNoise, rng: np.random.Generator) -> np.ndarray:
    """(T,) the frames a site is lost in: each loss starts in a tracked frame with
    loss_probability and lasts a time uniform in loss_seconds."""
    lost = np.zeros(T, dtype=bool)
    t = 0
    while t < T:
        if rng.random() < noise.loss_probability:
            frames = max(1, round(rng.uniform(*noise.loss_seconds) * fps))
            lost[t : t + frames] = True
            t += frames + 1  # back in view for a frame at least
        else:
            t += 1
    return lost


def synthesize_trackers(
    motion: Motion, config: SensorConfig, noise: TrackerNoise = NO_NOISE, seed: int = 0
) -> TrackerStream:
    rng = np.random.default_rng(seed)
    T, S = len(motion), len(config.sites)
    positions = np.full((T, S, 3), np.nan)
    orientations = np.full((T, S, 4), np.nan)
    valid = np.ones((T, S), dtype=bool)
    glob_rot, glob_pos = motion.global_rotations, motion.positions
    leg = motion.skeleton.leg_length()
    occlusions = _occlusions(T, [s.site for s in config.sites if s.site in noise.occlusion_sites], noise, rng)
    for s, site in enumerate(config.sites):
        j = site.joint_index
        rot = Rotation.from_matrix(glob_rot[:, j])
        pos = glob_pos[:, j] + rot.apply(np.asarray(site.offset_translation))
        rot = rot * Rotation.from_quat(site.offset_rotation)
        if noise.position_std > 0:
            pos = pos + rng.normal(0.0, noise.position_std, size=pos.shape)
        if noise.rotation_max_deg > 0:
            rot = _random_rotations(rng, T, noise.rotation_max_deg) * rot
        pos, quat = pos.copy(), rot.as_quat()
        if site.site in occlusions:
            occluded, bounded = occlusions[site.site]
            pos[occluded & ~bounded], quat[occluded & ~bounded] = 0.0, [0.0, 0.0, 0.0, 1.0]
            n = int((occluded & bounded).sum())
            direction = rng.normal(size=(n, 3))
            direction /= np.linalg.norm(direction, axis=1, keepdims=True)
            pos[occluded & bounded] += direction * rng.uniform(0.0, leg, size=(n, 1))
            quat[occluded & bounded] = Rotation.random(n, random_state=rng).as_quat()
        if site.has_position:
            positions[:, s] = pos
        if site.has_orientation:
            orientations[:, s] = quat
        if noise.drop_probability > 0:
            dropped = rng.random(T) < noise.drop_probability
            valid[dropped, s] = False
            positions[dropped, s] = np.nan
            orientations[dropped, s] = np.nan
    if noise.fault_probability > 0:
        for t in np.flatnonzero(rng.random(T) < noise.fault_probability):
            s = int(rng.integers(S))
            valid[t : t + noise.fault_frames, s] = False
            positions[t : t + noise.fault_frames, s] = np.nan
            orientations[t : t + noise.fault_frames, s] = np.nan
    lost = None
    if noise.loss_probability > 0:  # drawn last: the other draws stay what they were without it
        lost = np.zeros((T, S), dtype=bool)
        for s, site in enumerate(config.sites):
            if site.site not in noise.loss_sites:
                continue
            lost[:, s] = _losses(T, motion.fps, noise, rng)
            if noise.loss_mode == "lost":
                valid[lost[:, s], s] = False
                positions[lost[:, s], s] = np.nan
                orientations[lost[:, s], s] = np.nan
            else:  # each lost frame repeats the last sample before the loss
                last = np.maximum.accumulate(np.where(lost[:, s], 0, np.arange(T)))
                positions[:, s], orientations[:, s] = positions[last, s], orientations[last, s]
    # drawn after every other draw, and only when asked: without them, the streams stay as they were
    if noise.jump_probability > 0:
        for s, site in enumerate(config.sites):
            if site.has_position:
                positions[:, s] += _jumps(T, noise, rng)
    if noise.yaw_drift > 0:
        for s, site in enumerate(config.sites):
            if site.has_orientation and not site.has_position:
                rate = np.deg2rad(rng.uniform(-noise.yaw_drift, noise.yaw_drift)) / 60.0  # rad/s
                heading = Rotation.from_rotvec(np.outer(np.arange(T) / motion.fps * rate, [0.0, 0.0, 1.0]))
                good = np.isfinite(orientations[:, s]).all(axis=1)
                orientations[good, s] = (heading[good] * Rotation.from_quat(orientations[good, s])).as_quat()
    times = np.arange(T) / motion.fps
    return TrackerStream(config.site_names, times, positions, orientations, valid, lost)


def _jumps(T: int, noise: TrackerNoise, rng: np.random.Generator) -> np.ndarray:
    """(T, 3) the displacement reflections add to one tracker's positions."""
    out = np.zeros((T, 3))
    t = 0
    while t < T:
        if rng.random() < noise.jump_probability:
            frames = int(rng.integers(noise.jump_frames[0], noise.jump_frames[1] + 1))
            direction = rng.normal(size=3)
            out[t : t + frames] = direction / np.linalg.norm(direction) * rng.uniform(*noise.jump_size)
            t += frames + 1
        else:
            t += 1
    return out
