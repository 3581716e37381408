"""Where the tracker bridge's samples come from: a recorded bag, or live devices (VMC over
UDP, the serial tracker protocol). Each is a TrackerSource; the bridge (a lifecycle node)
makes one at configure, starts it at activate, stops it at deactivate and closes it at
cleanup. A source hands the bridge lists of Sample tuples; the bridge applies the
calibration and publishes them on /tf. Sources know nothing of ROS but the clock they are
given.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from ..adapters.vmc import map_device, parse_device_map
from ..core.sensors import SensorConfig
from ..io.bagio import read_tf_messages

if TYPE_CHECKING:  # imported where used: each source loads only its own transport
    from ..adapters.serial_reader import SerialTrackerReader
    from ..adapters.vmc import VmcReceiver

# (site or None, parent frame or None: the fixed frame, child frame, stamp, position or None,
# quaternion x y z w)
Sample = tuple[str | None, str | None, str, float, np.ndarray | None, np.ndarray]
Send = Callable[[list[Sample]], None]


class TrackerSource(Protocol):
    def start(self) -> None:
        """Begin handing samples to the bridge."""

    def stop(self) -> None:
        """Hand no more samples until started again."""

    def close(self) -> None:
        """Release the transport (a socket, a serial port, a thread); the source is done."""

    def diagnostics(self) -> tuple[str, dict[str, str]]:
        """(a problem, or "" when there is none; figures) for /diagnostics."""


class BagSource:
    """A rosbag2 of tracker /tf replayed at its recorded pace (rate times faster), restamped
    to now by default, once or in a loop. ready() says when to begin (the bridge waits for
    its /tf subscribers: /tf is volatile, what goes out before they match is lost to them)."""

    def __init__(
        self,
        path: str,
        sensors: SensorConfig,
        send: Send,
        now: Callable[[], float],
        rate: float = 1.0,
        loop: bool = False,
        restamp: bool = True,
        ready: Callable[[threading.Event], bool] = lambda stop: True,
        log: Callable[[str], object] = print,
    ) -> None:
        if rate <= 0:
            raise ValueError(f"parameter 'rate' must be positive, got {rate}")
        self.frames = read_tf_messages(Path(path))
        self.site_of_frame = {s.frame_id: s.site for s in sensors.sites}
        self.send, self.now, self.ready, self.log = send, now, ready, log
        self.rate, self.loop, self.restamp = rate, loop, restamp
        self.played = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self._play, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            # The player must be out of publish() before the node and the DDS participant go:
            # a thread left inside it at exit holds the writer's lock, and the participant's
            # teardown then waits for it forever (a launch test's bridge was killed after
            # 15 s on a starved machine; its join gave up after 2 s). A reliable publish
            # blocks for a bounded time; 10 s stays within launch's SIGINT-to-SIGKILL 15 s.
            self._thread.join(timeout=10.0)
            if self._thread.is_alive():
                self.log("the bag player did not stop within 10 s")
            self._thread = None

    close = stop

    def diagnostics(self) -> tuple[str, dict[str, str]]:
        return "", {"bag messages": str(len(self.frames)), "bag messages played": str(self.played)}

    def _play(self) -> None:
        if not self.ready(self._stop):
            return
        while True:
            start = time.monotonic()
            for t_rel, rows in self.frames:
                delay = start + t_rel / self.rate - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    return
                if self._stop.is_set():
                    return
                now = self.now()
                self.send(
                    [
                        (self.site_of_frame.get(child), parent, child, now if self.restamp else stamp, v[:3], v[3:])
                        for parent, child, stamp, v in rows
                    ]
                )
                self.played += 1
            if not self.loop:
                self.log("finished playing")
                return


class DeviceSource:
    """Live devices, VMC over UDP or the serial protocol, sent to body sites by a device map
    (PATTERN=SITE entries) and stamped with each sample's (device-clock corrected) time;
    samples older than stale_after when they arrive are dropped and counted. The transport
    is opened here (so a port in use fails configure); samples reach the bridge while the
    source is started."""

    def __init__(self, kind: str, params: dict, sensors: SensorConfig, send: Send) -> None:
        self.sensors, self.send, self.stale_after = sensors, send, params["stale_after"]
        entries = [e for e in params["devices"] if e]
        if not entries:
            if kind == "vmc":
                entries = ["hmd:*=head"]
            else:
                entries = [f"serial:{i + 1}={s.site}" for i, s in enumerate(sensors.sites)]
        self.device_map = parse_device_map(entries)
        unknown = {site for _, site in self.device_map} - set(sensors.site_names)
        if unknown:
            raise ValueError(
                f"devices map to {', '.join(sorted(unknown))}, which sensor configuration "
                f"{sensors.name!r} does not have"
            )
        self.counts = {"stale": 0, "unmapped": 0}
        self.unmapped: set[str] = set()
        self._lock = threading.Lock()  # the counts change on the transport's thread
        self.running = False
        self.adapter: VmcReceiver | SerialTrackerReader
        if kind == "vmc":
            from ..adapters.vmc import VmcReceiver

            self.adapter = VmcReceiver(self._on_samples, params["vmc_host"], params["vmc_port"])
            self.where = f"listening for VMC on {self.adapter.address[0]}:{self.adapter.address[1]}"
        else:
            from ..adapters.serial_reader import SerialTrackerReader

            self.adapter = SerialTrackerReader(params["serial_port"], self._on_samples, params["serial_baudrate"])
            self.where = f"reading serial trackers from {params['serial_port']}"

    def start(self) -> None:
        self.running = True

    def stop(self) -> None:
        self.running = False

    def close(self) -> None:
        self.running = False
        self.adapter.close()

    def diagnostics(self) -> tuple[str, dict[str, str]]:
        problem, figures = self.adapter.diagnostics()
        with self._lock:
            figures = {**figures, **{k: str(v) for k, v in self.counts.items()}}
            figures["unmapped devices"] = ", ".join(sorted(self.unmapped)) or "none"
        return problem or "", figures

    def _on_samples(self, samples) -> None:
        if not self.running:
            return
        now = time.time()
        out: list[Sample] = []
        for sample in samples:
            site = map_device(sample.device, self.device_map)
            if site is None:
                with self._lock:
                    self.counts["unmapped"] += 1
                    self.unmapped.add(sample.device)
                continue
            if sample.stamp < now - self.stale_after:
                with self._lock:
                    self.counts["stale"] += 1
                continue
            spec = self.sensors.site(site)
            position = sample.position if (sample.position is not None and spec.has_position) else None
            out.append((site, None, spec.frame_id, sample.stamp, position, np.asarray(sample.orientation, float)))
        if out:
            self.send(out)
