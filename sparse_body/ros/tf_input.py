"""Tracker poses from TF: a /tf + /tf_static reader over a TfCache.

One path on every install. tf2_ros's buffer was the other path once; it was dropped because
the estimators want each tracker's newest sample, not an interpolated lookup, and the buffer
hides what the node must count and act on: refused non-finite samples (tf2 only logs them),
clock jumps back (the estimator must start over) and the arrival of a tracker sample (which
drives the estimate). The reader refuses non-finite, out-of-order and jumped-back samples,
ignores the frames the node publishes itself, and tells the node when a tracker moved.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..io.tf_cache import Accepted, TfCache, sample_trackers
from .messages import to_seconds

# /tf's history is kept short: a node that falls behind then skips to the newest messages
# instead of working through a backlog (100 messages were 1.3 s of lag at 60 Hz plus the
# node's own link TF); a few per tracker still holds trackers published one per message.
TF_QUEUE_PER_TRACKER, TF_QUEUE_MIN = 1, 4


def tf_qos(tracker_count: int) -> QoSProfile:
    return QoSProfile(
        depth=TF_QUEUE_MIN + TF_QUEUE_PER_TRACKER * tracker_count,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
        history=HistoryPolicy.KEEP_LAST,
    )


TF_STATIC_QOS = QoSProfile(
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    history=HistoryPolicy.KEEP_LAST,
)


class TfReader:
    """Subscribes to /tf and /tf_static and keeps the newest transforms in a TfCache.

    on_tracker() is called after a message that brought a new sample of a tracker frame."""

    def __init__(
        self,
        node,
        tracker_frames: set[str],
        ignore_frames: set[str] | frozenset[str] = frozenset(),
        on_tracker=None,
        jump_back: float = 1.0,
    ) -> None:
        from tf2_msgs.msg import TFMessage

        self.cache = TfCache(jump_back)
        self.tracker_frames = set(tracker_frames)
        self.ignore_frames = set(ignore_frames) - self.tracker_frames
        self.on_tracker = on_tracker
        self.rejected = {a: 0 for a in Accepted if a is not Accepted.OK}
        self.jumped_back = False
        self._node = node
        self._subs = [
            node.create_subscription(
                TFMessage, "/tf", lambda m: self._on_tf(m, False), tf_qos(len(self.tracker_frames))
            ),
            node.create_subscription(TFMessage, "/tf_static", lambda m: self._on_tf(m, True), TF_STATIC_QOS),
        ]

    def _on_tf(self, msg, static: bool) -> None:
        moved = False
        for tf in msg.transforms:
            child = tf.child_frame_id
            if child in self.ignore_frames:
                continue
            tr, q = tf.transform.translation, tf.transform.rotation
            result = self.cache.set(
                tf.header.frame_id, child, to_seconds(tf.header.stamp), (tr.x, tr.y, tr.z), (q.x, q.y, q.z, q.w), static
            )
            if result is Accepted.JUMPED_BACK:
                self.jumped_back = True
            if child in self.tracker_frames:
                if result in (Accepted.OK, Accepted.JUMPED_BACK):
                    moved = True
                else:
                    self.rejected[result] += 1
        if moved and self.on_tracker is not None:
            self.on_tracker()

    def lookup(self, fixed_frame: str, frame_id: str):
        """(stamp, translation, rotation) of frame_id in fixed_frame, or None."""
        return self.cache.lookup(fixed_frame, frame_id)

    def stamps(self, frame_ids) -> list[float]:
        """The newest stamp of each frame's own transform (-inf unknown, inf static)."""
        return [self.cache.stamp(f) for f in frame_ids]

    def sample(self, config, stamp: float, stale_after: float):
        return sample_trackers(
            self.cache.lookup, config, stamp, stale_after, lambda frame_id: self.cache.budget(frame_id, stale_after)
        )

    def destroy(self) -> None:
        for sub in self._subs:
            self._node.destroy_subscription(sub)
        self._subs = []
