"""Tracker poses from a source, published as TF: a recorded bag, VMC over UDP, or serial devices.

- source:=bag replays a rosbag2 of tracker /tf (as `sparse-body make-bag` writes, or a
  recording of real trackers) at the recorded pace, restamped to now by default.
- source:=vmc listens for the VMC protocol (SlimeVR, Virtual Motion Capture) on
  vmc_host:vmc_port; source:=serial reads the serial tracker protocol
  (docs/serial_protocol.md) from serial_port and reconnects when the device comes back.
  Their devices are sent to body sites by the `devices` map (PATTERN=SITE) and published
  under the sensor configuration's frame names, stamped with the sample's (device-clock
  corrected) time. Orientation-only devices get a zero translation on TF; the sensor
  configuration marks them `measures: orientation`, so no estimator ever reads it.

A T-pose calibration (service ~/calibrate) measures each tracker's rotation offset and the
person's height; from then on (and at start, from the `calibration` file) the bridge
publishes joint-aligned orientations.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSProfile

from ..adapters.vmc import DEFAULT_PORT, map_device, parse_device_map
from ..core.calibration import Calibration, CalibrationError, calibrate_tpose
from ..core.sensors import SensorConfigError, load_sensor_config
from ..io.bagio import TF_TOPIC, BagError, typestore
from .messages import to_time
from .spin import init, spin_until_shutdown

if TYPE_CHECKING:  # imported where used: each source loads only its own transport
    from ..adapters.serial_reader import SerialTrackerReader
    from ..adapters.vmc import VmcReceiver

SOURCES = ("bag", "vmc", "serial")
PARAMETERS = {
    "source": ("bag", "where tracker poses come from: bag, vmc or serial"),
    "sensors": ("six_point", "sensor configuration naming the body sites' TF frames and fixed frame"),
    "bag": ("", "source bag: rosbag2 directory (or .mcap / .db3 file) holding tracker /tf"),
    "rate": (1.0, "source bag: playback speed factor"),
    "loop": (False, "source bag: start again at the end"),
    "restamp": (True, "source bag: stamp transforms with the current time instead of the recorded one"),
    "min_subscribers": (1, "wait until this many /tf subscribers are matched before publishing"),
    "start_delay": (0.5, "seconds to wait after that, so late subscribers can connect too"),
    "devices": (
        [""],
        "vmc / serial: PATTERN=SITE entries mapping device names (hmd:NAME, con:NAME, "
        "tra:NAME, serial:ID) to body sites; empty: hmd:*=head for vmc, serial:N = "
        "the N-th site of the sensor configuration for serial",
    ),
    "vmc_host": ("127.0.0.1", "vmc: address to listen on"),
    "vmc_port": (DEFAULT_PORT, "vmc: UDP port to listen on"),
    "serial_port": ("", "serial: device or pyserial URL (/dev/ttyUSB0, loop://, socket://host:port)"),
    "serial_baudrate": (921600, "serial: baud rate"),
    "stale_after": (0.25, "vmc / serial: samples older than this (s) when they arrive are dropped and counted"),
    "calibration": ("", "T-pose calibration YAML: applied at start when it exists; where ~/calibrate saves by default"),
    "calibration_dir": (
        "",
        "folder under which a ~/calibrate request's save_path may write (it must exist); "
        "empty: requests cannot name a file, only the calibration parameter's is written",
    ),
}
MAX_CALIBRATION_SECONDS = 30.0


def load_tf_frames(path: str) -> list[tuple[float, list]]:
    """(seconds from the first message, [(parent, child, stamp, translation, rotation)]) per /tf message."""
    from rosbags.rosbag2 import Reader

    store = typestore()
    out, first = [], None
    try:
        with Reader(Path(path)) as reader:
            conns = [c for c in reader.connections if c.topic == TF_TOPIC]
            if not conns:
                raise BagError(f"{path}: no {TF_TOPIC} topic")
            for conn, t_ns, raw in reader.messages(connections=conns):
                msg = store.deserialize_cdr(raw, conn.msgtype)
                first = t_ns if first is None else first
                out.append(
                    (
                        (t_ns - first) * 1e-9,
                        [
                            (
                                tf.header.frame_id,
                                tf.child_frame_id,
                                tf.header.stamp.sec + tf.header.stamp.nanosec * 1e-9,
                                (tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z),
                                (
                                    tf.transform.rotation.x,
                                    tf.transform.rotation.y,
                                    tf.transform.rotation.z,
                                    tf.transform.rotation.w,
                                ),
                            )
                            for tf in msg.transforms
                        ],
                    )
                )
    except BagError:
        raise
    except Exception as err:  # noqa: BLE001
        raise BagError(f"{path}: cannot be read as a rosbag2 ({err})") from None
    if not out:  # a loop over nothing would spin a core
        raise BagError(f"{path}: no {TF_TOPIC} messages to play")
    return out


class TrackerBridge(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("sparse_body_tracker_bridge", **kwargs)
        self._stop = threading.Event()
        self.adapter: VmcReceiver | SerialTrackerReader | None = None
        self._thread = None
        for name, (default, text) in PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(description=text))
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        if p["source"] not in SOURCES:
            raise ValueError(f"parameter 'source' must be one of {', '.join(SOURCES)}, got {p['source']!r}")
        self.params = p
        self.sensors = load_sensor_config(p["sensors"])
        self.site_of_frame = {s.frame_id: s.site for s in self.sensors.sites}
        self.calibration = None
        if p["calibration"] and Path(p["calibration"]).exists():
            self.calibration = Calibration.load(p["calibration"])
            self.get_logger().info(f"applying the calibration in {p['calibration']}")
        from tf2_msgs.msg import TFMessage

        from ..srv import Calibrate

        self._msg_type = TFMessage
        self.pub = self.create_publisher(TFMessage, "/tf", QoSProfile(depth=100))
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", QoSProfile(depth=10))
        # its own callback group: the service waits while samples arrive, the rest (diagnostics)
        # goes on in the executor's other thread
        self.create_service(
            Calibrate, "~/calibrate", self._on_calibrate, callback_group=MutuallyExclusiveCallbackGroup()
        )
        self.counts = {"published": 0, "stale": 0, "unmapped": 0}
        self.unmapped: set[str] = set()
        self._collect: dict[str, list] | None = None
        self._lock = threading.Lock()
        self._counts_lock = threading.Lock()
        self.finished = threading.Event()
        if p["source"] == "bag":
            if not p["bag"]:
                raise ValueError("parameter 'bag' is empty: name a rosbag2 of tracker TF")
            if p["rate"] <= 0:
                raise ValueError(f"parameter 'rate' must be positive, got {p['rate']}")
            self.frames = load_tf_frames(p["bag"])
            self.get_logger().info(f"playing {len(self.frames)} TF messages from {p['bag']}")
            self._thread = threading.Thread(target=self._play, daemon=True)
            self._thread.start()
        else:
            self._start_device_source(p)
        self.create_timer(1.0, self._publish_diagnostics)

    # -- live devices ----------------------------------------------------------------
    def _start_device_source(self, p) -> None:
        entries = [e for e in p["devices"] if e]
        if not entries:
            entries = (
                ["hmd:*=head"]
                if p["source"] == "vmc"
                else [f"serial:{i + 1}={s.site}" for i, s in enumerate(self.sensors.sites)]
            )
        self.device_map = parse_device_map(entries)
        unknown = {site for _, site in self.device_map} - set(self.sensors.site_names)
        if unknown:
            raise ValueError(
                f"devices map to {', '.join(sorted(unknown))}, which sensor configuration "
                f"{self.sensors.name!r} does not have"
            )
        if p["source"] == "vmc":
            from ..adapters.vmc import VmcReceiver

            receiver = self.adapter = VmcReceiver(self._on_samples, p["vmc_host"], p["vmc_port"])
            self.get_logger().info(f"listening for VMC on {receiver.address[0]}:{receiver.address[1]}")
        else:
            from ..adapters.serial_reader import SerialTrackerReader

            self.adapter = SerialTrackerReader(p["serial_port"], self._on_samples, p["serial_baudrate"])
            self.get_logger().info(f"reading serial trackers from {p['serial_port']}")

    def _count(self, key: str, n: int = 1) -> None:
        """Counters are changed from the adapters' and the player's threads."""
        with self._counts_lock:
            self.counts[key] += n

    def _on_samples(self, samples) -> None:
        now = time.time()
        transforms = []
        for sample in samples:
            site = map_device(sample.device, self.device_map)
            if site is None:
                self._count("unmapped")
                with self._counts_lock:
                    self.unmapped.add(sample.device)
                continue
            if sample.stamp < now - self.params["stale_after"]:
                self._count("stale")
                continue
            spec = self.sensors.site(site)
            position = sample.position if (sample.position is not None and spec.has_position) else None
            transforms.append(self._transform(site, spec.frame_id, sample.stamp, position, sample.orientation))
        self._send(transforms)

    # -- the bag --------------------------------------------------------------------
    def _wait_for_subscribers(self) -> bool:
        # /tf is volatile: what is published before a subscriber is matched is lost to it.
        while self.pub.get_subscription_count() < self.params["min_subscribers"]:
            if self._stop.wait(0.05):
                return False
        return not self._stop.wait(self.params["start_delay"])

    def _play(self) -> None:
        if not self._wait_for_subscribers():
            return
        while True:
            start = time.monotonic()
            for t_rel, transforms in self.frames:
                delay = start + t_rel / self.params["rate"] - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    return
                now = self.get_clock().now().nanoseconds * 1e-9
                self._send(
                    [
                        self._transform(
                            self.site_of_frame.get(child),
                            child,
                            now if self.params["restamp"] else stamp,
                            tr,
                            q,
                            parent,
                        )
                        for parent, child, stamp, tr, q in transforms
                    ]
                )
            if not self.params["loop"]:
                self.finished.set()
                self.get_logger().info("finished playing")
                return

    # -- common -----------------------------------------------------------------------
    def _transform(self, site, frame_id, stamp, position, quat, parent=None) -> TransformStamped:
        quat = np.asarray(quat, dtype=float)
        if site is not None:
            with self._lock:
                if self._collect is not None:
                    self._collect.setdefault(site, []).append(
                        (None if position is None else np.asarray(position, float), quat)
                    )
                if self.calibration is not None and np.all(np.isfinite(quat)) and np.linalg.norm(quat) > 0.5:
                    quat = self.calibration.apply(site, quat)
        m = TransformStamped()
        m.header.frame_id, m.child_frame_id = parent or self.sensors.fixed_frame, frame_id
        m.header.stamp = to_time(stamp)
        (m.transform.translation.x, m.transform.translation.y, m.transform.translation.z) = (
            (0.0, 0.0, 0.0) if position is None else map(float, position)
        )
        (m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z, m.transform.rotation.w) = map(
            float, quat
        )
        return m

    def _send(self, transforms) -> None:
        if not transforms or self._stop.is_set():
            return
        try:
            self.pub.publish(self._msg_type(transforms=transforms))
        except Exception:  # noqa: BLE001 - a source thread racing the shutdown: its context is gone
            if rclpy.ok() and not self._stop.is_set():
                raise
            return
        self._count("published", len(transforms))

    def _save_path(self, requested: str) -> Path | None:
        """Where a calibration may be written: the calibration parameter's file, or a
        request's save_path inside calibration_dir (any peer on the domain can call the
        service: it must not write anywhere else, nor create folders)."""
        if not requested:
            return Path(self.params["calibration"]) if self.params["calibration"] else None
        folder = self.params["calibration_dir"]
        if not folder:
            raise CalibrationError("save_path refused: the bridge has no calibration_dir to write requests under")
        # no expanduser: '~' is a peer's text, and expanding it raises for an unknown user
        try:
            path = (Path(folder) / requested).resolve()  # an absolute request stays absolute
        except (ValueError, OSError, RuntimeError) as err:  # a NUL byte, a symlink loop
            raise CalibrationError(f"save_path refused: {requested!r} ({err})") from None
        if not path.is_relative_to(Path(folder).resolve()) or path.suffix not in (".yaml", ".yml"):
            raise CalibrationError(f"save_path refused: {requested!r} is not a .yaml file under {folder}")
        if not path.parent.is_dir():
            raise CalibrationError(f"save_path refused: {path.parent} does not exist")
        return path

    def _on_calibrate(self, request, response):
        seconds = float(request.seconds) if request.seconds != 0 else 1.0
        try:
            if not 0 < seconds <= MAX_CALIBRATION_SECONDS:  # also NaN and inf
                raise CalibrationError(
                    f"seconds must be between 0 and {MAX_CALIBRATION_SECONDS:g}, got {request.seconds}"
                )
            path = self._save_path(request.save_path)
        except CalibrationError as err:
            response.success, response.message = False, str(err)
            self.get_logger().warn(f"calibration refused: {err}")
            return response
        with self._lock:
            self._collect = {}
        time.sleep(seconds)  # samples arrive on the source's thread meanwhile
        with self._lock:
            collected, self._collect = self._collect, None
        try:
            calibration = calibrate_tpose(
                collected, translations={s.site: np.array(s.offset_translation) for s in self.sensors.sites}
            )
        except CalibrationError as err:
            response.success, response.message = False, str(err)
            self.get_logger().warn(f"calibration failed: {err}")
            return response
        if path:
            try:
                calibration.save(path)
            except OSError as err:
                response.success, response.message = False, f"calibration not saved to {path}: {err.strerror or err}"
                self.get_logger().warn(response.message)
                return response
        with self._lock:
            self.calibration = calibration
        response.success, response.height, response.sites = True, float(calibration.height), sorted(calibration.offsets)
        response.message = f"calibrated {', '.join(sorted(calibration.offsets))}; height {calibration.height:.2f} m" + (
            f"; saved to {path}" if path else ""
        )
        self.get_logger().info(response.message)
        return response

    def _publish_diagnostics(self) -> None:
        status = DiagnosticStatus(name="sparse_body: tracker bridge", hardware_id=self.params["source"])
        with self._counts_lock:
            counts, unmapped = dict(self.counts), sorted(self.unmapped)
        values = {
            **{k: str(v) for k, v in counts.items()},
            "unmapped devices": ", ".join(unmapped) or "none",
            "calibrated": "yes" if self.calibration else "no",
        }
        level, message = DiagnosticStatus.OK, "ok"
        if self.adapter is not None:  # a live transport: its own figures and problem
            problem, figures = self.adapter.diagnostics()
            values.update(figures)
            if problem:
                level, message = DiagnosticStatus.ERROR, problem
        if counts["stale"] and level == DiagnosticStatus.OK:
            level, message = DiagnosticStatus.WARN, f"{counts['stale']} stale samples dropped"
        status.level, status.message = level, message
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)

    def destroy_node(self) -> None:
        self._stop.set()
        if self._thread is not None:
            # The player must be out of publish() before the node and the DDS participant go:
            # a thread left inside it at exit holds the writer's lock, and the participant's
            # teardown then waits for it forever (a launch test's bridge was killed after
            # 15 s on a starved machine; its join gave up after 2 s). A reliable publish
            # blocks for a bounded time; 10 s stays within launch's SIGINT-to-SIGKILL 15 s.
            self._thread.join(timeout=10.0)
            if self._thread.is_alive():
                self.get_logger().warning("the bag player did not stop within 10 s")
        if self.adapter is not None:
            self.adapter.close()
        super().destroy_node()


def main(args=None) -> None:
    init(args)
    try:
        node = TrackerBridge()
    except (ValueError, BagError, SensorConfigError, CalibrationError) as err:
        print(f"sparse_body_tracker_bridge: {err}", flush=True)
        rclpy.try_shutdown()
        raise SystemExit(1) from None
    spin_until_shutdown(node, threads=2)


if __name__ == "__main__":
    main()
