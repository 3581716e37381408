"""What an estimator gets in the field, from a motion capture clip: the evaluation protocols.

A user's estimator never sees the true skeleton or clean, perfectly mounted trackers. The
field protocol gives it only what a user has:
- trackers strapped on and held a little differently each session: each site's mounting
  rotation turned by up to 20 degrees (the T-pose calibration has to find it) and its
  translation off from the sensor configuration's (the device geometry the user gives) by
  mounting_translation_std per axis;
- tracker noise of a VR system (Lighthouse / headset grade unless told otherwise);
- tracker failures: hands out of view of a headset's cameras, lost or frozen; Lighthouse
  reflections that make a position jump; IMU heading drift; and, when asked, feet trackers
  occluded in a share of the frames (DTP's occlusion model);
- the body the T-pose calibration fits: the person first stands in a T-pose (synthesized
  in their own body, held a second, never quite exact), then moves as in the clip;
- with calibrate_mounting, between the two the person turns the head, circles the wrists
  and each ankle and rolls the hips (mounting_motion), and the calibration finds each
  tracker's mounting translation from it (core.mounting), as the bridge's
  ~/calibrate_mounting does.
The lab protocol is the one the papers report: the true skeleton, exact mounting, no noise.

PRESETS names them (`sparse-body eval --protocol NAME`, each of its values overridden by its
own flag): `field`, the default, a user's session with every failure at a realistic rate and
the mounting found by the movement calibration; `field-exact`, the field before those (exact
mounting translations, no failures: what the lab notes that name it used);
and `lab`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from ..core.calibration import Calibration, calibrate_mounting, calibrate_tpose, untimed
from ..core.sensors import SensorConfig
from ..core.skeleton import NUM_JOINTS, PARENTS, Skeleton
from ..core.types import TrackerStream
from .motion import Motion
from .virtual_trackers import NOISE_MODELS, VR_NOISE, TrackerNoise, synthesize_trackers

SKELETONS = ("calibrated", "height", "oracle")


@dataclass(frozen=True)
class Protocol:
    skeleton: str = "calibrated"  # calibrated: fitted from the T-pose; height: canonical at the
    #                                  calibrated height; oracle: the subject's true skeleton
    noise: TrackerNoise = VR_NOISE
    mounting_rotation_deg: float = 20.0  # uniform random axis, angle up to this, per site and clip
    mounting_translation_std: float = 0.0  # metres per axis, per site and clip
    tpose_wobble_deg: float = 2.0  # each segment of the calibration T-pose off by up to this
    tpose_seconds: float = 1.0
    calibrate_mounting: bool = False  # find the mounting translations from movement after the T-pose

    def __post_init__(self) -> None:
        if self.skeleton not in SKELETONS:
            raise ValueError(f"skeleton must be one of {', '.join(SKELETONS)}, got {self.skeleton!r}")

    @property
    def label(self) -> str:
        """What the protocol is, for table footers and JSON results."""
        if self == LAB:
            return "lab"
        plain = replace(
            self.noise,
            fault_probability=0.0,
            occlusion_probability=0.0,
            occlusion_frames=30,
            occlusion_mode="origin",
            loss_probability=0.0,
            loss_mode="lost",
            jump_probability=0.0,
            yaw_drift=0.0,
        )
        noise = next((n for n, v in NOISE_MODELS.items() if v == plain), "custom")
        faults = f", {self.noise.fault_probability * 100:g} % faulty" if self.noise.fault_probability else ""
        if self.noise.occlusion_probability:
            faults += f", feet occluded in {self.noise.occluded_percent:.3g} % of frames"
        if self.noise.loss_probability:
            faults += f", hands {self.noise.loss_mode} in {self.noise.lost_percent:.3g} % of frames"
        if self.noise.jump_probability:
            jumps = self.noise.jump_probability * 3600
            faults += f", {jumps:.3g} position jump{'' if f'{jumps:.3g}' == '1' else 's'} a minute"
        if self.noise.yaw_drift:
            faults += f", IMU heading drift up to {self.noise.yaw_drift:g} deg/min"
        name = (
            "field"
            if replace(self, noise=VR_NOISE, mounting_translation_std=0.0, calibrate_mounting=False) == FIELD_EXACT
            else f"{self.skeleton} skeleton"
        )
        mounting = (
            f", {self.mounting_translation_std * 1000:g} mm mounting error" if self.mounting_translation_std else ""
        )
        if self.calibrate_mounting:
            mounting += ", mounting calibrated from movement"
        noise = "no noise" if noise == "none" else f"{noise} noise"
        return f"{name}, {noise}{faults}{mounting}"

    @classmethod
    def named(
        cls,
        skeleton: str = "calibrated",
        noise: str = "vr",
        faulty_percent: float = 0.0,
        mounting_error: float = 0.0,
        occluded_percent: float = 0.0,
        lost_percent: float = 0.0,
        loss_mode: str = "lost",
        jumps_per_minute: float = 0.0,
        yaw_drift: float = 0.0,
        calibrate_mounting: bool = False,
    ) -> Protocol:
        """The protocol of `sparse-body eval --skeleton S --noise N --faulty P --mounting-error M
        --occlusion O --hand-loss L --hand-loss-mode MODE --jumps J --yaw-drift D
        [--calibrate-mounting]`: an oracle
        skeleton comes with the true mounting (the lab's), the others with a user's."""
        if noise not in NOISE_MODELS:
            raise ValueError(f"noise must be one of {', '.join(NOISE_MODELS)}, got {noise!r}")
        if not 0.0 <= mounting_error <= 0.1:
            raise ValueError(f"the mounting error must be between 0 and 0.1 m, got {mounting_error!r}")
        model = replace(NOISE_MODELS[noise], fault_probability=faulty_percent / 100)
        if occluded_percent:
            model = model.occluding(occluded_percent)
        if lost_percent:
            model = model.losing_hands(lost_percent, loss_mode)
        if jumps_per_minute:
            model = model.jumping(jumps_per_minute)
        if yaw_drift:
            model = model.drifting(yaw_drift)
        if skeleton == "oracle":
            if mounting_error or calibrate_mounting:
                raise ValueError("an oracle skeleton comes with the true mounting: no mounting error or calibration")
            return cls("oracle", model, 0.0, 0.0, 0.0)
        return cls(skeleton, model, mounting_translation_std=mounting_error, calibrate_mounting=calibrate_mounting)

    @classmethod
    def preset(cls, name: str, **overrides) -> Protocol:
        """PRESETS[name] with some of its values replaced (Protocol.named's arguments; None:
        the preset's). An oracle skeleton asked of the field comes with the true mounting, as
        named() requires, unless a mounting is asked for too."""
        if name not in PRESETS:
            raise ValueError(f"the protocol must be one of {', '.join(PRESETS)}, got {name!r}")
        given = {k: v for k, v in overrides.items() if v is not None}
        values = {**PRESETS[name], **given}
        if values.get("skeleton") == "oracle":
            for key in ("mounting_error", "calibrate_mounting"):
                if key not in given:
                    values.pop(key, None)
        return cls.named(**values)

    def to_json(self) -> dict:
        """Every field, so that a results file says exactly what its estimators were given."""
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> Protocol:
        noise: dict[str, Any] = {
            k: tuple(v) if isinstance(v, list) else v for k, v in data["noise"].items()
        }  # (JSON has no tuples)
        return cls(**{**data, "noise": TrackerNoise(**noise)})


# Presets as data: Protocol.named()'s arguments, one knob a line.
PRESETS: dict[str, dict] = {
    "field": {  # a user's session, the default of `eval` and of the cards' field tables
        "skeleton": "calibrated",  # the body the T-pose calibration fits
        "noise": "vr",  # a VR system's: 1 mm, 0.5 degrees on average
        # a headset sits 1-2 cm differently on each head, a grip shifts on a controller, a strap
        # on a belt or a shoe moves a few cm: 1.5 cm per axis (2.4 cm in 3D on average) ...
        "mounting_error": 0.015,
        "calibrate_mounting": True,  # ... which the movement after the T-pose finds
        # each controller out of the headset's cameras' view (behind the back, close to the
        # body) in 3 % of the frames, 0.2-2 s at a time, reported lost
        "lost_percent": 3.0,
        "jumps_per_minute": 1.0,  # a Lighthouse reflection about once a minute on each tracker
        "yaw_drift": 2.0,  # a 6-axis IMU's heading after its gyro bias calibration: up to 2 deg/min
    },
    "field-exact": {  # the field before failures: exact mounting translations, no failures
        "skeleton": "calibrated",
        "noise": "vr",
    },
    "lab": {  # what the papers report: the true skeleton, exact mounting, no noise
        "skeleton": "oracle",
        "noise": "none",
    },
}

FIELD = Protocol.preset("field")
FIELD_EXACT = Protocol.preset("field-exact")
LAB = Protocol.preset("lab")


@dataclass
class UserView:
    """What the estimator is given for one clip."""

    skeleton: Skeleton
    sensors: SensorConfig  # the configuration the user runs with (nominal mounting)
    stream: TrackerStream  # the clip's tracker samples, calibrated as the bridge does
    calibration: Calibration | None = None


def _random_rotation(rng: np.random.Generator, max_deg: float) -> Rotation:
    axis = rng.normal(size=3)
    return Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.deg2rad(rng.uniform(0.0, max_deg)))


def mounted_as_worn(sensors: SensorConfig, protocol: Protocol, rng: np.random.Generator) -> SensorConfig:
    """The configuration with this session's mounting: every site's offsets perturbed."""
    sites = []
    for site in sensors.sites:
        rot = Rotation.from_quat(site.offset_rotation) * _random_rotation(rng, protocol.mounting_rotation_deg)
        move = rng.normal(0.0, protocol.mounting_translation_std, 3)
        sites.append(
            replace(
                site,
                offset_translation=tuple(np.add(site.offset_translation, move)),
                offset_rotation=tuple(rot.as_quat()),
            )
        )
    return replace(sensors, sites=tuple(sites))


def tpose_motion(motion: Motion, protocol: Protocol, rng: np.random.Generator) -> Motion:
    """The clip's subject standing in a T-pose where the clip starts, facing its first
    heading, feet on the floor (z = 0). No one stands in an exact T-pose: each body segment
    is turned by up to tpose_wobble_deg from it (segments, not joints: a person squares each
    segment to the room, so the errors do not add up along a limb)."""
    T = max(2, int(round(protocol.tpose_seconds * motion.fps)))
    forward = Rotation.from_quat(motion.local_quats[0, 0]).apply([1.0, 0.0, 0.0])
    facing = Rotation.from_euler("z", np.arctan2(forward[1], forward[0]))
    glob = [facing * _random_rotation(rng, protocol.tpose_wobble_deg) for _ in range(NUM_JOINTS)]
    local = [glob[0]] + [glob[PARENTS[j]].inv() * glob[j] for j in range(1, NUM_JOINTS)]
    quats = np.tile(np.stack([r.as_quat() for r in local]), (T, 1, 1))
    standing = Motion("tpose", motion.fps, motion.skeleton, quats, np.zeros((T, 3)))
    root = np.tile(motion.root_positions[0] * [1.0, 1.0, 0.0], (T, 1))
    root[:, 2] = -standing.positions[0, :, 2].min()
    return Motion("tpose", motion.fps, motion.skeleton, quats, root)


# The calibration movement: (joints, each one's two axes in its frame and their amplitudes in
# degrees), one phase each, a joint circling about the two axes while the rest stands still.
MOUNTING_PHASES = (
    ((15,), ((0, 0, 1), 40.0), ((0, 1, 0), 25.0)),  # the head turned and nodded
    ((20, 21), ((0, 0, 1), 40.0), ((1, 0, 0), 30.0)),  # both wrists circled, arms out
    ((7,), ((0, 1, 0), 25.0), ((1, 0, 0), 15.0)),  # the left ankle circled, foot lifted
    ((8,), ((0, 1, 0), 25.0), ((1, 0, 0), 15.0)),  # the right ankle
    ((0,), ((0, 0, 1), 20.0), ((0, 1, 0), 15.0)),  # the hips rolled, upper body and legs kept
)
MOUNTING_PHASE_SECONDS = 3.0  # two circles a phase
SWAY_METRES = 0.01  # nobody stands still: the body drifts this much, slowly, throughout


def mounting_motion(tpose: Motion, rng: np.random.Generator) -> Motion:
    """The calibration movement after the T-pose (MOUNTING_PHASES), in the T-pose's body and
    wobble, each circle's phase and the sway's direction drawn by rng."""
    n = int(round(MOUNTING_PHASE_SECONDS * tpose.fps))
    t = np.arange(n) / tpose.fps
    envelope = np.sin(np.pi * t / MOUNTING_PHASE_SECONDS)  # each phase starts and ends at rest
    quats = []
    for joints, (axis1, deg1), (axis2, deg2) in MOUNTING_PHASES:
        angle = 2 * np.pi * (2 / MOUNTING_PHASE_SECONDS) * t + rng.uniform(0, 2 * np.pi)
        rotvec = envelope[:, None] * (
            np.outer(np.cos(angle), np.deg2rad(deg1) * np.array(axis1, float))
            + np.outer(np.sin(angle), np.deg2rad(deg2) * np.array(axis2, float))
        )
        turn = Rotation.from_rotvec(rotvec)
        phase = np.tile(tpose.local_quats[-1], (n, 1, 1))
        for j in joints:
            phase[:, j] = (Rotation.from_quat(phase[:, j]) * turn).as_quat()
        if joints == (0,):  # the spine and hips turn back: only the pelvis rolls
            for child in (1, 2, 3):
                phase[:, child] = (turn.inv() * Rotation.from_quat(phase[:, child])).as_quat()
        quats.append(phase)
    turned = np.concatenate(quats)
    T = len(turned)
    heading = rng.uniform(0, 2 * np.pi)
    sway = SWAY_METRES * np.sin(2 * np.pi * 0.2 * np.arange(T) / tpose.fps)
    root = tpose.root_positions[-1] + np.outer(sway, [np.cos(heading), np.sin(heading), 0.0])
    return Motion("mounting", tpose.fps, tpose.skeleton, turned, root)


def _samples(stream: TrackerStream, sensors: SensorConfig) -> dict[str, list]:
    """Each site's (seconds, position or None, orientation or None) samples, as the bridge
    collects them."""
    samples = {}
    for s, site in enumerate(stream.sites):
        spec = sensors.site(site)
        samples[site] = [
            (
                float(stream.times[t]),
                stream.positions[t, s] if spec.has_position else None,
                stream.orientations[t, s] if spec.has_orientation else None,
            )
            for t in np.flatnonzero(stream.valid[:, s])
        ]
    return samples


def _translations(sensors: SensorConfig) -> dict[str, np.ndarray]:
    return {s.site: np.array(s.offset_translation) for s in sensors.sites}


def calibrate_from_tpose(
    stream: TrackerStream, sensors: SensorConfig, movement: TrackerStream | None = None
) -> Calibration:
    """The bridge's ~/calibrate on a recorded T-pose, then, given movement after it,
    ~/calibrate_mounting."""
    samples = _samples(stream, sensors)
    if movement is None:
        return calibrate_tpose(untimed(samples), translations=_translations(sensors))
    return calibrate_mounting(samples, _samples(movement, sensors), _translations(sensors))[0]


def calibrated_stream(stream: TrackerStream, calibration: Calibration, sensors: SensorConfig) -> TrackerStream:
    """Tracker orientations turned into their joints', positions moved to where the
    configuration's mounting puts them (what the bridge publishes)."""
    orientations, positions = stream.orientations.copy(), stream.positions.copy()
    nominal = _translations(sensors)
    for s, site in enumerate(stream.sites):
        if site in calibration.offsets:
            ok = np.all(np.isfinite(orientations[:, s]), axis=1)
            orientations[ok, s] = calibration.apply(site, orientations[ok, s])
            if site in calibration.translations and sensors.site(site).has_position:
                ok &= np.all(np.isfinite(positions[:, s]), axis=1)
                positions[ok, s] = calibration.place(site, positions[ok, s], orientations[ok, s], nominal[site])
    return TrackerStream(stream.sites, stream.times, positions, orientations, stream.valid, stream.lost)


def user_view(motion: Motion, sensors: SensorConfig, protocol: Protocol = FIELD, seed: int = 0) -> UserView:
    """What a user's estimator would get for this clip under the protocol."""
    rng = np.random.default_rng(seed)
    if protocol.skeleton == "oracle" and protocol.mounting_rotation_deg == 0 and protocol.mounting_translation_std == 0:
        return UserView(motion.skeleton, sensors, synthesize_trackers(motion, sensors, protocol.noise, seed))
    worn = mounted_as_worn(sensors, protocol, rng)
    # the T-pose is taken standing in full view of the base stations: no foot occluded
    visible = replace(protocol.noise, occlusion_probability=0.0, loss_probability=0.0)
    standing = tpose_motion(motion, protocol, rng)
    tpose = synthesize_trackers(standing, worn, visible, seed + 1)
    movement = (
        synthesize_trackers(mounting_motion(standing, rng), worn, visible, seed + 2)
        if protocol.calibrate_mounting
        else None
    )
    calibration = calibrate_from_tpose(tpose, sensors, movement)
    stream = calibrated_stream(synthesize_trackers(motion, worn, protocol.noise, seed), calibration, sensors)
    # the calibration has absorbed the mounting rotations: the user's configuration keeps
    # only the nominal translations
    user_sensors = replace(
        sensors, sites=tuple(replace(s, offset_rotation=(0.0, 0.0, 0.0, 1.0)) for s in sensors.sites)
    )
    skeleton = {
        "calibrated": calibration.body(),
        "height": Skeleton.canonical(calibration.height),
        "oracle": motion.skeleton,
    }[protocol.skeleton]
    return UserView(skeleton, user_sensors, stream, calibration)
