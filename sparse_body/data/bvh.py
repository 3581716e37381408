"""BVH files: a HIERARCHY of offsets and channels, then a MOTION block of channel values.

Rotation channels compose in the listed order about the joint's own (moving) axes, so
"Zrotation Xrotation Yrotation" is R = Rz @ Rx @ Ry. End Sites carry no channels and are
dropped. Offsets are converted to metres with `length_unit`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from . import MotionFileError
from .source import MAX_JOINTS, SourceMotion, stem

# Length units of the CMU BVH conversions (cgspeed's releases of the CMU database): MotionBuilder and
# 3ds Max releases keep the ASF units (1/0.45 inch), Daz releases use centimetres.
CMU_ASF_UNIT = 0.0254 / 0.45


def _layout(names: list[str]) -> str:
    if "LeftUpLeg" in names and "LowerBack" in names:
        return "cmu_bvh_mb2"
    if "LeftHip" in names and "Chest2" in names:
        return "cmu_bvh_max"
    if "lThigh" in names and "abdomen" in names:
        return "cmu_bvh_daz"
    return "unknown"


_CHANNELS = {f"{a}{kind}" for a in "XYZ" for kind in ("position", "rotation")}


def _check_channels(path: Path, joint: str, channels: list[str]) -> None:
    """Known names, each at most once, and three rotations or none (scipy's Euler order)."""
    for ch in channels:
        if ch[:1].upper() + ch[1:].lower() not in _CHANNELS:
            raise MotionFileError(path, f"joint {joint!r} has unknown channel {ch!r} (known: Xposition ... Zrotation)")
    lowered = [c.lower() for c in channels]
    if len(set(lowered)) != len(lowered):
        raise MotionFileError(path, f"joint {joint!r} lists a channel twice: {' '.join(channels)}")
    rotations = sum(c.endswith("rotation") for c in lowered)
    if rotations not in (0, 3):
        raise MotionFileError(path, f"joint {joint!r} has {rotations} rotation channels (0 or 3 allowed)")


def _motion_values(path: Path, stream, first: bytes, expected: int) -> np.ndarray:
    """The motion's numbers, parsed a chunk at a time into one array of the declared size (a
    file holding more is cut at one value over, enough to say so)."""
    values = np.empty(expected + 1)
    count, pending = 0, first
    while True:
        chunk = stream.read(CHUNK)
        data = pending + chunk
        if chunk:  # the last token may continue in the next chunk
            cut = max(data.rfind(b" "), data.rfind(b"\n"), data.rfind(b"\t"), data.rfind(b"\r"))
            data, pending = (data[: cut + 1], data[cut + 1 :]) if cut >= 0 else (b"", data)
        try:
            parsed = np.array(data.split(), dtype=np.float64)
        except ValueError:
            raise MotionFileError(path, "malformed MOTION header or non-numeric motion data") from None
        take = min(len(parsed), len(values) - count)
        values[count : count + take] = parsed[:take]
        count += take
        if not chunk or count > expected:
            return values[:count]


def default_unit(layout: str) -> float:
    return 0.01 if layout == "cmu_bvh_daz" else CMU_ASF_UNIT


CHUNK = 8 << 20  # bytes of motion data parsed at a time
# Bytes a SourceMotion holds per frame and joint (a rotation and a position, float64), and per
# channel value while the values are parsed: what the motion size limit bounds, so that a file
# within it is read in memory of the same order, not some 20 times its size.
JOINT_FRAME_BYTES = (9 + 3) * 8
VALUE_BYTES = 8


def load_bvh(path: Path, length_unit: float | None = None) -> SourceMotion:
    """A BVH file (gzip-compressed when it ends in .gz), read as a stream: the hierarchy as
    text, the motion parsed into its array a chunk at a time. A file whose declared frames
    need more memory than the motion size limit allows is refused before they are read."""
    path = Path(path)
    if not path.is_file():
        raise MotionFileError(path, "no such file")
    import gzip

    from ..core.textfile import FileTooLarge, limit_bytes, too_large

    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rb") as raw:
            return _read_bvh(path, _LimitedStream(raw, path), length_unit, limit_bytes("motion"))
    except FileTooLarge as err:
        raise too_large(MotionFileError)(path, str(err).removeprefix(f"{path}: ")) from None
    except (OSError, EOFError) as err:  # a truncated .gz raises EOFError
        raise MotionFileError(path, f"cannot be read ({err})") from None


class _LimitedStream:
    """A file's bytes with read(n); past the motion size limit, FileTooLarge."""

    def __init__(self, file, path: Path) -> None:
        from ..core.textfile import limit_bytes

        self.file, self.path, self.limit, self.count = file, path, limit_bytes("motion"), 0

    def read(self, n: int) -> bytes:
        from ..core.textfile import LIMITS, MIB, FileTooLarge

        data = self.file.read(n)
        self.count += len(data)
        if self.count > self.limit:
            variable, _ = LIMITS["motion"]
            raise FileTooLarge(
                f"{self.path}: larger than the {self.limit / MIB:g} MiB allowed for a motion file "
                f"(set {variable} to raise it)"
            )
        return data


def _head(path: Path, stream) -> tuple[str, bytes]:
    """The text up to the first motion value ("... Frame Time: 0.0083"), and the bytes read after it."""
    buffer = b""
    while True:
        chunk = stream.read(1 << 20)
        buffer += chunk
        at = buffer.find(b"Frame Time:")
        if at >= 0:
            end = at + len(b"Frame Time:")
            # the frame time itself: the next token, whole
            while len(buffer) - end < 64 and chunk:
                chunk = stream.read(1 << 20)
                buffer += chunk
            rest = buffer[end:].lstrip()
            token_end = len(rest.split(None, 1)[0]) if rest.split(None, 1) else 0
            cut = len(buffer) - len(rest) + token_end
            return buffer[:cut].decode("utf-8", errors="replace"), buffer[cut:]
        if not chunk:
            return buffer.decode("utf-8", errors="replace"), b""
        if len(buffer) > 64 << 20:  # a hierarchy of MAX_JOINTS joints is under 1 MB
            raise MotionFileError(path, "no MOTION frames within its first 64 MB")


def _read_bvh(path: Path, stream, length_unit: float | None, limit: int) -> SourceMotion:
    text, after = _head(path, stream)
    head, sep, motion = text.partition("MOTION")
    if not head.lstrip().startswith("HIERARCHY"):
        raise MotionFileError(path, "does not start with HIERARCHY")
    if not sep:
        raise MotionFileError(path, "no MOTION section (file truncated?)")

    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float] | None] = []
    channels: list[list[str]] = []
    stack: list[int] = []
    tokens = head.split()
    i = 1
    try:
        while i < len(tokens):
            tok = tokens[i]
            if tok in ("ROOT", "JOINT", "End") and len(names) >= MAX_JOINTS:
                raise MotionFileError(path, f"more than {MAX_JOINTS} joints in HIERARCHY (a body has under 100)")
            if tok in ("ROOT", "JOINT"):
                names.append(tokens[i + 1])
                parents.append(stack[-1] if stack else -1)
                offsets.append(None)
                channels.append([])
                i += 2
            elif tok == "End":
                # Kept as a joint without channels: its position is a useful end point
                # (the toe of a Daz foot, the top of the head).
                names.append(f"{names[stack[-1]]}_End")
                parents.append(stack[-1])
                offsets.append(None)
                channels.append([])
                i += 2
            elif tok == "{":
                stack.append(len(names) - 1)
                i += 1
            elif tok == "}":
                stack.pop()
                i += 1
            elif tok == "OFFSET":
                offset = [float(v) for v in tokens[i + 1 : i + 4]]
                offsets[-1] = offset
                if len(offset) != 3 or not np.all(np.isfinite(offset)):
                    raise MotionFileError(path, f"joint {names[-1]!r} has a malformed OFFSET")
                i += 4
            elif tok == "CHANNELS":
                n = int(tokens[i + 1])
                if not 0 <= n <= 6 or len(tokens) < i + 2 + n:
                    raise MotionFileError(
                        path, f"joint {names[-1]!r} declares {tokens[i + 1]} CHANNELS (0 to 6 allowed)"
                    )
                channels[-1] = tokens[i + 2 : i + 2 + n]
                _check_channels(path, names[-1], channels[-1])
                i += 2 + n
            else:
                raise MotionFileError(path, f"unexpected token {tok!r} in HIERARCHY")
    except MotionFileError:
        raise
    except (ValueError, IndexError):
        raise MotionFileError(path, "malformed HIERARCHY") from None
    if not names or any(o is None for o in offsets) or stack:
        raise MotionFileError(path, "malformed HIERARCHY (unbalanced braces or a joint without OFFSET)")

    header, _, data = motion.partition("Frame Time:")
    try:
        frames = int(header.split("Frames:")[1].split()[0])
        frame_time = float(data.split()[0])
    except (IndexError, ValueError):
        raise MotionFileError(path, "malformed MOTION header or non-numeric motion data") from None
    # 1/1000 s to 10 s a frame: what a motion capture system records
    if not 1e-3 <= frame_time <= 10.0:
        raise MotionFileError(path, f"Frame Time {frame_time!r} is not a frame duration (1 ms to 10 s)")
    fps = 1.0 / frame_time
    n_channels = sum(len(c) for c in channels)
    needed = frames * (len(names) * JOINT_FRAME_BYTES + n_channels * VALUE_BYTES)
    if needed > limit:
        from ..core.textfile import LIMITS, MIB, FileTooLarge

        variable, _ = LIMITS["motion"]
        raise FileTooLarge(
            f"{path}: {frames:,} frames of {len(names)} joints need {needed / MIB:,.0f} MiB once read, more than "
            f"the {limit / MIB:g} MiB allowed for a motion file (set {variable} to raise it)"
        )
    values = _motion_values(path, stream, after, max(frames, 0) * n_channels)
    if frames <= 0 or values.size != frames * n_channels:
        have = values.size / n_channels if n_channels else 0
        raise MotionFileError(
            path, f"MOTION declares {frames} frames of {n_channels} channels but holds {have:g} frames (truncated?)"
        )
    values = values.reshape(frames, n_channels)

    layout = _layout(names)
    unit = default_unit(layout) if length_unit is None else length_unit
    bone_offsets = np.asarray(offsets, dtype=np.float64) * unit
    J = len(names)
    rot = np.empty((frames, J, 3, 3))
    pos = np.empty((frames, J, 3))
    rest = np.zeros((J, 3))
    col = 0
    for j in range(J):
        local = np.broadcast_to(np.eye(3), (frames, 3, 3))
        trans = np.zeros((frames, 3))
        rot_axes, rot_cols = "", []
        for ch in channels[j]:
            kind = ch[1:].lower()
            if kind == "position":
                trans[:, "XYZ".index(ch[0].upper())] = values[:, col] * unit
            elif kind == "rotation":
                rot_axes += ch[0].upper()
                rot_cols.append(col)
            else:
                raise MotionFileError(path, f"joint {names[j]!r} has unknown channel {ch!r}")
            col += 1
        if rot_axes:
            local = Rotation.from_euler(rot_axes, np.deg2rad(values[:, rot_cols])).as_matrix()
        p = parents[j]
        if p < 0:
            rot[:, j] = local
            pos[:, j] = bone_offsets[j] + trans
        else:
            rot[:, j] = rot[:, p] @ local
            pos[:, j] = pos[:, p] + np.einsum("tab,tb->ta", rot[:, p], bone_offsets[j] + trans)
            rest[j] = rest[p] + bone_offsets[j]
    if not np.all(np.isfinite(pos)):
        raise MotionFileError(path, "non-finite values")
    return SourceMotion(stem(path), layout, names, parents, rest, pos, rot, fps)
