"""Sensor configurations: which body sites carry a tracker, its TF frame, what it measures
and how it is mounted. Configurations are YAML files under config/sensors/."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import yaml

from .rotations import unit_quat_matrix
from .skeleton import JOINT_INDEX

# Body sites a tracker can sit on, and the body joint each one follows.
SITE_JOINTS = {
    "head": "head",
    "left_hand": "left_wrist",
    "right_hand": "right_wrist",
    "pelvis": "pelvis",
    "left_foot": "left_ankle",
    "right_foot": "right_ankle",
}
MEASURES = ("pose", "orientation", "position")


class SensorConfigError(ValueError):
    pass


@dataclass(frozen=True)
class TrackerSite:
    site: str
    frame_id: str
    measures: str = "pose"
    # Mounting: the tracker's pose in its joint's frame (metres; quaternion x y z w).
    offset_translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    offset_rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    @property
    def joint(self) -> str:
        return SITE_JOINTS[self.site]

    @property
    def joint_index(self) -> int:
        return JOINT_INDEX[self.joint]

    def joint_pose(self, position: np.ndarray, quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The followed joint's (position, rotation matrix) from a full tracker pose (unit
        quaternion): the inverse of the mounting offset."""
        rot = self.joint_rotation(quat)
        return np.asarray(position) - rot @ self._offset_in_joint, rot

    def joint_rotation(self, quat: np.ndarray) -> np.ndarray:
        """The followed joint's rotation matrix from the tracker's (unit) orientation alone."""
        return unit_quat_matrix(quat) @ self._offset_matrix.T

    @cached_property
    def _offset_matrix(self) -> np.ndarray:
        return unit_quat_matrix(np.asarray(self.offset_rotation, float) / np.linalg.norm(self.offset_rotation))

    @cached_property
    def _offset_in_joint(self) -> np.ndarray:
        # the tracker sits at joint position + R_joint @ t_offset
        return np.asarray(self.offset_translation, float)

    @property
    def has_position(self) -> bool:
        return self.measures in ("pose", "position")

    @property
    def has_orientation(self) -> bool:
        return self.measures in ("pose", "orientation")


@dataclass(frozen=True)
class SensorConfig:
    name: str
    sites: tuple[TrackerSite, ...]
    description: str = ""
    fixed_frame: str = "world"
    source: str = field(default="", compare=False)

    @property
    def site_names(self) -> tuple[str, ...]:
        return tuple(s.site for s in self.sites)

    def site(self, name: str) -> TrackerSite:
        for s in self.sites:
            if s.site == name:
                return s
        raise KeyError(f"sensor configuration {self.name!r} has no {name!r} tracker")

    def subset(self, names) -> SensorConfig:
        names = list(names)
        unknown = [n for n in names if n not in self.site_names]
        if unknown:
            raise SensorConfigError(f"{self.name}: no tracker on {', '.join(unknown)}")
        return SensorConfig(
            f"{self.name}[{'+'.join(names)}]",
            tuple(s for s in self.sites if s.site in names),
            self.description,
            self.fixed_frame,
        )


def _vector(where: str, value, size: int) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise SensorConfigError(f"{where}: expected {size} numbers, got {value!r}") from None
    if len(out) != size or not np.all(np.isfinite(out)):
        raise SensorConfigError(f"{where}: expected {size} finite numbers, got {value!r}")
    return out


def parse_sensor_config(data: dict, source: str = "<dict>") -> SensorConfig:
    if not isinstance(data, dict) or not isinstance(data.get("sites"), dict) or not data["sites"]:
        raise SensorConfigError(f"{source}: a sensor configuration needs a non-empty 'sites' mapping")
    sites = []
    for site, spec in data["sites"].items():
        where = f"{source}: site {site!r}"
        if site not in SITE_JOINTS:
            raise SensorConfigError(f"{source}: unknown body site {site!r}; sites are {', '.join(SITE_JOINTS)}")
        spec = spec or {}
        if not isinstance(spec, dict):
            raise SensorConfigError(f"{where}: expected a mapping, got {spec!r}")
        unknown = set(spec) - {"frame", "measures", "offset"}
        if unknown:
            raise SensorConfigError(f"{where}: unknown key(s) {', '.join(sorted(map(str, unknown)))}")
        measures = spec.get("measures", "pose")
        if measures not in MEASURES:
            raise SensorConfigError(f"{where}: measures must be one of {', '.join(MEASURES)}, got {measures!r}")
        offset = spec.get("offset") or {}
        if not isinstance(offset, dict):
            raise SensorConfigError(
                f"{where}: offset must be a mapping with translation and/or rotation, got {offset!r}"
            )
        unknown = set(offset) - {"translation", "rotation"}
        if unknown:
            raise SensorConfigError(f"{where}: unknown offset key(s) {', '.join(sorted(map(str, unknown)))}")
        translation = _vector(f"{where} offset.translation", offset.get("translation", (0, 0, 0)), 3)
        rotation = _vector(f"{where} offset.rotation", offset.get("rotation", (0, 0, 0, 1)), 4)
        norm = float(np.linalg.norm(rotation))
        if abs(norm - 1.0) > 1e-3:
            raise SensorConfigError(f"{where}: offset.rotation must be a unit quaternion (x y z w), norm is {norm:.4f}")
        sites.append(
            TrackerSite(
                site,
                str(spec.get("frame", site)),
                measures,
                (translation[0], translation[1], translation[2]),
                (rotation[0] / norm, rotation[1] / norm, rotation[2] / norm, rotation[3] / norm),
            )
        )
    return SensorConfig(
        str(data.get("name", Path(source).stem)),
        tuple(sites),
        str(data.get("description", "")),
        str(data.get("fixed_frame", "world")),
        source,
    )


def load_sensor_config(name_or_path: str | Path) -> SensorConfig:
    """A configuration by name (config/sensors/NAME.yaml) or by path."""
    from .resources import shipped_or_path

    path = shipped_or_path(name_or_path, "sensors", SensorConfigError, "sensor configuration")
    return parse_sensor_config(read_yaml(path, SensorConfigError), str(path))


def read_yaml(path: Path, error: type[Exception] = ValueError):
    """A YAML file's content, or error naming the file and what is wrong with it (unreadable,
    not UTF-8, not YAML; over a limit of core/textfile.py: its size, its values with aliases
    expanded, its nesting, then also an InputTooLarge)."""
    from .textfile import InputTooLarge, load_yaml, read_limited, too_large

    try:
        return load_yaml(read_limited(path, "yaml"))
    except OSError as err:
        raise error(f"{path}: cannot be read ({err.strerror or err})") from None
    except InputTooLarge as err:
        raise too_large(error)(f"{path}: {err}" if str(path) not in str(err) else str(err)) from None
    except UnicodeDecodeError as err:
        raise error(f"{path}: not UTF-8 text ({err.reason} at byte {err.start})") from None
    except yaml.YAMLError as err:
        raise error(f"{path}: not valid YAML ({' '.join(str(err).split())})") from None
