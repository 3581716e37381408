"""A robot's self-collisions, from the capsules its URDF gives each link (urdf_model.Capsule:
the collision primitives, or a cylinder fitted to a mesh link's mass and inertia, since the
mesh files are not read).

Which pairs are checked is decided as MoveIt's setup assistant decides it: not two links
within two joints of each other (a joint's two sides always touch), and not a pair that
already touches at the robot's own reference poses (its zero pose and the solver's neutral
one), since those are shapes overlapping by construction (a fitted capsule of a shell is
rough), not a pose reaching through itself. Distances are between segments, less both radii.
"""

from __future__ import annotations

import numpy as np

from .urdf_model import RobotModel

NEAR = 2  # joints: links this close in the tree are never checked against each other


def segment_distances(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """The least distance between segments p1-q1 and p2-q2, row by row ((n, 3) each)."""
    closest1, closest2 = closest_points(p1, q1, p2, q2)
    return np.linalg.norm(closest1 - closest2, axis=1)


def closest_points(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The closest points of segments p1-q1 and p2-q2, row by row, by clamping the closest
    parameters of the two lines to the segments (Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = np.einsum("ij,ij->i", d1, d1), np.einsum("ij,ij->i", d2, d2)
    b, c, f = np.einsum("ij,ij->i", d1, d2), np.einsum("ij,ij->i", d1, r), np.einsum("ij,ij->i", d2, r)
    tiny = 1e-12
    denom = a * e - b * b
    s = np.where(denom > tiny, np.clip((b * f - c * e) / np.maximum(denom, tiny), 0.0, 1.0), 0.0)
    t = np.where(e > tiny, (b * s + f) / np.maximum(e, tiny), 0.0)
    # t outside the second segment: clamp it and find s again
    low, high = t < 0.0, t > 1.0
    t = np.clip(t, 0.0, 1.0)
    s = np.where(low, np.clip(-c / np.maximum(a, tiny), 0.0, 1.0), s)
    s = np.where(high, np.clip((b - c) / np.maximum(a, tiny), 0.0, 1.0), s)
    point2, point1 = e <= tiny, a <= tiny  # a segment that is a point
    t = np.where(point2, 0.0, t)
    s = np.where(point2, np.clip(-c / np.maximum(a, tiny), 0.0, 1.0), s)
    s = np.where(point1, 0.0, s)
    t = np.where(point1, np.clip(f / np.maximum(e, tiny), 0.0, 1.0), t)
    t = np.where(point1 & point2, 0.0, t)
    return p1 + s[:, None] * d1, p2 + t[:, None] * d2


class SelfCollision:
    """distances(links) -> each checked pair's clearance (m; negative: the shapes overlap),
    for link transforms (links, 4, 4) as RobotModel.forward gives them."""

    def __init__(self, model: RobotModel, reference: list[np.ndarray], margin: float = 0.0) -> None:
        """reference: joint values (moving,) of poses whose touching pairs are not checked."""
        self.model = model
        capsules = model.capsules
        self._links = np.array([c.link for c in capsules], int)
        self._a = np.array([c.a for c in capsules]).reshape(-1, 3)
        self._b = np.array([c.b for c in capsules]).reshape(-1, 3)
        self._radii = np.array([c.radius for c in capsules])
        hops = _tree_hops(model)
        pairs = [
            (i, j)
            for i in range(len(capsules))
            for j in range(i + 1, len(capsules))
            if hops[self._links[i], self._links[j]] > NEAR
        ]
        self.first = np.array([i for i, _ in pairs], int)
        self.second = np.array([j for _, j in pairs], int)
        for q in reference:
            links, _ = model.forward(q, np.eye(4))
            keep = self.distances(links) > margin
            self.first, self.second = self.first[keep], self.second[keep]

    @property
    def pairs(self) -> list[tuple[str, str]]:
        """The checked pairs, by link name."""
        names = self.model.links
        return [(names[self._links[i]], names[self._links[j]]) for i, j in zip(self.first, self.second, strict=True)]

    def distances(self, links: np.ndarray) -> np.ndarray:
        return self.contacts(links)[0]

    def contacts(self, links: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(each pair's clearance, the closest point on its first capsule's axis and on its
        second's, (pairs, 3) each, in the frame of `links`)."""
        turns, places = links[self._links, :3, :3], links[self._links, :3, 3]
        a = np.einsum("nij,nj->ni", turns, self._a) + places
        b = np.einsum("nij,nj->ni", turns, self._b) + places
        i, j = self.first, self.second
        on_first, on_second = closest_points(a[i], b[i], a[j], b[j])
        gap = np.linalg.norm(on_first - on_second, axis=1) - self._radii[i] - self._radii[j]
        return gap, on_first, on_second

    def pair_links(self, k: int) -> tuple[int, int]:
        """The link indices of checked pair k."""
        return int(self._links[self.first[k]]), int(self._links[self.second[k]])


def _tree_hops(model: RobotModel) -> np.ndarray:
    """(links, links): how many joints lie between two links in the tree."""
    count = len(model.links)
    hops = np.full((count, count), count + 1, int)
    neighbours: dict[int, list[int]] = {}
    for joint in model.joints:
        neighbours.setdefault(joint.parent, []).append(joint.child)
        neighbours.setdefault(joint.child, []).append(joint.parent)
    for start in range(count):
        hops[start, start] = 0
        todo = [start]
        while todo:
            link = todo.pop(0)
            for other in neighbours.get(link, []):
                if hops[start, other] > hops[start, link] + 1:
                    hops[start, other] = hops[start, link] + 1
                    todo.append(other)
    return hops
