"""T-pose calibration: each tracker's rotation relative to its joint, the person's height and
body proportions.

In the body's rest pose (a T-pose facing +x) every joint's rotation is the identity, so in
a T-pose facing yaw psi every joint's rotation is Rz(psi). A tracker's orientation q then
gives its mounting offset Rz(psi)^-1 q, which absorbs how the controller is held or the
tracker strapped on, different each session. Facing comes from the hands (their left-right
line), else from the headset's forward axis. Height: the headset's height above the floor
scaled by the body model's stature ratio (LoBSTr's height scale, in metres).

Proportions: with the mounting translations undone, the trackers give the followed joints'
T-pose positions, and core.body_shape fits the body to them (arm span, shoulder height,
neck, torso and legs where pelvis and foot trackers show them). The calibration file keeps
the fitted body, so every node and the offline tools use the same one.

Applying a calibration turns a tracker orientation into its joint's orientation
(q offset^-1); the bridge publishes that, so estimators see joint-aligned trackers.

Mounting translations (optional, from a few seconds of movement after the T-pose:
core.mounting): where each tracker really sits on its segment. The bridge then moves each
published position by the difference to the configuration's translation, so estimators see
trackers mounted as the configuration says, and the body is fitted with the found ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from .body_shape import arm_span, fit_skeleton, standing_height
from .mounting import MAX_SHIFT, MountingFit, fit_mounting
from .rotations import yaw_matrix
from .skeleton import CANONICAL_HEIGHT, JOINT_NAMES, Skeleton

# the first line of every calibration file this package writes: what lets a new one replace it
CALIBRATION_MARKER = "# T-pose calibration written by sparse_body"


class CalibrationError(ValueError):
    pass


@dataclass
class Calibration:
    height: float
    facing_yaw: float  # radians, the facing during calibration
    offsets: dict[str, np.ndarray] = field(default_factory=dict)  # site -> (4,) x y z w
    skeleton: Skeleton | None = None  # the fitted body (None: scale by height)
    translations: dict[str, np.ndarray] = field(default_factory=dict)  # site -> (3,) found from movement

    def body(self) -> Skeleton:
        """The person's body: the fitted one, else the canonical body at their height."""
        return self.skeleton if self.skeleton is not None else Skeleton.canonical(self.height)

    def apply(self, site: str, quat: np.ndarray) -> np.ndarray:
        """The joint's orientation from its tracker's (unchanged for uncalibrated sites); quat
        (4,) or (N, 4)."""
        if site not in self.offsets:
            return np.asarray(quat, dtype=float)
        return (Rotation.from_quat(quat) * Rotation.from_quat(self.offsets[site]).inv()).as_quat()

    def place(self, site: str, position: np.ndarray, joint_quat: np.ndarray, nominal: np.ndarray) -> np.ndarray:
        """The position a tracker mounted at the configuration's translation (nominal, in its
        joint's frame) would have: the found mounting's difference undone. joint_quat: the
        joint's orientation (apply()'s); an uncalibrated site's position is unchanged."""
        if site not in self.translations:
            return np.asarray(position, dtype=float)
        shift = np.asarray(self.translations[site], float) - np.asarray(nominal, float)
        return np.asarray(position, dtype=float) - Rotation.from_quat(joint_quat).apply(shift)

    def save(self, path: str | Path) -> None:
        data = {
            "height": round(float(self.height), 4),
            "facing_yaw": round(float(self.facing_yaw), 6),
            "offsets": {s: [round(float(v), 8) for v in q] for s, q in self.offsets.items()},
        }
        if self.translations:
            data["translations"] = {s: [round(float(v), 5) for v in t] for s, t in self.translations.items()}
        if self.skeleton is not None:
            data["skeleton"] = {
                n: [round(float(v), 5) for v in o] for n, o in zip(JOINT_NAMES, self.skeleton.offsets, strict=True)
            }
        from .file_output import marker_in_head, write_file

        # an earlier calibration is replaced; a user's file, a link, a FIFO or a device never is
        write_file(
            Path(path),
            CALIBRATION_MARKER + " (rotation offsets x y z w:\n"
            "# the tracker's orientation in its joint's frame; skeleton: each joint's rest\n"
            "# offset from its parent, metres; translations: each tracker's mounting in its\n"
            "# joint's frame, found from movement, metres)\n" + yaml.safe_dump(data, sort_keys=False),
            marker_in_head(CALIBRATION_MARKER.encode()),
            overwrite=True,
            what="calibration",
        )

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        from .sensors import read_yaml

        path = Path(path)
        data = read_yaml(path, CalibrationError)
        if not isinstance(data, dict) or not isinstance(data.get("offsets", {}), dict):
            raise CalibrationError(f"{path}: expected height, facing_yaw and an offsets mapping")
        try:
            height, yaw = float(data["height"]), float(data.get("facing_yaw", 0.0))
        except (KeyError, TypeError, ValueError):
            raise CalibrationError(f"{path}: 'height' must be a number") from None
        if not 0.5 <= height <= 2.5:
            raise CalibrationError(f"{path}: height {height} m is not a person's")
        offsets = _site_vectors(
            path,
            data.get("offsets") or {},
            4,
            "offset",
            "a unit quaternion x y z w",
            lambda q: abs(np.linalg.norm(q) - 1) < 1e-3,
        )
        translations = data.get("translations") or {}
        if not isinstance(translations, dict):
            raise CalibrationError(f"{path}: 'translations' must map body sites to x y z (metres)")
        translations = _site_vectors(
            path,
            translations,
            3,
            "translation",
            f"three finite numbers within {0.5 + MAX_SHIFT:g} m",
            lambda t: np.linalg.norm(t) <= 0.5 + MAX_SHIFT,  # a configuration's translation is within half a metre
        )
        return cls(height, yaw, offsets, _read_skeleton(path, data.get("skeleton")), translations)


