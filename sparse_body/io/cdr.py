"""CDR bytes of the output messages for a whole recording at once, without a Python object
per field.

ROS 2 serialises messages as XCDR1, little-endian: a 4-byte encapsulation header, then the
fields in order, each number aligned to its own size counted from the end of that header,
strings as a length (with the terminating NUL) and the bytes, sequences as a count and the
elements. Once the frame names, joint names and message strings of our outputs are chosen,
everything but the numbers is the same in every message: a Layout writes that template once
and remembers where the numbers go, and numpy writes a recording's numbers into one row per
message. rosbags' `serialize_cdr` (the reference, and the reader everywhere) builds a
dataclass per field, about 70 microseconds a transform; the bytes are the same (test)."""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR, little-endian


@dataclass
class Layout:
    """One message's bytes with slots for its numbers, written field by field in order."""

    buf: bytearray = field(default_factory=lambda: bytearray(ENCAPSULATION))

    def _align(self, size: int) -> None:
        self.buf += bytes(-(len(self.buf) - len(ENCAPSULATION)) % size)

    def _slot(self, size: int, align: int) -> int:
        self._align(align)
        offset = len(self.buf)
        self.buf += bytes(size)
        return offset

    def uint32(self, value: int) -> None:
        self._align(4)
        self.buf += struct.pack("<I", value)

    def boolean(self, value: bool) -> None:
        self.buf += b"\x01" if value else b"\x00"

    def string(self, text: str) -> None:
        data = text.encode()
        self.uint32(len(data) + 1)
        self.buf += data + b"\x00"

    def stamp(self) -> int:
        """A builtin_interfaces/Time (int32 sec, uint32 nanosec): its offset."""
        return self._slot(8, 4)

    def doubles(self, count: int) -> int:
        return self._slot(8 * count, 8)

    def float32(self) -> int:
        return self._slot(4, 4)

    def rows(self, count: int) -> np.ndarray:
        """count copies of the template, one message per row."""
        return np.tile(np.frombuffer(bytes(self.buf), np.uint8), (count, 1))


def stamp_parts(seconds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sec, nanosec) of times in seconds, as output.stamp_parts does for one: nanoseconds that
    round up to a whole second carry into the seconds."""
    seconds = np.asarray(seconds, dtype=np.float64)
    sec = np.floor(seconds)
    nanosec = np.round((seconds - sec) * 1e9)
    carry = nanosec >= 1e9
    return (sec + carry).astype(np.int64), np.where(carry, nanosec - 1e9, nanosec).astype(np.int64)


def _put(rows: np.ndarray, offset: int, dtype: str, values: np.ndarray) -> None:
    width = np.dtype(dtype).itemsize
    values = np.asarray(values)
    count = values.shape[-1] if values.ndim > 1 else 1
    rows[:, offset : offset + width * count].view(dtype)[:] = values.reshape(len(rows), count)


def _put_stamp(rows: np.ndarray, offset: int, sec: np.ndarray, nanosec: np.ndarray) -> None:
    _put(rows, offset, "<i4", sec)
    _put(rows, offset + 4, "<u4", nanosec)


def _header(layout: Layout, frame_id: str) -> int:
    offset = layout.stamp()
    layout.string(frame_id)
    return offset


def tf_messages(stamps, parents: list[str], children: list[str], values: np.ndarray) -> list[bytes]:
    """tf2_msgs/TFMessage per frame, each holding the transforms parents[k] -> children[k]
    stamped with the frame's stamp; values (frames, k, 7): translation, then quaternion xyzw."""
    layout = Layout()
    layout.uint32(len(children))
    slots = []
    for parent, child in zip(parents, children, strict=True):
        stamp = _header(layout, parent)
        layout.string(child)
        slots.append((stamp, layout.doubles(7)))  # Vector3 and Quaternion: 7 doubles in a row
    rows = layout.rows(len(values))
    sec, nanosec = stamp_parts(stamps)
    for k, (stamp, numbers) in enumerate(slots):
        _put_stamp(rows, stamp, sec, nanosec)
        _put(rows, numbers, "<f8", values[:, k])
    return [row.tobytes() for row in rows]


def joint_state_messages(stamps, names: list[str], positions: np.ndarray) -> list[bytes]:
    """sensor_msgs/JointState per frame: no frame_id, the names, positions (frames, len(names)),
    no velocities or efforts."""
    layout = Layout()
    stamp = _header(layout, "")
    layout.uint32(len(names))
    for name in names:
        layout.string(name)
    layout.uint32(len(names))
    numbers = layout.doubles(len(names))
    layout.uint32(0)  # velocity
    layout.uint32(0)  # effort
    rows = layout.rows(len(positions))
    _put_stamp(rows, stamp, *stamp_parts(stamps))
    _put(rows, numbers, "<f8", positions)
    return [row.tobytes() for row in rows]


def foot_contact_messages(
    stamps, frame_id: str, names: list[str], contact: np.ndarray, probability: np.ndarray, points: np.ndarray
) -> list[bytes]:
    """sparse_body/FootContacts per frame: contact (frames, feet) bool, probability (frames,
    feet), points (frames, feet, 3)."""
    out: list[bytes] = [b""] * len(stamps)
    contact = np.asarray(contact, bool)
    for pattern in {tuple(row) for row in contact.tolist()}:  # in_contact is a byte: a template per pattern
        layout = Layout()
        stamp = _header(layout, frame_id)
        layout.uint32(len(names))
        feet = []
        for name, touching in zip(names, pattern, strict=True):
            layout.string(name)
            layout.boolean(touching)
            feet.append((layout.float32(), layout.doubles(3)))
        which = np.flatnonzero(np.all(contact == np.array(pattern, bool), axis=1))
        rows = layout.rows(len(which))
        _put_stamp(rows, stamp, *stamp_parts(np.asarray(stamps)[which]))
        for k, (prob, point) in enumerate(feet):
            _put(rows, prob, "<f4", np.asarray(probability, np.float64)[which, k].astype(np.float32))
            _put(rows, point, "<f8", np.asarray(points)[which, k])
        for i, row in zip(which, rows, strict=True):
            out[i] = row.tobytes()
    return out


def status_messages(stamps, frame_id: str, valid: np.ndarray, held_message: str) -> list[bytes]:
    """sparse_body/EstimateStatus per frame: valid with an empty message, else held_message."""
    out: list[bytes] = [b""] * len(stamps)
    valid = np.asarray(valid, bool)
    for state in (True, False):
        which = np.flatnonzero(valid == state)
        layout = Layout()
        stamp = _header(layout, frame_id)
        layout.boolean(state)
        layout.string("" if state else held_message)
        rows = layout.rows(len(which))
        _put_stamp(rows, stamp, *stamp_parts(np.asarray(stamps)[which]))
        for i, row in zip(which, rows, strict=True):
            out[i] = row.tobytes()
    return out
