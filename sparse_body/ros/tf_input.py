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

    def sample(self, config, now: float, stale_after: float):
        return sample_trackers(self.cache, config, now, stale_after)

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

    def sample(self, config, now: float, stale_after: float):
        from rclpy.time import Time
        from ..core.types import TrackerFrame
        S = len(config.sites)
        positions, orientations = np.full((S, 3), np.nan), np.full((S, 4), np.nan)
        valid, stamps = np.zeros(S, dtype=bool), np.full(S, -np.inf)
        for s, site in enumerate(config.sites):
            try:
                tf = self.buffer.lookup_transform(config.fixed_frame, site.frame_id, Time())
            except Exception:  # noqa: BLE001 - tf2 raises several lookup errors; all mean "no pose"
                continue
            tr, q = tf.transform.translation, tf.transform.rotation
            pos, quat = np.array([tr.x, tr.y, tr.z]), np.array([q.x, q.y, q.z, q.w])
            stamps[s] = to_seconds(tf.header.stamp)
            if now - stamps[s] > stale_after or not (np.all(np.isfinite(pos)) and np.all(np.isfinite(quat))):
                continue
            valid[s] = True
            if site.has_position:
                positions[s] = pos
            if site.has_orientation:
                orientations[s] = quat / np.linalg.norm(quat)
        return TrackerFrame(now, config.site_names, positions, orientations, valid), stamps

    def destroy(self) -> None:
        self.listener.unregister()