def person_body(calibration: str | Path | None, height: float) -> Skeleton:
    """The body to estimate with: a calibration file's (its fitted body, else its height), or
    the canonical body at height when no file is given (the node, `process`, the launch file)."""
    return Calibration.load(calibration).body() if calibration else Skeleton.canonical(height)


def _site_vectors(
    path: Path, mapping: dict, size: int, what: str, description: str, plausible
) -> dict[str, np.ndarray]:
    """Each body site's vector from a calibration file's mapping; one line naming the site
    when its value is not `description` (finite numbers of the right count, plausible)."""
    from .sensors import SITE_JOINTS

    vectors = {}
    for site, value in mapping.items():
        if site not in SITE_JOINTS:
            raise CalibrationError(f"{path}: unknown body site {site!r}")
        try:
            v = np.array([float(x) for x in value])
        except (TypeError, ValueError):
            v = np.zeros(0)
        if v.shape != (size,) or not np.all(np.isfinite(v)) or not plausible(v):
            raise CalibrationError(f"{path}: {what} of {site!r} is not {description}")
        vectors[site] = v
    return vectors


def _read_skeleton(path: Path, data) -> Skeleton | None:
    if data is None:
        return None
    if not isinstance(data, dict) or set(map(str, data)) != set(JOINT_NAMES):
        raise CalibrationError(
            f"{path}: 'skeleton' must give the rest offset of each of the 22 joints ({', '.join(JOINT_NAMES)})"
        )
    try:
        offsets = np.array([[float(v) for v in data[n]] for n in JOINT_NAMES])
    except (TypeError, ValueError):
        offsets = np.zeros(0)
    if offsets.shape != (len(JOINT_NAMES), 3) or not np.all(np.isfinite(offsets)):
        raise CalibrationError(f"{path}: every skeleton offset must be three finite numbers (x y z, metres)")
    lengths = np.linalg.norm(offsets[1:], axis=1)
    if lengths.max() > 1.0:
        raise CalibrationError(f"{path}: a skeleton offset of {lengths.max():.2f} m is not a person's bone")
    skeleton = Skeleton(offsets)
    if not 0.5 <= skeleton.height() <= 2.5:
        raise CalibrationError(f"{path}: the skeleton is {skeleton.height():.2f} m tall: not a person's")
    return skeleton


def _mean_rotation(quats) -> Rotation:  # (n, 4) quaternions, any sequence of them
    return Rotation.from_quat(np.asarray(quats)).mean()


