"""The serial wire protocol of microcontroller trackers (docs/serial_protocol.md).

Frame (little-endian):

    A5 5A | version 1 | type | device id | payload length n | device time u32 [us] | payload | CRC-16

type 1: orientation only (IMU), payload qx qy qz qw as float32 (n = 16)
type 2: full pose (Lighthouse), payload px py pz qx qy qz qw as float32 (n = 28)
CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over everything after the sync bytes.

FrameDecoder takes bytes as they arrive (any split) and resynchronises after garbage: a
header that does not fit, or a checksum that fails, costs one byte and the search goes on.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass, field

import numpy as np

SYNC = b"\xa5\x5a"
VERSION = 1
ORIENTATION, POSE = 1, 2
PAYLOAD_LENGTH = {ORIENTATION: 16, POSE: 28}
_HEADER = struct.Struct("<2sBBBBI")  # sync, version, type, device, length, device time
MAX_BUFFER = 4096


def crc16(data: bytes) -> int:
    return binascii.crc_hqx(data, 0xFFFF)


@dataclass(frozen=True)
class Frame:
    device_id: int
    device_time_us: int
    orientation: np.ndarray  # (4,) x y z w
    position: np.ndarray | None  # (3,) or None for orientation-only devices


def encode_frame(device_id: int, device_time_us: int, orientation, position=None) -> bytes:
    kind = ORIENTATION if position is None else POSE
    values = ([] if position is None else list(position)) + list(orientation)
    payload = struct.pack(f"<{len(values)}f", *values)
    body = _HEADER.pack(SYNC, VERSION, kind, device_id & 0xFF, len(payload), device_time_us & 0xFFFFFFFF)[2:] + payload
    return SYNC + body + struct.pack("<H", crc16(body))


@dataclass
class DecoderStats:
    frames: int = 0
    garbage_bytes: int = 0
    bad_checksums: int = 0
    bad_values: int = 0  # well-formed frames whose numbers are not a pose (NaN, zero quaternion)
    counts: dict = field(default_factory=dict)


class FrameDecoder:
    def __init__(self) -> None:
        self._buf = bytearray()
        self.stats = DecoderStats()

    def feed(self, data: bytes) -> list[Frame]:
        self._buf += data
        frames = []
        while True:
            start = self._buf.find(SYNC)
            if start < 0:
                keep = 1 if self._buf.endswith(SYNC[:1]) else 0  # a sync split across reads
                self.stats.garbage_bytes += len(self._buf) - keep
                del self._buf[: len(self._buf) - keep]
                break
            if start:
                self.stats.garbage_bytes += start
                del self._buf[:start]
            if len(self._buf) < _HEADER.size:
                break
            _, version, kind, device, length, dev_time = _HEADER.unpack_from(self._buf)
            if version != VERSION or PAYLOAD_LENGTH.get(kind) != length:
                self._skip()
                continue
            end = _HEADER.size + length + 2
            if len(self._buf) < end:
                break
            (crc,) = struct.unpack_from("<H", self._buf, end - 2)
            if crc != crc16(bytes(self._buf[2 : end - 2])):
                self.stats.bad_checksums += 1
                self._skip()
                continue
            values = np.array(struct.unpack_from(f"<{length // 4}f", self._buf, _HEADER.size), dtype=float)
            del self._buf[:end]
            frame = self._frame(kind, device, dev_time, values)
            if frame is not None:
                frames.append(frame)
        if len(self._buf) > MAX_BUFFER:  # cannot happen with valid lengths; a guard all the same
            self.stats.garbage_bytes += len(self._buf)
            self._buf.clear()
        return frames

    def discard(self) -> None:
        """Forget buffered bytes (a new connection starts mid-stream)."""
        self._buf.clear()

    def _skip(self) -> None:
        self.stats.garbage_bytes += 1
        del self._buf[:1]

    def _frame(self, kind: int, device: int, dev_time: int, values: np.ndarray) -> Frame | None:
        position = values[:3] if kind == POSE else None
        quat = values[-4:]
        norm = np.linalg.norm(quat) if np.all(np.isfinite(quat)) else 0.0
        if not 0.9 < norm < 1.1 or (position is not None and not np.all(np.isfinite(position))):
            self.stats.bad_values += 1
            return None
        self.stats.frames += 1
        self.stats.counts[device] = self.stats.counts.get(device, 0) + 1
        return Frame(device, dev_time, quat / norm, position)
