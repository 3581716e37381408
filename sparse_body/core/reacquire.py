"""What a method is given while a tracker is lost and when it comes back (the filter options
`filter_carry_lost`, seconds, `filter_reacquire_speed` and `filter_leap_speed`, m/s).

Carried: a lost tracker's last joint target moves on with the body, rigidly with the first
tracker still followed (the head in every shipped configuration: its position and its
heading), for up to carry_lost seconds; a leg's tracker (a foot's) is not carried. A method
that needs every tracker (AvatarJLM, LoBSTr) keeps estimating instead of freezing the whole
body, and every method sees the hand where a user expects it: where it was, relative to them.

Eased: when a tracker comes back (after a loss, or, with leap_speed, when its samples leap
faster than that between two frames, as a frozen controller's do when tracking resumes), its
joint target
starts where the last estimate had that joint and catches up with the tracker at
reacquire_speed: the offset shrinks by speed x dt a frame, so the joint's step is its
tracker's own step plus at most that. The user sees a hand glide back rather than snap.

Why here, on the joint targets every method reads: each method guessed a lost hand in its own
way and snapped back from its guess (the README's tracker-failure table); treating the targets
once gives every method the same loss and the same return.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from . import mat3
from .mat3 import njit
from .skeleton import LOWER_BODY, joint_indices
from .types import TrackerFrame

# A lost tracker on a leg is not carried: a foot stays planted while the body moves on, or
# swings on its own, and moved rigidly with the head it was a worse guess than none
# (validation, six-point, DragPoser's faulty sensors: DragPoser 4.31 cm MPJPE carried, 4.07 not)
NOT_CARRIED = frozenset(joint_indices(LOWER_BODY))


class Reacquisition:
    """Per site, in a frame's order: the last usable target, whether it is carried, and the
    offset a returning tracker's target still has."""

    def __init__(self, speed: float, carry: float, leap_speed: float = 0.0) -> None:
        # leap_speed > 0: a sample that leaps faster than this is a return too (a frozen tracker
        # resuming); 0: a leap is given as it is (see FilterConfig.leap_speed)
        self.speed, self.carry, self.leap_speed = float(speed), float(carry), float(leap_speed)
        self.reset()

    @property
    def enabled(self) -> bool:
        return self.speed > 0 or self.carry > 0

    def reset(self) -> None:
        self._stamp: float | None = None
        self._sites = 0

    def _start(self, count: int) -> None:
        self._sites = count
        self._last = np.zeros((count, 3))  # each site's last usable target (as the tracker gave it)
        self._given = np.zeros((count, 3))  # and as the method was given it (eased)
        self._last_rot = np.tile(np.eye(3), (count, 1, 1))
        self._last_kind = np.zeros(count, dtype=np.int64)
        self._usable = np.zeros(count, dtype=bool)  # given by its tracker in the frame before
        self._seen = np.zeros(count, dtype=bool)  # given at some time since the reset
        self._offset = np.zeros((count, 3))
        self._lost_since = np.full(count, np.nan)  # stamp of the loss, while carried
        # the body's tracker (index, position, rotation) when each site was lost, and in the frame before
        self._anchor_then: list[tuple[int, np.ndarray, np.ndarray] | None] = [None] * count
        self._anchor_last: tuple[int, np.ndarray, np.ndarray] | None = None

    def apply(
        self,
        stamp: float,
        positions: np.ndarray,
        rotations: np.ndarray,
        kinds: np.ndarray,
        position_kinds: tuple[int, ...],
        joints: np.ndarray,
        shown: Callable[[], np.ndarray | None],
    ) -> None:
        """Treat one frame's joint targets in place: positions (S, 3), rotations (S, 3, 3),
        kinds (S,) (a kind in position_kinds gives a position; 0 nothing); joints[s] site s's
        joint; shown() the joint positions (22, 3) of the last pose the estimator gave."""
        count = len(positions)
        if self._sites != count:  # another site set: start afresh
            self._start(count)
        dt = 0.0 if self._stamp is None else max(0.0, stamp - self._stamp)
        self._stamp = stamp
        max_step = self.leap_speed * dt if self.leap_speed > 0 and dt > 0 else -1.0
        anchor = _pass_through(
            positions, rotations, kinds, np.array(position_kinds, dtype=kinds.dtype), max_step,
            self._last, self._given, self._last_rot, self._last_kind, self._lost_since,
            self._usable, self._seen, self._offset,
        )  # fmt: skip
        if anchor >= -1:  # the common frame: nothing lost, returning or catching up; kept as given
            self._anchor_last = (anchor, positions[anchor].copy(), rotations[anchor].copy()) if anchor >= 0 else None
            return
        usable = np.isin(kinds, position_kinds)
        steps = np.linalg.norm(positions - self._last, axis=-1)
        leap = self._usable & (steps > max_step) if max_step >= 0 else np.zeros(count, dtype=bool)
        back = usable & ((self._seen & ~self._usable) | leap)
        easing = self._offset.any(axis=1)
        raw, raw_rot, raw_kinds = positions.copy(), rotations.copy(), kinds.copy()
        steady = np.flatnonzero(usable & ~back & ~easing)
        anchor = int(steady[0]) if len(steady) else -1  # the body's tracker this frame
        if back.any() and self.speed > 0:
            pose = shown()
            if pose is not None and anchor >= 0:
                # the last pose may be older than this frame (held while a tracker was lost):
                # carried with the body, it starts where the user saw it
                pose = pose + (raw[anchor] - pose[joints[anchor]])
            for r in np.flatnonzero(back):
                self._offset[r] = 0.0 if pose is None else pose[joints[r]] - raw[r]
        for s in range(count):
            if usable[s]:
                if not back[s] and self._offset[s].any():
                    left = np.linalg.norm(self._offset[s])
                    self._offset[s] *= max(0.0, 1.0 - self.speed * dt / left)
                positions[s] = raw[s] + self._offset[s]
                self._lost_since[s] = np.nan
                continue
            self._offset[s] = 0.0
            if self.carry > 0 and self._seen[s] and anchor >= 0 and anchor != s and int(joints[s]) not in NOT_CARRIED:
                if self._usable[s]:  # lost now: remember the anchor as it was
                    self._lost_since[s] = stamp
                    self._anchor_then[s] = self._anchor_last
                then = self._anchor_then[s]
                if then is not None and then[0] == anchor and stamp - self._lost_since[s] <= self.carry:
                    turn = mat3.yaw_frame(raw_rot[anchor]) @ mat3.yaw_frame(then[2]).T
                    positions[s] = raw[anchor] + turn @ (self._given[s] - then[1])
                    rotations[s] = turn @ self._last_rot[s]
                    kinds[s] = self._last_kind[s]
        self._anchor_last = (anchor, raw[anchor].copy(), raw_rot[anchor].copy()) if anchor >= 0 else None
        self._last[usable], self._given[usable] = raw[usable], positions[usable]
        self._last_rot[usable], self._last_kind[usable] = raw_rot[usable], raw_kinds[usable]
        self._usable[:], self._seen[:] = usable, self._seen | usable


