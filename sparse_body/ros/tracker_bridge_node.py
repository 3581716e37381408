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
publishes joint-aligned orientations. A mounting calibration after it (service
~/calibrate_mounting: for `seconds`, 15 by default, the person turns the head, circles the
wrists and each ankle and rolls the hips) finds where each tracker sits on its segment; the
bridge then publishes positions as if each tracker were mounted where the sensor
configuration says, and the body is fitted again with the found mountings.

A lifecycle node, as the estimator is: configure reads the parameters, opens the source
(ros/tracker_sources.py: the bag is read, a port is bound) and makes the publishers and the
service; activate starts the samples flowing, deactivate stops them, cleanup releases it
all. With autostart (the default) it configures and activates itself, so a launch file or
`ros2 run` needs no lifecycle manager; a configure that fails then ends the process with
the reason in one line and exit code 1.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.lifecycle import LifecycleNode, LifecyclePublisher, LifecycleState, TransitionCallbackReturn
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from rclpy.service import Service
from rclpy.timer import Timer

from ..core.calibration import Calibration, CalibrationError, calibrate_mounting, calibrate_tpose, untimed
from ..core.file_output import OutputError
from ..core.sensors import SensorConfig, SensorConfigError, load_sensor_config
from ..io.bagio import BagError
from .messages import to_time
from .node_options import TrackerBridgeOptions
from .parameters import declare, problems, table
from .spin import init, start_and_spin
from .tracker_sources import Sample, SourceContext, TrackerSource, make_source

PARAMETERS, RANGES = table(TrackerBridgeOptions)
MAX_CALIBRATION_SECONDS = 30.0
MOUNTING_SECONDS = 15.0  # ~/calibrate_mounting's default: three seconds for each of five movements


