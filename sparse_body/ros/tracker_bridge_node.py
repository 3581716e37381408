"""Tracker poses from a source, republished as TF.

The source here is a rosbag2 of tracker TF (as `sparse-body make-bag` writes or a recording
of real trackers): its /tf messages are played at the recorded pace, restamped to the
current time by default, as live trackers would stamp them. Device adapters (VMC, serial)
plug in as further sources.
"""
from __future__ import annotations

import threading
import time

import rclpy
from geometry_msgs.msg import TransformStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import QoSProfile

from ..bagio import TF_TOPIC, BagError, typestore
from .messages import to_time
from .spin import spin_until_shutdown

PARAMETERS = {
    "bag": ("", "rosbag2 directory (or .mcap / .db3 file) holding tracker /tf"),
    "rate": (1.0, "playback speed factor"),
    "loop": (False, "start again at the end"),
    "restamp": (True, "stamp transforms with the current time instead of the recorded one"),
    "min_subscribers": (1, "wait until this many /tf subscribers are matched before playing"),
    "start_delay": (0.5, "seconds to wait after that, so late subscribers can connect too"),
}


def load_tf_frames(path: str) -> list[tuple[float, list]]:
    """(seconds from the first message, [(parent, child, translation, rotation)]) per /tf message."""
    from pathlib import Path

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
                out.append(((t_ns - first) * 1e-9, [
                    (tf.header.frame_id, tf.child_frame_id,
                     tf.header.stamp.sec + tf.header.stamp.nanosec * 1e-9,
                     (tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z),
                     (tf.transform.rotation.x, tf.transform.rotation.y, tf.transform.rotation.z, tf.transform.rotation.w))
                    for tf in msg.transforms]))
    except BagError:
        raise
    except Exception as err:  # noqa: BLE001
        raise BagError(f"{path}: cannot be read as a rosbag2 ({err})") from None
    return out


class TrackerBridge(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("sparse_body_tracker_bridge", **kwargs)
        for name, (default, text) in PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(description=text))
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        if not p["bag"]:
            raise ValueError("parameter 'bag' is empty: name a rosbag2 of tracker TF")
        if p["rate"] <= 0:
            raise ValueError(f"parameter 'rate' must be positive, got {p['rate']}")
        self.params = p
        self.frames = load_tf_frames(p["bag"])
        from tf2_msgs.msg import TFMessage
        self._msg_type = TFMessage
        self.pub = self.create_publisher(TFMessage, "/tf", QoSProfile(depth=100))
        self.get_logger().info(f"playing {len(self.frames)} TF messages from {p['bag']}")
        self._stop = threading.Event()
        self.finished = threading.Event()
        self._thread = threading.Thread(target=self._play, daemon=True)
        self._thread.start()

    def _play(self) -> None:
        # /tf is volatile: what is published before a subscriber is matched is lost to it.
        while self.pub.get_subscription_count() < self.params["min_subscribers"]:
            if self._stop.wait(0.05):
                return
        if self._stop.wait(self.params["start_delay"]):
            return
        while True:
            start = time.monotonic()
            for t_rel, transforms in self.frames:
                delay = start + t_rel / self.params["rate"] - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    return
                now = self.get_clock().now().nanoseconds * 1e-9
                msgs = []
                for parent, child, stamp, tr, q in transforms:
                    m = TransformStamped()
                    m.header.frame_id, m.child_frame_id = parent, child
                    m.header.stamp = to_time(now if self.params["restamp"] else stamp)
                    (m.transform.translation.x, m.transform.translation.y, m.transform.translation.z) = tr
                    (m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z,
                     m.transform.rotation.w) = q
                    msgs.append(m)
                self.pub.publish(self._msg_type(transforms=msgs))
            if not self.params["loop"]:
                self.finished.set()
                self.get_logger().info("finished playing")
                return

    def destroy_node(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        super().destroy_node()


def main(args=None) -> None:
    rclpy.init(args=args)
    try:
        node = TrackerBridge()
    except (ValueError, BagError) as err:
        print(f"sparse_body_tracker_bridge: {err}", flush=True)
        rclpy.shutdown()
        raise SystemExit(1)
    spin_until_shutdown(node)


if __name__ == "__main__":
    main()
