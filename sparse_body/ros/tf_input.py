"""Tracker poses from TF: tf2_ros where it is installed, else a /tf + /tf_static reader.

Both sample the newest transform of each tracker frame in the fixed frame; the reader path
uses TfCache, which also refuses non-finite, out-of-order and jumped-back samples."""
from __future__ import annotations

import numpy as np
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..tf_cache import Accepted, TfCache, sample_trackers
from .messages import to_seconds

from importlib.util import find_spec

HAVE_TF2_ROS = find_spec("tf2_ros") is not None   # apt / colcon installs only

TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE,
                    history=HistoryPolicy.KEEP_LAST)
TF_STATIC_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL, history=HistoryPolicy.KEEP_LAST)


class TfReader:
    """Subscribes to /tf and /tf_static and keeps the newest transforms in a TfCache."""

    def __init__(self, node, tracker_frames: set[str], jump_back: float = 1.0) -> None:
        from tf2_msgs.msg import TFMessage
        self.cache = TfCache(jump_back)
        self.tracker_frames = tracker_frames
        self.rejected = {a: 0 for a in Accepted if a is not Accepted.OK}
        self.jumped_back = False
        self._node = node
        self._subs = [node.create_subscription(TFMessage, "/tf", lambda m: self._on_tf(m, False), TF_QOS),
                      node.create_subscription(TFMessage, "/tf_static", lambda m: self._on_tf(m, True), TF_STATIC_QOS)]

    def _on_tf(self, msg, static: bool) -> None:
        for tf in msg.transforms:
            tr, q = tf.transform.translation, tf.transform.rotation
            result = self.cache.set(tf.header.frame_id, tf.child_frame_id, to_seconds(tf.header.stamp),
                                    (tr.x, tr.y, tr.z), (q.x, q.y, q.z, q.w), static)
            if result is Accepted.JUMPED_BACK:
                self.jumped_back = True
            if result is not Accepted.OK and tf.child_frame_id in self.tracker_frames:
                self.rejected[result] += 1

    def lookup(self, fixed_frame: str, frame_id: str):
        """(stamp, translation, rotation) of frame_id in fixed_frame, or None."""
        return self.cache.lookup(fixed_frame, frame_id)

    def sample(self, config, now: float, stale_after: float):
        return sample_trackers(self.cache.lookup, config, now, stale_after)

    def destroy(self) -> None:
        for sub in self._subs:
            self._node.destroy_subscription(sub)
        self._subs = []


class Tf2Reader:
    """tf2_ros Buffer + TransformListener (the usual path on a ROS install)."""

    def __init__(self, node, tracker_frames: set[str]) -> None:
        import tf2_ros
        self.buffer = tf2_ros.Buffer(node=node)
        self.listener = tf2_ros.TransformListener(self.buffer, node, spin_thread=False)
        self.rejected = {a: 0 for a in Accepted if a is not Accepted.OK}
        self.jumped_back = False

    def lookup(self, fixed_frame: str, frame_id: str):
        from rclpy.time import Time
        try:
            tf = self.buffer.lookup_transform(fixed_frame, frame_id, Time())
        except Exception:  # noqa: BLE001 - tf2 raises several lookup errors; all mean "no pose"
            return None
        tr, q = tf.transform.translation, tf.transform.rotation
        return to_seconds(tf.header.stamp), np.array([tr.x, tr.y, tr.z]), np.array([q.x, q.y, q.z, q.w])

    def sample(self, config, now: float, stale_after: float):
        return sample_trackers(self.lookup, config, now, stale_after)

    def destroy(self) -> None:
        self.listener.unregister()