def calibrate_tpose(
    samples: dict[str, list[tuple[np.ndarray | None, np.ndarray | None]]],
    floor: float = 0.0,
    translations: dict[str, np.ndarray] | None = None,
) -> Calibration:
    """samples: site -> [(position or None, orientation x y z w or None)] collected during the
    T-pose (a position-only tracker has no rotation offset to find).

    translations: each site's mounting translation in its joint's frame (the sensor
    configuration's), so that heights and lengths are measured at the joints."""
    samples = {s: v for s, v in samples.items() if v}
    if not samples:
        raise CalibrationError("no tracker samples arrived during the calibration")
    mean_pos = {
        s: np.mean(np.array([p for p, _ in v], dtype=float), axis=0)
        for s, v in samples.items()
        if all(p is not None for p, _ in v)
    }
    if "left_hand" in mean_pos and "right_hand" in mean_pos:
        left = mean_pos["left_hand"] - mean_pos["right_hand"]
        left[2] = 0.0
        if np.linalg.norm(left) < 0.5:
            raise CalibrationError(
                f"the hands are {np.linalg.norm(left):.2f} m apart: not a T-pose (arms straight out to the sides)"
            )
        forward = np.cross(left / np.linalg.norm(left), [0.0, 0.0, 1.0])
        yaw = float(np.arctan2(forward[1], forward[0]))
    elif "head" in samples and all(q is not None for _, q in samples["head"]):
        fwd = _mean_rotation([q for _, q in samples["head"]]).as_matrix()[:, 0]
        yaw = float(np.arctan2(fwd[1], fwd[0]))
    else:
        raise CalibrationError("facing cannot be found: calibration needs both hands or the headset")
    facing = Rotation.from_matrix(yaw_matrix(yaw))
    offsets = {
        s: (facing.inv() * _mean_rotation([q for _, q in v])).as_quat()
        for s, v in samples.items()
        if all(q is not None for _, q in v)
    }
    if "head" not in mean_pos and not {"left_hand", "right_hand"} <= set(mean_pos):
        raise CalibrationError("the height needs a headset with a position, or both hand trackers")
    # In the T-pose every joint frame is the facing frame: a tracker sits at its joint plus
    # the facing-rotated mounting translation.
    translations = translations or {}
    joints = {
        s: facing.inv().apply(p - facing.apply(np.asarray(translations.get(s, np.zeros(3)), float))) - [0.0, 0.0, floor]
        for s, p in mean_pos.items()
    }
    if "head" in joints:
        height = standing_height(joints["head"][2])  # as Skeleton.height(): head joint above the toes
        where = f"the headset is {joints['head'][2]:.2f} m above the floor"
    else:  # no headset: the canonical body's height for this arm span
        span = float(np.linalg.norm(joints["left_hand"] - joints["right_hand"]))
        height = span * CANONICAL_HEIGHT / arm_span(Skeleton.canonical())
        where = f"the hands are {span:.2f} m apart"
    if not 0.5 <= height <= 2.5:
        raise CalibrationError(f"{where}: not a standing person in a T-pose")
    return Calibration(height, yaw, offsets, fit_skeleton(joints, height))


Samples = dict[str, list[tuple[float, np.ndarray | None, np.ndarray | None]]]


def untimed(samples: Samples) -> dict[str, list[tuple[np.ndarray | None, np.ndarray | None]]]:
    """calibrate_tpose()'s samples from timed ones (site -> [(seconds, position, orientation)])."""
    return {site: [(p, q) for _, p, q in v] for site, v in samples.items()}


def calibrate_mounting(
    tpose: Samples,
    movement: Samples,
    translations: dict[str, np.ndarray],
    floor: float = 0.0,
) -> tuple[Calibration, dict[str, MountingFit]]:
    """The T-pose calibration again, with each tracker's mounting translation found from
    movement taken after it (core.mounting) and the body fitted with those.

    tpose, movement: site -> [(seconds, position or None, orientation or None)] as the
    trackers report them (uncalibrated); translations: the configuration's. A tracker
    with no position or no orientation, or that never turned about its joint, keeps the
    configuration's translation."""
    first = calibrate_tpose(untimed(tpose), floor, translations)
    fits = {}
    for site, samples in movement.items():
        if site not in first.offsets or site not in translations:
            continue
        usable = [(t, p, q) for t, p, q in samples if p is not None and q is not None]
        if len(usable) < 2:
            continue
        times = np.array([t for t, _, _ in usable], float)
        quats = first.apply(site, np.array([q for _, _, q in usable], float))
        fits[site] = fit_mounting(times, np.array([p for _, p, _ in usable], float), quats, translations[site])
    found = {s: f.translation for s, f in fits.items() if f.windows}
    if not found:
        raise CalibrationError(
            "no tracker turned about its joint during the movement: turn the head, circle the wrists "
            "and the ankles and roll the hips, one at a time, the rest of the body still"
        )
    calibration = calibrate_tpose(untimed(tpose), floor, {**translations, **found})
    calibration.translations = found
    return calibration, fits
