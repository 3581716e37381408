"""The latest tracker transforms, for the nodes' /tf input and for bags.

Keeps the newest transform of every child frame (and how often it comes), and looks a frame
up in a fixed frame by walking parents. Unlike tf2 it does not interpolate: estimators want
the newest sample, and a newer one replaces it (a burst is coalesced, never queued).
Samples are checked on the way in: non-finite values and degenerate quaternions are refused;
an older stamp than the one held is refused as out of order, unless it is older by more than
`jump_back` seconds, which is taken for a clock jump back (a looping bag): then everything
is forgotten and the caller is told, so it can reset its estimator.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np
from scipy.spatial.transform import Rotation


class Accepted(Enum):
    OK = "ok"
    NON_FINITE = "non-finite"
    BAD_QUATERNION = "degenerate quaternion"
    OUT_OF_ORDER = "out of order"
    JUMPED_BACK = "clock jumped back"


@dataclass
class Edge:
    parent: str
    stamp: float
    translation: np.ndarray
    rotation: np.ndarray  # x y z w, unit
    static: bool
    interval: float = 0.0  # running mean of the time between samples (s); 0 until the second


class TfCache:
    def __init__(self, jump_back: float = 1.0) -> None:
        self.jump_back = jump_back
        self._edges: dict[str, Edge] = {}

    def clear(self, keep_static: bool = True) -> None:
        self._edges = {c: e for c, e in self._edges.items() if keep_static and e.static}

    def set(self, parent: str, child: str, stamp: float, translation, rotation, static: bool = False) -> Accepted:
        t = np.asarray(translation, dtype=float)
        q = np.asarray(rotation, dtype=float)
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q)) and np.isfinite(stamp)):
            return Accepted.NON_FINITE
        norm = np.linalg.norm(q)
        if not 0.9 < norm < 1.1:
            return Accepted.BAD_QUATERNION
        held = self._edges.get(child)
        result = Accepted.OK
        if held is not None and not static and stamp < held.stamp:
            if held.stamp - stamp <= self.jump_back:
                return Accepted.OUT_OF_ORDER
            self.clear()
            result = Accepted.JUMPED_BACK
        interval = 0.0
        if held is not None and result is Accepted.OK and not static:
            gap = float(stamp) - held.stamp
            interval = gap if held.interval == 0.0 else 0.9 * held.interval + 0.1 * gap
        self._edges[child] = Edge(parent, float(stamp), t, q / norm, static, interval)
        return result

    def stamp(self, child: str) -> float:
        """The newest stamp of a child frame's own transform (-inf unknown, inf static)."""
        edge = self._edges.get(child)
        return -np.inf if edge is None else (np.inf if edge.static else edge.stamp)

    def budget(self, child: str, stale_after: float) -> float:
        """How far (s) a child frame's newest sample may lag the newest tracker sample and
        still count: stale_after, or three of the frame's own sample intervals if longer."""
        edge = self._edges.get(child)
        return max(stale_after, 3.0 * (0.0 if edge is None else edge.interval))

    def lookup(self, target: str, source: str):
        """(stamp, translation, rotation xyzw) of source in target, or None when unknown.
        The stamp is the oldest of the dynamic transforms on the way (inf if all static)."""
        edge = self._edges.get(source)
        if edge is not None and edge.parent == target:  # the usual tracker: one edge, nothing to compose
            return (np.inf if edge.static else edge.stamp), edge.translation.copy(), edge.rotation.copy()
        rot, trans, stamp = Rotation.identity(), np.zeros(3), np.inf
        frame, seen = source, set()
        while frame != target:
            edge = self._edges.get(frame)
            if edge is None or frame in seen:
                return None
            seen.add(frame)
            # parent_T_child applied after what is accumulated so far: x_parent = R x_child + t
            edge_rot = Rotation.from_quat(edge.rotation)
            trans = edge_rot.apply(trans) + edge.translation
            rot = edge_rot * rot
            if not edge.static:
                stamp = min(stamp, edge.stamp)
            frame = edge.parent
        return stamp, trans, rot.as_quat()

    def newest_stamp(self) -> float:
        dynamic = [e.stamp for e in self._edges.values() if not e.static]
        return max(dynamic) if dynamic else -np.inf


def sample_trackers(lookup, config, stamp: float, stale_after: float, budget=None):
    """The trackers of a sensor configuration at `stamp` (the newest tracker sample's stamp:
    staleness is judged in the input's own time, so a late delivery is latency, not loss).

    lookup(fixed_frame, frame_id) gives (stamp, translation, rotation xyzw) or None (a
    TfCache's lookup). Returns (TrackerFrame, stamps): a site is invalid when its frame is
    unknown, its pose is not finite, or its newest transform is older than `stamp` by more
    than its budget: budget(frame_id) (TfCache.budget: stale_after, or three of the
    tracker's own sample intervals if longer), else stale_after. stamps[s] is that transform's stamp (-inf
    when unknown, `stamp` when the chain is all static).
    Orientation-only sites get NaN positions, position-only sites NaN orientations."""
    from ..core.types import TrackerFrame

    S = len(config.sites)
    positions = np.full((S, 3), np.nan)
    orientations = np.full((S, 4), np.nan)
    valid = np.zeros(S, dtype=bool)
    stamps = np.full(S, -np.inf)
    for s, site in enumerate(config.sites):
        found = lookup(config.fixed_frame, site.frame_id)
        if found is None:
            continue
        t_stamp, t, q = found
        stamps[s] = t_stamp if np.isfinite(t_stamp) else stamp
        norm = np.linalg.norm(q)
        allowed = budget(site.frame_id) if budget is not None else stale_after
        if stamp - stamps[s] > allowed or not (np.all(np.isfinite(t)) and np.isfinite(norm) and norm > 0.5):
            continue
        valid[s] = True
        if site.has_position:
            positions[s] = t
        if site.has_orientation:
            orientations[s] = np.asarray(q) / norm
    return TrackerFrame(stamp, config.site_names, positions, orientations, valid), stamps