class FreezeGuard:
    """A tracker whose sample repeats bit for bit for frozen_after seconds is lost (valid =
    False from then on, until it changes): some runtimes freeze a controller they lost at its
    last pose rather than report it lost, and a live tracker's samples always differ by its
    noise. Runs on the raw frames, before the filter, which would make a frozen sample look
    alive."""

    def __init__(self, frozen_after: float) -> None:
        self.frozen_after = float(frozen_after)
        self.reset()

    def reset(self) -> None:
        self._sites: tuple[str, ...] = ()

    def __call__(self, frame: TrackerFrame) -> TrackerFrame:
        if frame.sites != self._sites:
            count = len(frame.sites)
            self._sites = frame.sites
            self._positions, self._orientations = np.full((count, 3), np.nan), np.full((count, 4), np.nan)
            self._since = np.full(count, np.inf)  # when the repeated sample first came
        positions = np.asarray(frame.positions, dtype=float)
        orientations = np.asarray(frame.orientations, dtype=float)
        same = _equal(positions, self._positions) & _equal(orientations, self._orientations)
        self._since = np.where(same, self._since, frame.stamp)
        self._positions, self._orientations = positions.copy(), orientations.copy()
        frozen = same & (frame.stamp - self._since >= self.frozen_after)
        if not (frozen & frame.valid).any():
            return frame
        return TrackerFrame(frame.stamp, frame.sites, frame.positions, frame.orientations, frame.valid & ~frozen)


def _equal(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rows equal bit for bit, a missing (NaN) value equal to a missing one."""
    return ((a == b) | (np.isnan(a) & np.isnan(b))).all(axis=1)


# Most frames have every tracker and nothing to ease: checked and kept in one compiled call (in
# numpy, the checks alone were a quarter of an IK step).
@njit
def _pass_through(
    positions, rotations, kinds, position_kinds, max_step, last, given, last_rot, last_kind, lost_since, usable, seen,
    offset,
):  # fmt: skip
    """When no site is lost, returning (after a loss, or leaping further than max_step; < 0:
    no leaps) or catching up, keep the frame's usable targets and return the index of the
    first (the body's tracker; -1 if none); else change nothing and return -2."""
    n = positions.shape[0]
    given_now = np.zeros(n, dtype=np.bool_)
    for s in range(n):
        for kind in position_kinds:
            if kinds[s] == kind:
                given_now[s] = True
        if offset[s, 0] != 0.0 or offset[s, 1] != 0.0 or offset[s, 2] != 0.0:
            return -2
        if seen[s] and not (given_now[s] and usable[s]):
            return -2  # lost now, or back after a loss
        if given_now[s] and usable[s] and max_step >= 0.0:
            d = positions[s] - last[s]
            if np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) > max_step:
                return -2
    anchor = -1
    for s in range(n):
        if given_now[s]:
            if anchor < 0:
                anchor = s
            last[s] = positions[s]
            given[s] = positions[s]
            last_rot[s] = rotations[s]
            last_kind[s] = kinds[s]
            lost_since[s] = np.nan
        usable[s] = given_now[s]
        seen[s] = seen[s] or given_now[s]
    return anchor
