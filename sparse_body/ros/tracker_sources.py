"""Where the tracker bridge's samples come from: a recorded bag, or live devices (VMC over
UDP, the serial tracker protocol). Each is a TrackerSource; the bridge (a lifecycle node)
makes one at configure (by the name its `source` parameter gives, from SOURCES), starts it at
activate, stops it at deactivate and closes it at cleanup. A source hands the bridge lists of
Sample tuples; the bridge applies the calibration and publishes them on /tf. Sources know
nothing of ROS but the clock they are given.

A new source is one file with a function that makes it from a SourceContext, and its line in
SOURCES (as a method is one folder and its line in methods/__init__.py); its module is
imported only when it is chosen.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib import import_module
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


@dataclass(frozen=True)
class SourceContext:
    """What the bridge gives a source's maker."""

    params: dict  # the bridge's parameters (a source reads its own: bag, rate, vmc_port, ...)
    sensors: SensorConfig
    send: Send  # hands samples to the bridge (from any thread)
    now: Callable[[], float]  # the node's clock [s]
    ready: Callable[[threading.Event], bool]  # waits for the /tf subscribers (False: stopped first)
    log: Callable[[str], object]


# source name -> "module:function" making it from a SourceContext
SOURCES = {
    "bag": "sparse_body.ros.tracker_sources:bag_source",
    "vmc": "sparse_body.ros.tracker_sources:vmc_source",
    "serial": "sparse_body.ros.tracker_sources:serial_source",
}


def make_source(name: str, context: SourceContext) -> TrackerSource:
    """The source a name in SOURCES makes (ValueError for another name)."""
    if name not in SOURCES:
        raise ValueError(f"parameter 'source' must be one of {', '.join(SOURCES)}, got {name!r}")
    module, _, function = SOURCES[name].partition(":")
    return getattr(import_module(module), function)(context)


def bag_source(c: SourceContext) -> BagSource:
    p = c.params
    if not p["bag"]:
        raise ValueError("parameter 'bag' is empty: name a rosbag2 of tracker TF")
    source = BagSource(p["bag"], c.sensors, c.send, c.now, p["rate"], p["loop"], p["restamp"], c.ready, c.log)
    c.log(f"playing {len(source.frames)} TF messages from {p['bag']}")
    return source


def vmc_source(c: SourceContext) -> DeviceSource:
    from ..adapters.vmc import VmcReceiver

    host, port = c.params["vmc_host"], c.params["vmc_port"]
    source = DeviceSource(c, ["hmd:*=head"], lambda on_samples: VmcReceiver(on_samples, host, port))
    assert isinstance(source.adapter, VmcReceiver)
    address = source.adapter.address
    c.log(f"listening for VMC on {address[0]}:{address[1]}")
    return source


def serial_source(c: SourceContext) -> DeviceSource:
    from ..adapters.serial_reader import SerialTrackerReader

    port, baudrate = c.params["serial_port"], c.params["serial_baudrate"]
    source = DeviceSource(
        c,
        [f"serial:{i + 1}={s.site}" for i, s in enumerate(c.sensors.sites)],
        lambda on_samples: SerialTrackerReader(port, on_samples, baudrate),
    )
    c.log(f"reading serial trackers from {port}")
    return source


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
    """Live devices (VMC over UDP, the serial protocol: their transport), sent to body sites by a device map
    (PATTERN=SITE entries) and stamped with each sample's (device-clock corrected) time;
    samples older than stale_after when they arrive are dropped and counted. The transport
    is opened here (so a port in use fails configure); samples reach the bridge while the
    source is started."""

    def __init__(self, context: SourceContext, default_map: list[str], open_transport: Callable) -> None:
        """default_map: the device map where the `devices` parameter gives none; open_transport:
        the transport (VmcReceiver, SerialTrackerReader) for a callback taking its samples."""
        params, sensors = context.params, context.sensors
        self.sensors, self.send, self.stale_after = sensors, context.send, params["stale_after"]
        entries = [e for e in params["devices"] if e] or default_map
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
        self.adapter: VmcReceiver | SerialTrackerReader = open_transport(self._on_samples)

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
