"""The VMC protocol (OSC over UDP) as SlimeVR, Virtual Motion Capture and similar tools send it.

Tracking messages carry a device name and a pose in Unity's left-handed frame (x right,
y up, z forward):

    /VMC/Ext/Hmd/Pos   name px py pz qx qy qz qw      the headset
    /VMC/Ext/Con/Pos   name px py pz qx qy qz qw      controllers
    /VMC/Ext/Tra/Pos   name px py pz qx qy qz qw      generic trackers
    /VMC/Ext/Root/Pos  name px py pz qx qy qz qw [scale and offset, VMC 2.1]

Each device becomes "<kind>:<name>" (hmd:, con:, tra:, root:), which a device map sends
to a body site. Everything else VMC sends (bones, blendshapes, status) is ignored; a
datagram that is not OSC, or a tracking message with the wrong arguments, is counted and
dropped. Parsing is python-osc's; decoding a datagram never raises.
"""

from __future__ import annotations

import fnmatch
import socket
import threading
import time
from collections import Counter

import numpy as np

from .sample import TrackerSample, valid_pose

KINDS = {"/VMC/Ext/Hmd/Pos": "hmd", "/VMC/Ext/Con/Pos": "con", "/VMC/Ext/Tra/Pos": "tra", "/VMC/Ext/Root/Pos": "root"}
DEFAULT_PORT = 39539


def unity_to_rep103(position, quat) -> tuple[np.ndarray, np.ndarray]:
    """Unity (x right, y up, z forward, left-handed) -> REP-103 (x forward, y left, z up).

    Positions: (x, y, z) -> (z, -x, y). A rotation R becomes M R M^T with M the (improper)
    axis change; for a quaternion that flips the vector part through M and negates it."""
    x, y, z = position
    qx, qy, qz, qw = quat
    return np.array([z, -x, y], dtype=float), np.array([-qz, qx, -qy, qw], dtype=float)


def parse_device_map(entries) -> list[tuple[str, str]]:
    """["hmd:*=head", "con:LHR-1234=left_hand"] -> [(pattern, site)]; first match wins."""
    from ..core.sensors import SITE_JOINTS

    out = []
    for entry in entries:
        pattern, eq, site = str(entry).partition("=")
        if not eq or not pattern.strip():
            raise ValueError(f"device map entry {entry!r} is not PATTERN=SITE")
        if site.strip() not in SITE_JOINTS:
            raise ValueError(
                f"device map entry {entry!r}: unknown body site {site.strip()!r}; sites are {', '.join(SITE_JOINTS)}"
            )
        out.append((pattern.strip(), site.strip()))
    return out


def map_device(device: str, device_map: list[tuple[str, str]]) -> str | None:
    for pattern, site in device_map:
        if fnmatch.fnmatchcase(device, pattern):
            return site
    return None


def _structure_is_sane(data: bytes, depth: int = 0) -> bool:
    """Bundle framing checked before python-osc sees it: python-osc 1.10 loops forever on a
    bundle element whose size is negative (found by `sparse_body.apps.fuzz vmc`), so a
    73-byte datagram would hang the receiver. Sizes must be positive multiples of 4 that fit."""
    if not data.startswith(b"#bundle\0"):
        return True
    if depth > 8 or len(data) < 16:
        return False
    i = 16
    while i < len(data):
        if i + 4 > len(data):
            return False
        size = int.from_bytes(data[i : i + 4], "big", signed=True)
        if size <= 0 or size % 4 or i + 4 + size > len(data):
            return False
        if not _structure_is_sane(data[i + 4 : i + 4 + size], depth + 1):
            return False
        i += 4 + size
    return True


class VmcDecoder:
    def __init__(self) -> None:
        self.errors: Counter[str] = Counter()
        self.devices: Counter[str] = Counter()

    def datagram(self, data: bytes, arrival: float) -> list[TrackerSample]:
        from pythonosc.osc_packet import OscPacket

        data = bytes(data)
        if not _structure_is_sane(data):
            self.errors["not OSC"] += 1
            return []
        try:
            messages = OscPacket(data).messages
        except Exception:  # noqa: BLE001 - python-osc raises ParseError and, on some inputs, others
            self.errors["not OSC"] += 1
            return []
        samples = []
        for timed in messages:
            kind = KINDS.get(str(getattr(timed.message, "address", "")))
            if kind is None:
                continue
            sample = self._tracking(kind, list(timed.message.params), arrival)
            if sample is not None:
                samples.append(sample)
        return samples

    def _tracking(self, kind: str, params: list, arrival: float) -> TrackerSample | None:
        if len(params) < 8 or not isinstance(params[0], str):
            self.errors["bad arguments"] += 1
            return None
        try:
            values = np.array([float(v) for v in params[1:8]])
        except (TypeError, ValueError):
            self.errors["bad arguments"] += 1
            return None
        position, quat = unity_to_rep103(values[:3], values[3:7])
        if not valid_pose(position, quat):
            self.errors["not a pose"] += 1
            return None
        device = f"{kind}:{params[0]}"
        self.devices[device] += 1
        return TrackerSample(device, arrival, quat / np.linalg.norm(quat), position)


class VmcReceiver:
    """A UDP socket on host:port in a thread, handing decoded samples to on_samples."""

    def __init__(self, on_samples, host: str = "127.0.0.1", port: int = DEFAULT_PORT) -> None:
        self.decoder = VmcDecoder()
        self._on_samples = on_samples
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as err:
            self._sock.close()
            raise ValueError(f"cannot listen for VMC on {host}:{port} ({err.strerror})") from None
        self._sock.settimeout(0.1)
        self.address = self._sock.getsockname()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="vmc-receiver", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, _ = self._sock.recvfrom(65536)
            except TimeoutError:
                continue
            except OSError:
                break
            samples = self.decoder.datagram(data, time.time())
            if samples:
                self._on_samples(samples)

    def diagnostics(self) -> tuple[str | None, dict[str, str]]:
        """(the problem, if any; figures) for the bridge's diagnostic status."""
        values = {f"errors: {k}": str(v) for k, v in self.decoder.errors.items()}
        values["devices seen"] = ", ".join(sorted(self.decoder.devices)) or "none"
        return None, values

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        self._sock.close()
