"""Tracker poses from TF: a /tf + /tf_static reader over a TfCache.

One path on every install. tf2_ros's buffer was the other path once; it was dropped because
the estimators want each tracker's newest sample, not an interpolated lookup, and the buffer
hides what the node must count and act on: refused non-finite samples (tf2 only logs them),
clock jumps back (the estimator must start over) and the arrival of a tracker sample (which
drives the estimate). The reader takes /tf as bytes and reads them with io/cdr.py's read_tf
(rclpy's message objects cost about 20 times more: 1.2 ms for the node's own 22-link message
on a loaded machine), skips the messages the node published itself (by their bytes) and drops any other
transform of the node's own links (robot_state_publisher's), hands the rest to the
TfCache's one ingest (the bag reader's too: its guards and counts are in io/tf_cache.py),
judged by the node's clock, and tells the node when a tracker moved. Bytes that are no
TFMessage are counted ("malformed message") and dropped.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..io.cdr import MalformedMessage, read_tf
from ..io.tf_cache import Accepted, TfCache, TfGuards

# /tf's history is kept short: a node that falls behind then skips to the newest messages
# instead of working through a backlog (100 messages were 1.3 s of lag at 60 Hz plus the
# node's own link TF); a few per tracker still holds trackers published one per message.
TF_QUEUE_PER_TRACKER, TF_QUEUE_MIN = 1, 4
# at most this many waiting /tf messages are taken in one go (more than the queue holds, so
# all of them; the bound only keeps a publisher faster than the ingest from starving the node)
MAX_DRAINED = 64
# the node's own /tf messages remembered, to know them when they come back (a few estimates'
# worth: one comes back within milliseconds, or never once the history has moved on)
OWN_KEPT = 8


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
    """Subscribes to /tf and /tf_static and hands each message to one TfCache (its guards
    judge stamps by the node's clock).

    on_tracker() is called after a message that brought a new sample of a tracker frame."""

    def __init__(
        self,
        node,
        tracker_frames: set[str],
        ignore_frames: set[str] | frozenset[str] = frozenset(),
        on_tracker=None,
        guards: TfGuards | None = None,
        also: set[str] | frozenset[str] = frozenset(),
    ) -> None:
        from tf2_msgs.msg import TFMessage

        self.cache = TfCache(tracker_frames, guards, also)
        self.ignore_frames = set(ignore_frames) - set(tracker_frames)
        self.on_tracker = on_tracker
        self._node = node
        self.drained = 0  # /tf messages taken at once because the node ran behind (on /diagnostics)
        # The node's own link TF comes back on /tf, 22 transforms at the output rate. Known by
        # its bytes (the reader takes /tf raw, and DDS hands the publisher's bytes over as they
        # were), it costs a hash instead of a parse; own_skipped counts them (on /diagnostics).
        self._own: deque[bytes] = deque(maxlen=OWN_KEPT)
        self._own_set: set[bytes] = set()
        self.own_skipped = 0
        # (frame prefix, callback(bytes, static)): messages with a frame under the prefix are
        # also handed there as they came (the live view shows the robot's links)
        self.forward: tuple[str, Callable[[bytes, bool], None]] | None = None
        self._subs = [  # /tf first: _on_tf takes what waits on it
            node.create_subscription(
                TFMessage, "/tf", lambda m: self._on_tf(m, False), tf_qos(len(tracker_frames)), raw=True
            ),
            node.create_subscription(TFMessage, "/tf_static", lambda m: self._on_tf(m, True), TF_STATIC_QOS, raw=True),
        ]

    @property
    def rejected(self) -> dict[str, int]:
        return {reason.value: count for reason, count in self.cache.refused.items()}

    def _on_tf(self, data: bytes, static: bool) -> None:
        now = self._node.get_clock().now().nanoseconds * 1e-9
        arrived = self._ingest(data, static, now)
        if not static:
            # A node that fell behind finds more /tf messages waiting: take them all now, so the
            # one estimate that follows uses the newest samples instead of working through a
            # backlog one estimate a message (the executor would hand them over one per wait).
            # take_message is what rclpy's executor itself calls on a subscription's handle.
            sub = self._subs[0]
            for _ in range(MAX_DRAINED):
                with sub.handle:
                    taken = sub.handle.take_message(sub.msg_type, sub.raw)
                if taken is None:
                    break
                arrived |= self._ingest(taken[0], False, now)
                self.drained += 1
        if arrived and self.on_tracker is not None:
            self.on_tracker()

    def published(self, data: bytes) -> None:
        """The node published this /tf message: skip it when it comes back."""
        if len(self._own) == OWN_KEPT:
            self._own_set.discard(self._own[0])
        self._own.append(data)
        self._own_set.add(data)

    def _ingest(self, data: bytes, static: bool, now: float) -> bool:
        if not static and data in self._own_set:
            self._own_set.discard(data)
            self.own_skipped += 1
            return False
        try:
            rows = read_tf(data)
        except MalformedMessage:
            self.cache.refused[Accepted.MALFORMED] += 1
            return False
        if self.forward is not None and any(row[1].startswith(self.forward[0]) for row in rows):
            self.forward[1](data, static)
        if self.ignore_frames:  # the node's own link TF comes back on /tf
            rows = [row for row in rows if row[1] not in self.ignore_frames]
        return self.cache.ingest_rows(rows, static, now).arrived

    def take_jump_back(self) -> bool:
        """Whether the input started again (a looping bag) since the last call."""
        jumped, self.cache.jumped_back = self.cache.jumped_back, False
        return jumped

    def lookup(self, fixed_frame: str, frame_id: str):
        """(stamp, translation, rotation) of a tracker or `also` frame in fixed_frame, or None."""
        return self.cache.lookup(fixed_frame, frame_id)

    def stamps(self, frame_ids) -> list[float]:
        """The newest stamp of each frame's own transform (-inf unknown, inf static)."""
        return [self.cache.stamp(f) for f in frame_ids]

    def sample(self, config, stamp: float, stale_after: float):
        return self.cache.sample(config, stamp, stale_after)

    def destroy(self) -> None:
        for sub in self._subs:
            self._node.destroy_subscription(sub)
        self._subs = []