class TrackerBridge(LifecycleNode):
    """Tracker samples from a TrackerSource, published on /tf; handles made in configure,
    destroyed in cleanup (ros2/demos' lifecycle talker)."""

    source: TrackerSource | None = None
    pub: LifecyclePublisher | None = None
    pub_diag: Publisher | None = None
    service: Service | None = None
    mounting_service: Service | None = None
    diag_timer: Timer | None = None

    def __init__(self, **kwargs) -> None:
        super().__init__("sparse_body_tracker_bridge", **kwargs)
        self._refused_at_start = declare(self, PARAMETERS, RANGES)
        self.params: dict = {}
        self.calibration: Calibration | None = None
        self._collect: dict[str, list] | None = None  # site -> [(stamp, position, orientation)]
        self._tpose: dict[str, list] | None = None  # the last T-pose's samples, for ~/calibrate_mounting
        self._lock = threading.Lock()  # the calibration and the collection, shared with the source's thread
        self._counts_lock = threading.Lock()
        self.published = 0
        self._active = threading.Event()  # samples go out only while active
        self._stopping = False  # destroy_node has begun

    # -- lifecycle -------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        try:
            wrong = list(self._refused_at_start.values()) + problems(PARAMETERS, p, RANGES)
            if wrong:
                raise ValueError("; ".join(wrong))
            sensors = load_sensor_config(p["sensors"])
            self.calibration, self._tpose = None, None
            if p["calibration"] and Path(p["calibration"]).exists():
                self.calibration = Calibration.load(p["calibration"])
                self.get_logger().info(f"applying the calibration in {p['calibration']}")
            self.params, self.sensors = p, sensors
            self._nominal = {s.site: np.array(s.offset_translation) for s in sensors.sites}
            self.source = self._make_source(p, sensors)
        except (ValueError, BagError, SensorConfigError, CalibrationError, OSError) as err:
            self.get_logger().error(f"configure failed: {err}")
            return TransitionCallbackReturn.FAILURE
        from tf2_msgs.msg import TFMessage  # here, not at import: the stand-in exists only after setup

        from ..srv import Calibrate

        self._msg_type = TFMessage
        self.pub = self.create_lifecycle_publisher(TFMessage, "/tf", QoSProfile(depth=100))
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", QoSProfile(depth=10))
        # its own callback group: the service waits while samples arrive, the rest (diagnostics)
        # goes on in the executor's other thread
        group = MutuallyExclusiveCallbackGroup()  # one calibration at a time
        self.service = self.create_service(Calibrate, "~/calibrate", self._on_calibrate, callback_group=group)
        self.mounting_service = self.create_service(
            Calibrate, "~/calibrate_mounting", self._on_calibrate_mounting, callback_group=group
        )
        self.diag_timer = self.create_timer(1.0, self._publish_diagnostics)
        return TransitionCallbackReturn.SUCCESS

    def _make_source(self, p: dict, sensors: SensorConfig) -> TrackerSource:
        now = lambda: self.get_clock().now().nanoseconds * 1e-9  # noqa: E731
        context = SourceContext(p, sensors, self._send, now, self._wait_for_subscribers, self.get_logger().info)
        return make_source(p["source"], context)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)  # the /tf publisher first: the source sends at once
        assert self.source is not None  # activate follows a successful configure
        self._active.set()
        self.source.start()
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_source()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def _stop_source(self) -> None:
        self._active.clear()
        if self.source is not None:
            self.source.stop()

    def _release(self) -> None:
        self._stop_source()
        if self.source is not None:
            self.source.close()
        if self.diag_timer is not None:
            self.destroy_timer(self.diag_timer)
        if self.service is not None:
            self.destroy_service(self.service)
        if self.mounting_service is not None:
            self.destroy_service(self.mounting_service)
        if self.pub is not None:
            self.destroy_lifecycle_publisher(self.pub)
        if self.pub_diag is not None:
            self.destroy_publisher(self.pub_diag)
        self.source = self.pub = self.pub_diag = self.service = self.mounting_service = self.diag_timer = None

    def destroy_node(self) -> None:
        self._stopping = True  # what runs meanwhile in the executor's other thread ends quietly
        self._release()  # the source's thread must be out of publish() before the participant goes
        super().destroy_node()

    # -- publishing ------------------------------------------------------------------------
    def _wait_for_subscribers(self, stop: threading.Event) -> bool:
        # /tf is volatile: what is published before a subscriber is matched is lost to it. A
        # count alone can be met by a listener that is not the consumer (a test's, a viewer's)
        # while the estimator is still starting on a busy machine: named nodes are waited for.
        pub, names = self.pub, {n for n in self.params["wait_for_nodes"] if n}
        try:
            while pub is not None and not (
                pub.get_subscription_count() >= self.params["min_subscribers"]
                and names <= {info.node_name for info in self.get_subscriptions_info_by_topic("/tf")}
            ):
                if stop.wait(0.05):
                    return False
        except Exception:  # noqa: BLE001 - the publisher destroyed under the waiting thread: a stop
            if not self._stopping and rclpy.ok():
                raise
            return False
        return not stop.wait(self.params["start_delay"])

    def _send(self, samples: list[Sample]) -> None:
        pub = self.pub
        if not samples or pub is None or not self._active.is_set():
            return
        transforms = [self._transform(*sample) for sample in samples]
        try:
            pub.publish(self._msg_type(transforms=transforms))
        except Exception:  # noqa: BLE001 - a source thread racing the shutdown: its context is gone
            if rclpy.ok() and self._active.is_set():
                raise
            return
        with self._counts_lock:
            self.published += len(transforms)

    def _transform(self, site, parent, frame_id, stamp, position, quat) -> TransformStamped:
        quat = np.asarray(quat, dtype=float)
        if site is not None:
            with self._lock:
                if self._collect is not None:
                    self._collect.setdefault(site, []).append(
                        (stamp, None if position is None else np.asarray(position, float), quat)
                    )
                if self.calibration is not None and np.all(np.isfinite(quat)) and np.linalg.norm(quat) > 0.5:
                    quat = self.calibration.apply(site, quat)
                    if position is not None and site in self._nominal:
                        position = self.calibration.place(site, position, quat, self._nominal[site])
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
        """The T-pose: rotation offsets, height and body."""
        prepared = self._prepare(request, response, 1.0)
        if prepared is None:
            return response
        tpose = self._gather(prepared[0])
        try:
            calibration = calibrate_tpose(untimed(tpose), translations=self._nominal)
        except CalibrationError as err:
            return self._refuse(response, str(err), "calibration failed: ")
        self._tpose = tpose
        return self._adopt(calibration, prepared[1], response, f"calibrated {', '.join(sorted(calibration.offsets))}")

    def _on_calibrate_mounting(self, request, response):
        """Movement after the T-pose: each tracker's mounting translation (core.mounting)."""
        prepared = self._prepare(request, response, MOUNTING_SECONDS)
        if prepared is None:
            return response
        if self._tpose is None:
            return self._refuse(response, "take a T-pose first (~/calibrate)", "calibration refused: ")
        movement = self._gather(prepared[0])
        try:
            calibration, fits = calibrate_mounting(self._tpose, movement, self._nominal)
        except CalibrationError as err:
            return self._refuse(response, str(err), "calibration failed: ")
        found = ", ".join(f"{s} {np.linalg.norm(f.shift) * 1000:.0f} mm" for s, f in sorted(fits.items()) if f.windows)
        kept = sorted(s for s, f in fits.items() if not f.windows)
        what = f"mountings found ({found} from the configuration's)" + (
            f"; {', '.join(kept)} kept the configuration's (not turned)" if kept else ""
        )
        return self._adopt(calibration, prepared[1], response, what)

    def _prepare(self, request, response, default_seconds: float) -> tuple[float, Path | None] | None:
        """The request's seconds and save path, or None with the response refused."""
        seconds = float(request.seconds) if request.seconds != 0 else default_seconds
        try:
            if not 0 < seconds <= MAX_CALIBRATION_SECONDS:  # also NaN and inf
                raise CalibrationError(
                    f"seconds must be between 0 and {MAX_CALIBRATION_SECONDS:g}, got {request.seconds}"
                )
            return seconds, self._save_path(request.save_path)
        except CalibrationError as err:
            self._refuse(response, str(err), "calibration refused: ")
            return None

    def _gather(self, seconds: float) -> dict[str, list]:
        with self._lock:
            self._collect = {}
        time.sleep(seconds)  # samples arrive on the source's thread meanwhile
        with self._lock:
            collected, self._collect = self._collect, None
        return collected

    def _refuse(self, response, message: str, log_prefix: str = ""):
        response.success, response.message = False, message
        self.get_logger().warn(log_prefix + message)
        return response

    def _adopt(self, calibration: Calibration, path: Path | None, response, what: str):
        """Save (when asked) and apply a new calibration; the response says what it found."""
        if path:
            try:
                calibration.save(path)
            except (OSError, OutputError) as err:  # a FIFO, a link or a user's file there is refused
                return self._refuse(
                    response, f"calibration not saved to {path}: {getattr(err, 'strerror', None) or err}"
                )
        with self._lock:
            self.calibration = calibration
        response.success, response.height, response.sites = True, float(calibration.height), sorted(calibration.offsets)
        response.message = f"{what}; height {calibration.height:.2f} m" + (f"; saved to {path}" if path else "")
        self.get_logger().info(response.message)
        return response

    def _publish_diagnostics(self) -> None:
        """The timer's callback, in the executor's other thread: a stop (Ctrl-C) may destroy its
        publisher meanwhile, and what it raised then was printed as "The following exception
        was never retrieved: cannot use Destroyable because destruction was requested"."""
        try:
            self._send_diagnostics()
        except Exception:  # noqa: BLE001 - re-raised unless the node is being destroyed
            if not self._stopping and rclpy.ok():
                raise

    def _send_diagnostics(self) -> None:
        source, pub = self.source, self.pub_diag
        if source is None or pub is None:  # released meanwhile
            return
        status = DiagnosticStatus(name="sparse_body: tracker bridge", hardware_id=self.params["source"])
        problem, figures = source.diagnostics()
        with self._counts_lock:
            values = {"published": str(self.published), **figures}
        values["calibrated"] = "yes" if self.calibration else "no"
        level, message = DiagnosticStatus.OK, "ok" if self._active.is_set() else "inactive"
        if problem:  # a live transport's own problem
            level, message = DiagnosticStatus.ERROR, problem
        elif values.get("stale", "0") != "0":
            level, message = DiagnosticStatus.WARN, f"{values['stale']} stale samples dropped"
        status.level, status.message = level, message
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        pub.publish(msg)


def main(args=None) -> None:
    init(args)
    start_and_spin(TrackerBridge, threads=2)


if __name__ == "__main__":
    main()
