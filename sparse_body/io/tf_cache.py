"""The latest tracker transforms, for the nodes' /tf input and for bags: one store, one ingest.

Keeps the newest transform of each tracker frame and of the frames between it and the fixed
frame (and how often each comes), and looks a tracker up in the fixed frame by walking
parents. Unlike tf2 it does not interpolate: estimators want the newest sample, and a newer
one replaces it (a burst is coalesced, never queued). Both the live node (ros/tf_input.py)
and the bag reader (io/bagio.py) hand every /tf message to `ingest`, as tf2_ros's listener
hands each message to its buffer, so live and offline judge samples alike.

/tf is open to every process on the ROS domain, so what arrives is checked (TfGuards) and
what is refused is counted by reason (`refused`):
- non-finite or absurd values (any number beyond `MAX_VALUE`: squaring 2e154 overflowed and
  stopped the node) and degenerate quaternions;
- a stamp older than the one held: out of order within `jump_back`; further back, that
  frame alone starts again (one wrong frame cannot clear the others). The input as a whole
  starts again (a looping bag, a restarted simulation) when most trackers have jumped back;
  the consumer is told (`jumped_back`) so it can reset its estimator;
- dynamic stamps further than `clock_window` behind the clock (the node's, or a bag's receive
  time): a head stamped 0, a replay with its recorded stamps on a live clock; or further than
  `future_window` ahead of it: a sample from the future would make every estimate after it
  carry that stamp, valid and seconds ahead of every consumer's clock;
- a tracker further than `play_radius` from the fixed frame's origin, and a parent chain
  longer than `max_depth` (looked up each sample: a 2000-frame chain costs 16 steps);
- memory stays bounded whatever arrives: only tracker frames and their ancestors are kept
  for good; other frames (which may become ancestors later) are kept in a small
  least-recently-set store of `other_frames`.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from scipy.spatial.transform import Rotation

from .tf_guards import TfGuards

# Any value (metres, quaternion components, seconds) beyond this is refused before arithmetic
# on it: squares and sums of squares of values within it stay finite (2e154 squared overflowed
# Python's float power and stopped the node). Positions this far are refused later anyway,
# by the play space, and counted there.
MAX_VALUE = 1e150


class Accepted(Enum):
    OK = "ok"
    NON_FINITE = "non-finite or absurd value"
    BAD_QUATERNION = "degenerate quaternion"
    OUT_OF_ORDER = "out of order"
    JUMPED_BACK = "clock jumped back"  # accepted: the frame starts again
    FAR_FROM_CLOCK = "stamp far from the clock"
    AHEAD_OF_CLOCK = "stamp ahead of the clock"
    OUT_OF_PLAY_SPACE = "outside the play space"
    TOO_DEEP = "parent chain too deep"
    MALFORMED = "malformed message"  # a whole /tf message that cannot be read (live: any peer can send one)


def _row(tf):
    """A TransformStamped object as the row read_tf gives."""
    tr, q, stamp = tf.transform.translation, tf.transform.rotation, tf.header.stamp
    seconds = stamp.sec + stamp.nanosec * 1e-9
    return tf.header.frame_id, tf.child_frame_id, seconds, (tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w)


@dataclass(slots=True)
class Edge:
    parent: str
    stamp: float
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]  # x y z w, unit
    static: bool
    interval: float = 0.0  # running mean of the time between samples (s); 0 until the second


@dataclass
class Ingested:
    """What one /tf message did to the trackers."""

    moved: bool = False  # a tracker frame came in it on /tf (accepted or not): a bag's input frame
    arrived: bool = False  # a tracker sample in it was taken, /tf_static too: the trackers are alive
    newest: float = -math.inf  # the newest accepted tracker stamp in it
    refused: set[str] = field(default_factory=set)  # tracker frames whose sample in it was refused
    refused_stamp: float = -math.inf  # the newest finite stamp among those


class TfCache:
    def __init__(self, trackers: Iterable[str], guards: TfGuards | None = None, also: Iterable[str] = ()) -> None:
        """trackers: the frames whose samples are the input; also: other frames to look up
        (kept with their ancestors like trackers, but no input of their own)."""
        self.guards = guards or TfGuards()
        self.trackers = frozenset(trackers)
        self.refused: dict[Accepted, int] = {a: 0 for a in Accepted if a not in (Accepted.OK, Accepted.JUMPED_BACK)}
        self.jumped_back = False  # the input started again; the consumer clears it
        self._edges: dict[str, Edge] = {}  # tracker frames and their ancestors
        self._others: OrderedDict[str, Edge] = OrderedDict()  # the rest, bounded
        self._roots = self.trackers | frozenset(also)
        self._depth: dict[str, int] = dict.fromkeys(self._roots, 0)  # kept frames: steps below a tracker

    # -- in -----------------------------------------------------------------------------------
    def ingest(self, transforms, static: bool = False, now: float | None = None) -> Ingested:
        """Take one /tf (or /tf_static) message's transforms as message objects, rclpy's or
        rosbags' (the same fields). `now`: the clock to judge stamps by (None: not judged)."""
        return self.ingest_rows(map(_row, transforms), static, now)  # one row at a time: a flood costs no list

    def ingest_rows(self, rows, static: bool = False, now: float | None = None) -> Ingested:
        """Take one /tf (or /tf_static) message's transforms as io/cdr.py's read_tf gives them:
        (parent, child, stamp, (x, y, z, qx, qy, qz, qw)). The one ingest, live and offline."""
        out = Ingested()
        for parent, child, stamp, values in rows:
            result = self.set(parent, child, stamp, values[:3], values[3:], static, now)
            if child not in self.trackers:
                continue
            taken = result in (Accepted.OK, Accepted.JUMPED_BACK)
            out.arrived |= taken
            if not static:
                out.moved = True  # even a refused sample is an input frame: it gets an output
                if taken:
                    out.newest = max(out.newest, stamp)
                else:
                    out.refused.add(child)
                    if math.isfinite(stamp):
                        out.refused_stamp = max(out.refused_stamp, stamp)
        return out

    def set(
        self,
        parent: str,
        child: str,
        stamp: float,
        translation,
        rotation,
        static: bool = False,
        now: float | None = None,
    ) -> Accepted:
        # plain floats, not numpy: a transform costs a few microseconds, also in a flood
        x, y, z = map(float, translation)
        qx, qy, qz, qw = map(float, rotation)
        stamp = float(stamp)
        held = self._edges.get(child) or self._others.get(child)
        result = self._check(held, stamp, (x, y, z, qx, qy, qz, qw), static, now)
        if result not in (Accepted.OK, Accepted.JUMPED_BACK):
            self.refused[result] += 1
            return result
        interval = 0.0
        if held is not None and result is Accepted.OK and not static:
            gap = stamp - held.stamp
            interval = gap if held.interval == 0.0 else 0.9 * held.interval + 0.1 * gap
        n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        edge = Edge(parent, stamp, (x, y, z), (qx / n, qy / n, qz / n, qw / n), static, interval)
        if child in self._depth:
            self._edges[child] = edge
            self._want(parent, self._depth[child] + 1)
        else:
            self._others[child] = edge
            self._others.move_to_end(child)
            while len(self._others) > self.guards.other_frames:
                self._others.popitem(last=False)
        if result is Accepted.JUMPED_BACK and child in self.trackers:
            self._restart_if_most_jumped(stamp)
        return result

    def _check(self, held: Edge | None, stamp: float, values: tuple, static: bool, now: float | None) -> Accepted:
        """values: x y z qx qy qz qw."""
        # bounded first (NaN fails every comparison): no product below can overflow; written
        # out, as every sample of every tracker passes here
        x, y, z, qx, qy, qz, qw = values
        m = MAX_VALUE
        if not (
            -m <= stamp <= m
            and -m <= x <= m
            and -m <= y <= m
            and -m <= z <= m
            and -m <= qx <= m
            and -m <= qy <= m
            and -m <= qz <= m
            and -m <= qw <= m
        ):
            return Accepted.NON_FINITE
        if not 0.81 < qx * qx + qy * qy + qz * qz + qw * qw < 1.21:
            return Accepted.BAD_QUATERNION
        window = self.guards.clock_window
        if not static and now is not None and window > 0:
            if now - stamp > window:
                return Accepted.FAR_FROM_CLOCK
            if stamp - now > min(window, self.guards.future_window):
                return Accepted.AHEAD_OF_CLOCK
        if held is not None and not static and stamp < held.stamp:
            return Accepted.OUT_OF_ORDER if held.stamp - stamp <= self.guards.jump_back else Accepted.JUMPED_BACK
        return Accepted.OK

    def _want(self, frame: str, depth: int) -> None:
        """Keep `frame` (an ancestor of a tracker) for good, and its own known ancestors."""
        while depth <= self.guards.max_depth and self._depth.get(frame, depth + 1) > depth:
            self._depth[frame] = depth
            edge = self._others.pop(frame, None)
            if edge is not None:
                self._edges[frame] = edge
            edge = self._edges.get(frame)
            if edge is None:
                break
            frame, depth = edge.parent, depth + 1
        if len(self._depth) > len(self._roots) * (self.guards.max_depth + 1):
            self._forget_former_ancestors()

    def _forget_former_ancestors(self) -> None:
        """Trackers re-parented again and again: keep only today's ancestors."""
        kept = dict.fromkeys(self._roots, 0)
        for tracker in self._roots:
            frame, depth = tracker, 0
            while (edge := self._edges.get(frame)) is not None and depth < self.guards.max_depth:
                frame, depth = edge.parent, depth + 1
                kept[frame] = min(kept.get(frame, depth), depth)
        self._depth = kept
        self._edges = {c: e for c, e in self._edges.items() if c in kept}

    def _restart_if_most_jumped(self, stamp: float) -> None:
        """A tracker jumped back to `stamp`: when the trackers still ahead of it are fewer than
        those that are not, the input started again (they are dropped, the consumer told);
        otherwise only that tracker did (a wrong or oscillating frame), and it alone restarted."""
        held = {t: self._edges[t] for t in self.trackers if t in self._edges and not self._edges[t].static}
        ahead = [t for t, e in held.items() if e.stamp > stamp + self.guards.jump_back]
        if len(ahead) < len(held) - len(ahead):
            for t in ahead:
                del self._edges[t]
            self.jumped_back = True

    # -- out ----------------------------------------------------------------------------------
    def stamp(self, child: str) -> float:
        """The newest stamp of a child frame's own transform (-inf unknown, inf static)."""
        edge = self._edges.get(child)
        return -np.inf if edge is None else (np.inf if edge.static else edge.stamp)

    def budget(self, child: str, stale_after: float) -> float:
        """How far (s) a child frame's newest sample may lag the newest tracker sample and
        still count: stale_after, or three of the frame's own sample intervals if longer."""
        edge = self._edges.get(child)
        return max(stale_after, 3.0 * (0.0 if edge is None else edge.interval))

    def newest_tracker_stamp(self) -> float:
        dynamic = [e.stamp for t, e in self._edges.items() if t in self.trackers and not e.static]
        return max(dynamic) if dynamic else -np.inf

    def lookup(self, target: str, source: str):
        """(stamp, translation, rotation xyzw) of source in target, or None when unknown or
        further than max_depth transforms. The stamp is the oldest of the dynamic transforms on
        the way (inf if all static)."""
        edge = self._edges.get(source)
        if edge is not None and edge.parent == target:  # the usual tracker: one edge, nothing to compose
            return (np.inf if edge.static else edge.stamp), np.array(edge.translation), np.array(edge.rotation)
        rot, trans, stamp = Rotation.identity(), np.zeros(3), np.inf
        frame = source
        for _ in range(self.guards.max_depth):
            edge = self._edges.get(frame)
            if edge is None:
                return None
            # parent_T_child applied after what is accumulated so far: x_parent = R x_child + t
            edge_rot = Rotation.from_quat(edge.rotation)
            trans = edge_rot.apply(trans) + edge.translation
            rot = edge_rot * rot
            if not edge.static:
                stamp = min(stamp, edge.stamp)
            frame = edge.parent
            if frame == target:
                return stamp, trans, rot.as_quat()
        if frame in self._edges:  # a chain goes on (or loops) past max_depth
            self.refused[Accepted.TOO_DEEP] += 1
        return None

    def sample(self, config, stamp: float, stale_after: float):
        """The trackers of a sensor configuration at `stamp` (the newest tracker sample's stamp:
        staleness is judged in the input's own time, so a late delivery is latency, not loss).

        Returns (TrackerFrame, stamps): a site is invalid when its frame is unknown, its pose is
        not finite or outside the play space, or its newest transform is older than `stamp` by
        more than its budget (stale_after, or three of the tracker's own sample intervals if
        longer). stamps[s] is that transform's stamp (-inf when unknown, `stamp` when the chain
        is all static). Orientation-only sites get NaN positions, position-only sites NaN
        orientations."""
        from ..core.types import TrackerFrame

        S = len(config.sites)
        # rows gathered as tuples and made arrays once: a frame is sampled for every /tf message
        nowhere, unturned = (math.nan,) * 3, (math.nan,) * 4
        positions: list[tuple[float, ...]] = [nowhere] * S
        orientations: list[tuple[float, ...]] = [unturned] * S
        valid, stamps = [False] * S, [-math.inf] * S
        for s, site in enumerate(config.sites):
            edge = self._edges.get(site.frame_id)
            if edge is not None and edge.parent == config.fixed_frame:  # the usual tracker, as lookup's
                t_stamp, t, q = (math.inf if edge.static else edge.stamp), edge.translation, edge.rotation
            else:
                found = self.lookup(config.fixed_frame, site.frame_id)
                if found is None:
                    continue
                t_stamp, t, q = found
            stamps[s] = t_stamp if t_stamp != math.inf else stamp
            if not math.sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]) <= self.guards.play_radius:
                self.refused[Accepted.OUT_OF_PLAY_SPACE] += 1
                continue
            if stamp - stamps[s] > self.budget(site.frame_id, stale_after):
                continue
            valid[s] = True
            if site.has_position:
                positions[s] = tuple(t)
            if site.has_orientation:
                orientations[s] = tuple(q)
        frame = TrackerFrame(
            stamp,
            config.site_names,
            np.array(positions, np.float64).reshape(S, 3),
            np.array(orientations, np.float64).reshape(S, 4),
            np.array(valid, bool),
        )
        return frame, np.array(stamps, np.float64)
