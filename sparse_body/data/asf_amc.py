"""Acclaim ASF (skeleton) and AMC (motion) files, as in the CMU database.

Conventions (CMU's, as their viewer applies them): a bone's axis gives its rest frame C; the
motion angles (degrees; radians after the AMC's `:RADIANS` header, or by default when the ASF
says `:units angle rad`, which also governs its own axis angles) compose as R = Rz @ Ry @ Rx
over the bone's dof; the bone's global rotation is R_parent @ C @ R @ C^T and its end is
start + rotation @ direction * length.
Lengths are in units of `:units length` inches/100, converted to metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from . import MotionFileError
from .source import MAX_JOINTS, SourceMotion, read_text, stem

INCH = 0.0254


@dataclass
class Bone:
    name: str
    direction: np.ndarray
    length: float
    axis: np.ndarray  # C, 3x3
    dof: list[str] = field(default_factory=list)


@dataclass
class AsfSkeleton:
    path: Path
    length_unit: float  # metres per ASF length unit
    root_order: list[str]
    root_axis: np.ndarray
    root_position: np.ndarray
    bones: dict[str, Bone]
    children: dict[str, list[str]]
    radians: bool = False  # `:units angle rad`: the ASF's angles (and by default the AMC's)

    def order(self) -> list[str]:
        """Bones with every parent before its children, starting at root; a bone reached
        twice (a cycle, or two parents) is a MotionFileError naming it."""
        out, stack, seen = [], ["root"], set()
        while stack:
            name = stack.pop(0)
            if name in seen:
                raise MotionFileError(self.path, f"the hierarchy reaches bone {name!r} twice (a cycle or two parents)")
            seen.add(name)
            out.append(name)
            stack[0:0] = self.children.get(name, [])
        return out

    def parent_of(self) -> dict[str, str]:
        return {c: p for p, cs in self.children.items() for c in cs}


ROOT_CHANNELS = {"TX", "TY", "TZ", "RX", "RY", "RZ"}
ANGLE_UNITS = {"deg": False, "degree": False, "degrees": False, "rad": True, "radian": True, "radians": True}


def _three(path: Path, lineno: int, what: str, values: list[str]) -> np.ndarray:
    out = np.array([float(v) for v in values[:3]])
    if out.shape != (3,) or not np.all(np.isfinite(out)):
        raise MotionFileError(path, f"line {lineno}: {what} needs three finite numbers, got {' '.join(values)!r}")
    return out


def _axis_matrix(values: list[str], order: str, radians: bool = False) -> np.ndarray:
    angles = np.array([float(v) for v in values]) if radians else np.deg2rad([float(v) for v in values])
    return Rotation.from_euler(order.lower(), angles).as_matrix()


def load_asf(path: Path) -> AsfSkeleton:
    path = Path(path)
    lines = [ln.split("#")[0].strip() for ln in read_text(path).splitlines()]
    section = None
    bones: dict[str, Bone] = {}
    children: dict[str, list[str]] = {}
    length = 0.45
    root_order, root_axis, root_position = ["TX", "TY", "TZ", "RX", "RY", "RZ"], np.eye(3), np.zeros(3)
    current: dict | None = None
    radians = False
    try:
        for lineno, line in enumerate(lines, 1):
            if not line:
                continue
            tok = line.split()
            if tok[0].startswith(":"):
                section = tok[0]
                continue
            if section == ":units" and tok[0] == "angle":
                if tok[1].lower() not in ANGLE_UNITS:
                    raise MotionFileError(path, f"line {lineno}: units angle {tok[1]!r}: deg or rad")
                radians = ANGLE_UNITS[tok[1].lower()]
            elif section == ":units" and tok[0] == "length":
                length = float(tok[1])
                if not (np.isfinite(length) and length > 0):
                    raise MotionFileError(path, f"line {lineno}: units length must be a positive number, got {tok[1]}")
            elif section == ":root":
                if tok[0] == "order":
                    root_order = [t.upper() for t in tok[1:]]
                    if not set(root_order) <= ROOT_CHANNELS or len(set(root_order)) != len(root_order):
                        raise MotionFileError(
                            path,
                            f"line {lineno}: root order {' '.join(tok[1:])!r}: each of "
                            f"{', '.join(sorted(ROOT_CHANNELS))} at most once",
                        )
                elif tok[0] == "axis":
                    root_axis = _axis_matrix(["0", "0", "0"], tok[1])
                elif tok[0] == "position":
                    root_position = _three(path, lineno, "root position", tok[1:])
            elif section == ":bonedata":
                if tok[0] == "begin":
                    if len(bones) >= MAX_JOINTS:
                        raise MotionFileError(
                            path, f"line {lineno}: more than {MAX_JOINTS} bones (a body has under 100)"
                        )
                    current = {"dof": []}
                elif tok[0] == "end":
                    if current is None or not {"name", "direction", "length", "axis"} <= current.keys():
                        raise MotionFileError(path, f"line {lineno}: incomplete bone definition")
                    bones[current["name"]] = Bone(
                        current["name"], current["direction"], current["length"], current["axis"], current["dof"]
                    )
                    current = None
                elif current is not None:
                    if tok[0] == "name":
                        current["name"] = tok[1]
                    elif tok[0] == "direction":
                        current["direction"] = _three(path, lineno, "direction", tok[1:])
                    elif tok[0] == "length":
                        current["length"] = float(tok[1])
                        if not (np.isfinite(current["length"]) and current["length"] >= 0):
                            raise MotionFileError(
                                path, f"line {lineno}: bone length must be a number >= 0, got {tok[1]}"
                            )
                    elif tok[0] == "axis":
                        current["axis"] = _axis_matrix(tok[1:4], tok[4] if len(tok) > 4 else "XYZ", radians)
                    elif tok[0] == "dof":
                        current["dof"] = [t.lower() for t in tok[1:]]
                        if not set(current["dof"]) <= {"rx", "ry", "rz"} or len(set(current["dof"])) != len(
                            current["dof"]
                        ):
                            raise MotionFileError(
                                path, f"line {lineno}: dof {' '.join(tok[1:])!r}: each of rx, ry, rz at most once"
                            )
            elif section == ":hierarchy" and tok[0] not in ("begin", "end"):
                children.setdefault(tok[0], []).extend(tok[1:])
    except MotionFileError:
        raise
    except (ValueError, IndexError) as err:
        raise MotionFileError(path, f"malformed ASF ({err})") from None
    if not bones:
        raise MotionFileError(path, "no :bonedata section with bones")
    unknown = [n for p, cs in children.items() for n in [p, *cs] if n != "root" and n not in bones]
    if unknown:
        raise MotionFileError(path, f"hierarchy names undefined bones: {', '.join(sorted(set(unknown)))}")
    parents: dict[str, str] = {}
    for parent, kids in children.items():
        for kid in kids:
            if kid in parents or kid == "root":
                raise MotionFileError(
                    path, f"the hierarchy gives bone {kid!r} a second parent ({parents.get(kid, 'none')} and {parent})"
                )
            parents[kid] = parent
    metres = INCH / length
    for bone in bones.values():
        bone.length *= metres
    skeleton = AsfSkeleton(path, metres, root_order, root_axis, root_position * metres, bones, children, radians)
    skeleton.order()  # a cycle is an error here, not a hang later
    return skeleton


def _read_amc_frames(path: Path, skeleton: AsfSkeleton) -> tuple[dict[str, np.ndarray], bool]:
    """Per-bone (T, n_values) arrays, every frame listing every moving bone once, and whether
    the angles are radians (the `:RADIANS` / `:DEGREES` header; else the ASF's angle unit)."""
    radians = skeleton.radians
    expected = {"root": len(skeleton.root_order)}
    expected.update({n: len(b.dof) for n, b in skeleton.bones.items() if b.dof})
    values: dict[str, list[list[float]]] = {n: [] for n in expected}
    frame_no, frames = None, 0
    seen: set[str] = set()

    def close_frame():
        missing = set(expected) - seen
        if missing:
            raise MotionFileError(path, f"frame {frame_no} is missing bone(s) {', '.join(sorted(missing))}")

    for lineno, line in enumerate(read_text(path).splitlines(), 1):
        line = line.strip()
        if line.upper() in (":RADIANS", ":DEGREES"):
            radians = line.upper() == ":RADIANS"
            continue
        if not line or line[0] in "#:":
            continue
        tok = line.split()
        if len(tok) == 1 and tok[0].isdigit():
            if frame_no is not None:
                close_frame()
            frame_no, seen, frames = int(tok[0]), set(), frames + 1
            continue
        if frame_no is None:
            raise MotionFileError(path, f"line {lineno}: bone values before the first frame number")
        name = tok[0]
        if name not in expected:
            raise MotionFileError(path, f"line {lineno}: bone {name!r} is not a moving bone of {skeleton.path.name}")
        if name in seen:
            raise MotionFileError(path, f"line {lineno}: bone {name!r} twice in frame {frame_no}")
        if len(tok) - 1 != expected[name]:
            raise MotionFileError(
                path, f"line {lineno}: bone {name!r} has {len(tok) - 1} values, its dof needs {expected[name]}"
            )
        try:
            values[name].append([float(v) for v in tok[1:]])
        except ValueError:
            raise MotionFileError(path, f"line {lineno}: non-numeric value for bone {name!r}") from None
        seen.add(name)
    if frame_no is None:
        raise MotionFileError(path, "no frames")
    close_frame()
    return {n: np.asarray(v, dtype=np.float64).reshape(frames, expected[n]) for n, v in values.items()}, radians


def load_amc(amc_path: Path, skeleton: AsfSkeleton, fps: float = 120.0) -> SourceMotion:
    amc_path = Path(amc_path)
    frames, radians = _read_amc_frames(amc_path, skeleton)
    to_radians = (lambda v: v) if radians else np.deg2rad  # noqa: E731
    order = skeleton.order()
    parent = skeleton.parent_of()
    index = {n: i for i, n in enumerate(order)}
    T = len(frames["root"])
    J = len(order)
    rot = np.empty((T, J, 3, 3))
    pos = np.empty((T, J, 3))
    rest = np.zeros((J, 3))
    end = np.empty((T, J, 3))  # where each bone ends: its children start there
    rest_end = np.zeros((J, 3))

    root_vals = frames["root"]
    trans = np.zeros((T, 3))
    angles = {}
    for k, ch in enumerate(skeleton.root_order):
        if ch.startswith("T"):
            trans[:, "XYZ".index(ch[1])] = root_vals[:, k] * skeleton.length_unit
        else:
            angles[ch[1].lower()] = to_radians(root_vals[:, k])
    axes = "".join(a for a in "xyz" if a in angles)
    m = Rotation.from_euler(axes, np.stack([angles[a] for a in axes], -1)).as_matrix() if axes else np.eye(3)
    rot[:, 0] = skeleton.root_axis @ m @ skeleton.root_axis.T
    pos[:, 0] = end[:, 0] = trans + skeleton.root_position
    rest_end[0] = rest[0] = 0.0

    for name in order[1:]:
        i, p = index[name], index[parent[name]]
        bone = skeleton.bones[name]
        if bone.dof:
            vals = to_radians(frames[name])
            axes = "".join(d[1] for d in bone.dof)  # "rx rz" -> "xz": extrinsic, R = Rz @ Rx
            local = Rotation.from_euler(axes, vals).as_matrix()
            rot[:, i] = rot[:, p] @ (bone.axis @ local @ bone.axis.T)
        else:
            rot[:, i] = rot[:, p]
        vec = bone.direction * bone.length
        pos[:, i] = end[:, p]
        end[:, i] = end[:, p] + rot[:, i] @ vec
        rest[i] = rest_end[p]
        rest_end[i] = rest_end[p] + vec
    if not np.all(np.isfinite(pos)):
        raise MotionFileError(amc_path, "non-finite values")
    return SourceMotion(
        stem(amc_path), "cmu_asf", order, [index[parent[n]] if n != "root" else -1 for n in order], rest, pos, rot, fps
    )


def plain_name(path: Path) -> str:
    return path.name.lower().removesuffix(".gz")


def _lower_stem(path: Path) -> str:
    return plain_name(path).rsplit(".", 1)[0]


def skeleton_for(amc: Path, given: Path | None = None) -> tuple[Path, str]:
    """The ASF of an AMC file and how it was found: the one given; the ASF beside it whose name
    is the longest prefix of the AMC file's name (case ignored); the only ASF beside it (the
    two layouts it serves: data/motion_inputs.py)."""
    if given is not None:
        return Path(given), "given"
    beside = sorted(p for p in amc.parent.iterdir() if p.is_file() and plain_name(p).endswith(".asf"))
    name = _lower_stem(amc)
    prefixes = [p for p in beside if name.startswith(_lower_stem(p))]
    if prefixes:
        return max(prefixes, key=lambda p: len(_lower_stem(p))), "name prefix"
    if len(beside) == 1:
        return beside[0], "the only ASF in its folder"
    found = ", ".join(p.name for p in beside) if beside else "none"
    raise MotionFileError(
        amc,
        f"which skeleton? an AMC file gets the ASF beside it whose name starts its own name, "
        f"or the only ASF in its folder (ASF files there: {found}); pair them as "
        f"--motion AMC=ASF or pass --skeleton-file ASF",
    )
