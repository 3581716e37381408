"""Each estimated body pose as a humanoid robot's joint angles.

The human is scaled to the robot (by default robot leg over human leg, so a standing person
stands the robot at its own height), and each mapped robot link reaches for its human joint:
damped Gauss-Newton over the robot's floating base and its joints, a few steps a frame from
the last frame's solution, each step clipped to the URDF's limits (so no published angle is
ever outside them). Two weak pulls keep the solution steady where the targets leave freedom:
towards the last frame's angles (smooth in time) and towards the robot's zero pose.

A target may also turn its link as the human joint turns (`orientation`), or only turn the
bone leaving that joint as the person's, its twist left free (`direction`: thighs and shins,
so the knees bend as the person's whatever the robot's hips' width).

Feet: the fixed frame's z = 0 is the floor. A foot target below its standing height is lifted
to it (and a foot the solve puts under it is pushed up), it stands as far across from the
pelvis as the robot's own feet do, and while the estimator says that foot is planted, its
target stays where it touched down, so the robot's foot does not slide when the human
estimate's does.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..core.kinematics import forward_kinematics
from ..core.rotations import matrix_to_quat, quat_to_matrix
from ..core.skeleton import JOINT_INDEX, Skeleton
from ..core.types import BodyPose
from .collision import SelfCollision
from .mapping import SIDES, RobotMapping, bone_children, load_mapping
from .urdf_model import MAX_SOLVED_JOINTS, RobotFileError, RobotModel, load_urdf, read_urdf_text

BASE_POSITION = 1.0  # weight of the base (pelvis) place, per metre
BASE_TURN = 0.5  # and of its turn, per radian
REST = 1e-3  # weight of the pull to the zero pose
DAMPING = 1e-4  # Levenberg damping of each step
# steps of a fresh solve (the first frame, after a reset, a hold or a jump): 40 before the legs'
# directions; with them 40 ran past the node's 0.1 s solve_budget beside four burners after a
# looped walk's jump, so the robot held its pose 4 m from the body (launch test, 3 of 10
# runs); 24 gave the same figures on the first 12 validation clips (H1: hands 0.57 / 0.54 cm,
# lowest knee correlation 0.51)
FIRST_ITERATIONS = 24
# a planted foot's position weighs this many times its own: the base and the legs' directions
# give way, not the foot (H1, first 12 validation clips, skate left / right: 10 2.7 / 7.8 cm/s,
# 30 2.2 / 7.4)
PLANTED = 30.0
LET_GO = 0.15  # m (robot's): a planted foot whose human foot has gone this far is planted again there
# weight of the pull of a one-way hinge bent the wrong way back to straight: H1's knees, free
# to hyperextend 15 degrees, sat there while the person's were straight (knee against the
# person's: lowest correlation over four validation clips 0.46, with it 0.70; 0.3 gave the same)
HYPEREXTENDED = 0.05
MAX_TURN_STEP = 0.3  # rad: the largest joint or base turn of one step (a longer step is shortened)
MAX_MOVE_STEP = 0.1  # m: the largest base move of one step
# a step no joint or base coordinate of which is longer than this (rad or m) is a solve's last:
# on the first 12 validation clips every figure as with all of a frame's steps (H1 and G1, to
# 0.01 cm), the step's p50 8.7 -> 5.8 ms on H1 and 10.3 -> 7.4 on G1; 1e-2 let a foot 0.3 cm
# under the floor (0.13 before), and 2 steps a frame instead of 4 G1's lowest knee correlation
# 0.35 -> 0.28
CONVERGED = 3e-3
JUMP = 0.3  # m (robot's): a body whose pelvis moved this far in a frame jumped (it did not walk there)
GAP = 0.1  # s between two body poses over which the base is put where the body is (the joints go on)
# A target further than RESTART from its goal after a frame's solve: solved afresh as well,
# RESTART_ITERATIONS steps from the neutral pose, the closer of the two kept; where the fresh
# one is no closer, not tried again for RESTART_WAIT. On G1 over the validation people (53
# clips): feet 2.10 / 2.35 cm off -> 1.62 / 1.88, hands 1.88 / 1.44 -> 1.64 / 1.33, frames
# with links overlapping 0.25 % -> 0.10 %; 12 steps did as well as 40
RESTART = 0.08  # m
RESTART_ITERATIONS = 12
RESTART_WAIT = 0.25  # s
# the clearance the solver keeps between two of the robot's links (robot/collision.py), and how
# hard: a pair closer than CLEARANCE is pushed apart. 3 did while only the feet and hands
# pulled; with the thighs and shins turned as the person's, G1's links overlapped in 0.37 % of
# the validation frames (0.09 % with 6, hands and feet within 0.01 cm of 3's; 10 overshot before)
CLEARANCE = 0.01  # m
COLLISION = 6.0
# a foot below its standing height (the floor) is pushed up this hard, one-sided: its goal is
# never below the floor, but its weight alone left H1's feet up to 3.5 cm under it where the
# legs' directions pulled
FLOOR = 10.0
# The farthest robot base place given (m): a body's root is refused beyond 1,000 m
# (io/output.py) and a robot is at most 20 times a person (a mapping's scale)
MAX_BASE = 20_000.0


@dataclass(frozen=True)
class RobotPose:
    stamp: float
    positions: np.ndarray  # (moving joints,) in RobotModel.moving order, within limits
    base_position: np.ndarray  # (3,) the base link's place in the fixed frame
    base_quat: np.ndarray  # (4,) x y z w
    reached: np.ndarray  # (targets, 3) where each target point is
    wanted: np.ndarray  # (targets, 3) the scaled human joint it reaches for (before the floor and locks)
    valid: bool = True
    fresh: bool = False  # solved afresh (a start, after a hold or a gap, a jump): not from the last frame


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a x b of (k, 3) arrays (numpy's cross costs more than the product for three rows)."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )


def _skews(v: np.ndarray) -> np.ndarray:
    """(k, 3, 3) skew matrices of (k, 3) vectors (a x b = skew(a) @ b)."""
    out = np.zeros((len(v), 3, 3))
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    out[:, 1, 0], out[:, 2, 0], out[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return out


@dataclass(frozen=True)
class _TargetWeights:
    """A mapping's targets' weights as arrays (targets,), for the rows of all targets at once."""

    position: np.ndarray
    orientation: np.ndarray
    direction: np.ndarray
    contact: np.ndarray  # bool: a foot (it has a contact side)

    @classmethod
    def of(cls, mapping: RobotMapping) -> _TargetWeights:
        targets = mapping.targets
        return cls(
            np.array([t.position for t in targets], float),
            np.array([t.orientation for t in targets], float),
            np.array([t.direction for t in targets], float),
            np.array([bool(t.contact) for t in targets], bool),
        )


def _log(r: np.ndarray) -> np.ndarray:
    """The rotation vector of a rotation matrix."""
    cos = min(1.0, max(-1.0, (np.trace(r) - 1.0) / 2.0))
    angle = math.acos(cos)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if angle < 1e-6:
        return w / 2.0
    if math.pi - angle < 1e-4:  # near a half turn the skew part vanishes: the axis from the diagonal
        axis = np.sqrt(np.maximum((np.diag(r) + 1.0) / 2.0, 0.0))
        k = int(np.argmax(axis))
        axis = (r[:, k] + np.eye(3)[k]) / (2.0 * axis[k]) if axis[k] > 0 else axis
        return axis / np.linalg.norm(axis) * angle
    return w * (angle / (2.0 * math.sin(angle)))


def _exp(v: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(v))
    if angle < 1e-12:
        return np.eye(3)
    k = _skew(v / angle)
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


# A hinge whose zero lies within HINGE_NEAR of one limit and whose range reaches HINGE_REACH the
# other way bends only that way (a knee, an elbow): its neutral is bent HINGE_BEND into its
# range (a quarter of it at most). Read from the limits, never assumed from names or axes.
HINGE_NEAR = 0.3  # rad
HINGE_REACH = 1.2  # rad
HINGE_BEND = 0.35  # rad (20 degrees)


def hinge_ways(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """+1 for a one-way hinge that bends to positive angles, -1 to negative, 0 for the rest."""
    bends_up = (np.abs(lower) <= HINGE_NEAR) & (upper >= HINGE_REACH)
    bends_down = (np.abs(upper) <= HINGE_NEAR) & (lower <= -HINGE_REACH)
    return bends_up.astype(float) - bends_down.astype(float)


def neutral_pose(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Each joint's neutral value: zero within its limits, or for a one-way hinge a small bend
    the way its limits allow."""
    neutral = np.clip(0.0, lower, upper)
    ways = hinge_ways(lower, upper)
    bends_up, bends_down = ways > 0, ways < 0
    span = np.where(np.isfinite(upper - lower), upper - lower, 0.0)
    bend = np.minimum(HINGE_BEND, 0.25 * span)
    neutral = np.where(bends_up, np.maximum(lower, 0.0) + bend, neutral)
    neutral = np.where(bends_down, np.minimum(upper, 0.0) - bend, neutral)
    return np.clip(neutral, lower, upper)


def load_retarget(mapping: str | Path, urdf: str | Path | None, skeleton: Skeleton) -> HumanoidRetarget:
    """A retargeting from a mapping YAML and the robot's URDF (empty or None: the one the
    mapping names); RobotFileError (one line) where either cannot be used."""
    robot = load_mapping(mapping)
    path = Path(urdf) if urdf else robot.urdf
    if path is None:
        raise RobotFileError(f"{mapping}: names no urdf; give the robot's URDF file")
    return HumanoidRetarget(load_urdf(path), robot, skeleton)


def robot_urdf_text(mapping: str | Path, urdf: str | Path | None) -> str:
    """The robot's URDF as text (empty or None: the file the mapping names), for its
    robot_description; RobotFileError (one line) where it cannot be read."""
    path = Path(urdf) if urdf else load_mapping(mapping).urdf
    if path is None:
        raise RobotFileError(f"{mapping}: names no urdf; give the robot's URDF file")
    return read_urdf_text(path)


class HumanoidRetarget:
    """Body poses of one person (skeleton) as joint angles of one robot (model, mapping)."""

    def __init__(self, model: RobotModel, mapping: RobotMapping, skeleton: Skeleton) -> None:
        self.model, self.mapping, self.skeleton = model, mapping, skeleton
        self.names = tuple(j.name for j in model.moving)
        self.lower, self.upper = model.limits()
        try:
            self.base = model.link(mapping.base)
            self.links = [model.link(t.link) for t in mapping.targets]
        except RobotFileError as err:  # the mapping names it: say which file
            raise RobotFileError(f"{mapping.source}: {err}") from None
        chains = [np.array(model.chain(link), int) for link in self.links]
        # only the joints between the base and a target move: the others have nothing to reach
        # for and stay at the zero pose, so the normal equations leave them out
        self.solved = np.unique(np.concatenate(chains)) if chains else np.zeros(0, int)
        if len(self.solved) > MAX_SOLVED_JOINTS:
            raise RobotFileError(
                f"{mapping.source}: its targets hang from {len(self.solved)} moving joints; at most "
                f"{MAX_SOLVED_JOINTS} are solved (a humanoid has 20-60)"
            )
        moving = model.moving
        self._solved_axes = np.array([moving[i].axis for i in self.solved], float).reshape(-1, 3)
        self._solved_prismatic = np.array([moving[i].kind == "prismatic" for i in self.solved], bool)
        self._in_chain = np.zeros((len(chains), len(self.solved)))  # 1 where a solved joint moves a target
        for k, chain in enumerate(chains):
            self._in_chain[k, np.searchsorted(self.solved, chain)] = 1.0
        self._targets = _TargetWeights.of(mapping)
        if model.chain(self.base):
            raise RobotFileError(f"{mapping.source}: base {mapping.base!r} must be the URDF's root link or fixed to it")
        self.points = np.array([t.point for t in mapping.targets], float)
        self._reaching = [k for k, t in enumerate(mapping.targets) if t.position > 0]  # (those _miss reads)
        self.joints = [JOINT_INDEX[t.joint] for t in mapping.targets]
        # the bone leaving each direction target's joint, at the T-pose (unit; zero where unused)
        self.bones = np.zeros((len(mapping.targets), 3))
        for k, t in enumerate(mapping.targets):
            if t.direction > 0:
                offset = skeleton.offsets[bone_children(t.joint)[0]]
                self.bones[k] = offset / max(float(np.linalg.norm(offset)), 1e-9)
        self.rest_q = np.clip(0.0, self.lower, self.upper)  # the zero pose: the scale and the feet's turn
        # where the solver starts and what it is pulled towards: hinges bent a little the way
        # their limits let them (a straight knee is a singular start, from which H1's knee
        # went to its hyperextension limit and stayed there)
        self.neutral_q = neutral_pose(self.lower, self.upper)
        self.hinge_ways = hinge_ways(self.lower, self.upper)
        rest_links, _ = model.forward(self.rest_q, np.eye(4))
        to_base = np.linalg.inv(rest_links[self.base])
        # the root link in the base link's frame at the zero pose: the solver places the base,
        # and the tree is computed from its root
        self._base_in_root = to_base
        rest = [to_base @ rest_links[link] for link in self.links]
        self.rest_turns = np.array([r[:3, :3] for r in rest])  # each link's turn at the zero pose, base unturned
        self._rest_bones = np.einsum("kba,kb->ka", self.rest_turns, self.bones)  # each bone in its link's frame
        rest_points = np.array([r[:3, :3] @ p + r[:3, 3] for r, p in zip(rest, self.points, strict=True)])
        self._scale_to(rest_points)
        self.over_budget = 0  # solves abandoned at their time budget (step's budget)
        self.restarts = 0  # frames whose fresh solve came closer than the one from the last frame
        self.reset()

    def _scale_to(self, rest_points: np.ndarray) -> None:
        """The scale and the floor heights, from the feet targets (those with a contact)."""
        feet = [k for k, t in enumerate(self.mapping.targets) if t.contact]
        human = self.skeleton.rest_positions()  # pelvis at the origin, T-pose
        floor = human[:, 2].min()
        if feet:
            robot_leg = float(np.mean([-rest_points[k, 2] for k in feet]))
            human_leg = float(np.mean([-human[self.joints[k], 2] for k in feet]))
            self.human_ankle = float(np.mean([human[self.joints[k], 2] - floor for k in feet]))
        elif self.mapping.scale is None:
            raise RobotFileError(f"{self.mapping.source}: scale: auto needs feet targets (with contact: left/right)")
        else:
            robot_leg = human_leg = 1.0
            self.human_ankle = 0.0
        if self.mapping.scale is None and not robot_leg > 0.05:
            raise RobotFileError(
                f"{self.mapping.source}: the feet targets are not below the base at the zero pose; give a scale"
            )
        self.scale = self.mapping.scale if self.mapping.scale is not None else robot_leg / human_leg
        # the feet kept as far apart as the robot's hips, not the person's scaled: H1's ankles
        # stand 0.41 m apart, a person's scaled 0.19 m, and legs turned as the person's then
        # reached 11 cm past the person's feet (across, in the pelvis's frame)
        self.stance = np.zeros_like(rest_points)
        for k in feet:
            self.stance[k, :2] = rest_points[k, :2] - self.scale * human[self.joints[k], :2]
        self.ankle_height = (
            self.mapping.ankle_height if self.mapping.ankle_height is not None else self.scale * self.human_ankle
        )

    def to_robot(self, points: np.ndarray) -> np.ndarray:
        """Human points (..., 3) in the fixed frame, as the robot's: scaled about the floor,
        a foot's standing height going to the robot's."""
        out = np.asarray(points, float) * self.scale
        out[..., 2] = self.scale * (np.asarray(points, float)[..., 2] - self.human_ankle) + self.ankle_height
        return out

    def reset(self) -> None:
        """Forget the last solution and the planted feet (a new recording, a jump)."""
        self.q = self.neutral_q.copy()
        self.base_turn = np.eye(3)
        self.base_place = np.zeros(3)
        self._locks: dict[int, np.ndarray] = {}
        self._last: RobotPose | None = None
        self._fresh = True  # the next pose is solved from its own place (FIRST_ITERATIONS)
        self._steps_left = 0  # steps of a fresh solve still to take (one past the time budget goes on)
        self._last_goal: np.ndarray | None = None  # where the last body pose put the base (a jump is from there)
        self._next_restart = -math.inf  # no fresh solve after a miss is tried before this stamp

    def step(self, pose: BodyPose, budget: float | None = None) -> RobotPose:
        """The robot's pose for a body pose. An invalid or non-finite body pose holds the last
        robot pose, marked invalid (the zero pose before the first); so does a solve that
        takes longer than `budget` seconds (None: no limit), counted in `over_budget`."""
        if not pose.valid or not pose.is_finite():
            self._fresh, self._steps_left = True, 0  # what comes after is solved afresh
            return self._held(pose.stamp)
        turns, places = forward_kinematics(quat_to_matrix(pose.local_quats), pose.root_position, self.skeleton.offsets)
        base_goal = self.to_robot(places[0])
        # the first pose, the first after invalid ones, or a body that jumped (an estimate that
        # starts over, a looped recording): solved from the body's place at once rather than a
        # trust region's steps behind; after a jump, its feet are planted again
        jumped = self._last_goal is None or float(np.linalg.norm(base_goal - self._last_goal)) > JUMP
        gap = self._last is not None and pose.stamp - self._last.stamp > GAP
        first = jumped or self._fresh
        self._last_goal = base_goal
        if first or gap:
            self.base_place, self.base_turn = base_goal, turns[0].copy()
        if jumped or (self._fresh and not self._steps_left):
            self._steps_left = FIRST_ITERATIONS
        # after a gap (a starved node drops what waits) the joints go on from the last solution,
        # in a frame's steps: a fresh solve there made a starved node slower still (beside four
        # burners its 24 steps took 270 ms, past the node's budget, so it held and started
        # afresh again: the launch test's robot published 206 poses for 1940 bodies)
        self._fresh = False
        if jumped:  # (a foot planted before a short hold or gap is still where it was)
            self._locks.clear()
        wanted = self.to_robot(places[self.joints]) + self.stance @ turns[0].T
        goals = wanted.copy()
        for k, target in enumerate(self.mapping.targets):
            if not target.contact:
                continue
            goals[k, 2] = max(goals[k, 2], self.ankle_height)
            if pose.contact[SIDES.index(target.contact)]:
                held = self._locks.get(k)
                if held is None or np.linalg.norm(held[:2] - goals[k, :2]) > LET_GO:
                    held = self._locks[k] = goals[k, :2].copy()
                # held where it touched down across the floor, but as high as the person's: a
                # planted heel rises before the toes leave, and held at the floor G1's and H1's
                # stance legs stretched straight (the person's knee 20-30 degrees, theirs 4-13)
                goals[k, :2] = held
            else:
                self._locks.pop(k, None)
        goal_turns = turns[self.joints] @ self.rest_turns
        planted = np.array([k in self._locks for k in range(len(goals))])
        start = (self.q.copy(), self.base_place.copy(), self.base_turn.copy())
        deadline = math.inf if budget is None else time.perf_counter() + budget
        try:
            left = self._solve(base_goal, turns[0], goals, goal_turns, planted, self._steps_left or None, deadline)
        except np.linalg.LinAlgError:  # a singular step (bounded robot files make it rare): hold, start afresh
            self.reset()
            return self._held(pose.stamp)
        if left:
            self.over_budget += 1
            if self._steps_left:  # a fresh solve goes on from where it stopped, on the next frame
                self._steps_left, self._fresh = left, True
            else:  # a frame's steps: the last solution, as it was
                self.q, self.base_place, self.base_turn = start
            return self._held(pose.stamp)
        self._steps_left = 0
        reached = self._reached()
        miss = self._miss(reached, goals)
        if not first and miss > RESTART and pose.stamp >= self._next_restart:
            # a limb the last frame's solution cannot bring to its goal may be caught in the wrong
            # branch (G1's leg on a dance's crossing step turned its hip yaw to its 158 degree
            # limit and folded the knee, and stayed so): solved afresh as well, the closer kept
            kept = (self.q.copy(), self.base_place.copy(), self.base_turn.copy())
            self.q, self.base_place, self.base_turn = self.neutral_q.copy(), base_goal, turns[0].copy()
            redone = not self._solve(base_goal, turns[0], goals, goal_turns, planted, RESTART_ITERATIONS, deadline)
            again = self._reached()
            if redone and self._miss(again, goals) < miss:
                reached = again
                self.restarts += 1
            else:  # out of reach from anywhere (G1's arms are short): not tried again for a while
                self.q, self.base_place, self.base_turn = kept
                self._next_restart = pose.stamp + RESTART_WAIT
        result = RobotPose(
            pose.stamp,
            self.q.copy(),
            self.base_place.copy(),
            matrix_to_quat(self.base_turn),
            reached,
            wanted,
            fresh=first,
        )
        if not (np.all(np.isfinite(result.positions)) and np.all(np.abs(result.base_position) <= MAX_BASE)):
            self.reset()  # never published: the last good pose is held instead
            return self._held(pose.stamp)
        self._last = result
        return result

    @cached_property
    def collision(self) -> SelfCollision:
        """The robot's self-collision check, its pairs those apart at the zero and neutral poses."""
        return SelfCollision(self.model, [self.rest_q, self.neutral_q])

    def _held(self, stamp: float) -> RobotPose:
        if self._last is None:
            zero = np.zeros((len(self.links), 3))
            return RobotPose(
                stamp, self.neutral_q.copy(), np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), zero, zero, False
            )
        last = self._last
        return RobotPose(stamp, last.positions, last.base_position, last.base_quat, last.reached, last.wanted, False)

    def _reached(self) -> np.ndarray:
        """Where each target's point is (targets, 3) at the current solution."""
        links = self._links()
        return np.array(
            [links[link][:3, :3] @ p + links[link][:3, 3] for link, p in zip(self.links, self.points, strict=True)]
        )

    def _miss(self, reached: np.ndarray, goals: np.ndarray) -> float:
        """The furthest a target that has a position weight is from its goal [m]."""
        k = self._reaching
        return float(np.linalg.norm(reached[k] - goals[k], axis=-1).max(initial=0.0))

    def _links(self) -> np.ndarray:
        return self.link_transforms(self.q, self.base_place, self.base_turn)

    def link_transforms(self, positions: np.ndarray, base_position: np.ndarray, base_turn: np.ndarray) -> np.ndarray:
        """Every link's transform (links, 4, 4) in the fixed frame for joint values and the base
        link's place and turn (3, 3) (a RobotPose's, as the node and the bag publish them)."""
        base = np.eye(4)
        base[:3, :3], base[:3, 3] = base_turn, base_position
        links, _ = self.model.forward(np.asarray(positions, float), base @ self._base_in_root)
        return links

    def _solve(
        self, base_goal, base_goal_turn, goals, goal_turns, planted, iterations: int | None, deadline: float
    ) -> int:
        """Gauss-Newton steps towards the goals: how many of them were left when the clock
        passed `deadline` (time.perf_counter), 0 when all were taken."""
        solved = self.solved
        n = len(solved)
        q, lower, upper = self.q[solved], self.lower[solved], self.upper[solved]
        smooth = 0.0 if iterations else self.mapping.smoothing  # fresh: no last frame to stay near
        previous = q.copy()
        rest_q, ways = self.neutral_q[solved], self.hinge_ways[solved]
        steps = iterations or self.mapping.iterations
        for taken in range(steps):
            if time.perf_counter() > deadline:
                self.q[solved] = q
                return steps - taken
            base = np.eye(4)
            base[:3, :3], base[:3, 3] = self.base_turn, self.base_place
            self.q[solved] = q
            links, frames = self.model.forward(self.q, base @ self._base_in_root)
            rows, residuals = [], []
            # the base: its place and turn
            row = np.zeros((6, 6 + n))
            row[:3, :3] = np.eye(3) * BASE_POSITION
            row[3:, 3:6] = np.eye(3) * BASE_TURN
            rows.append(row)
            residuals.append(
                np.concatenate(
                    [(base_goal - self.base_place) * BASE_POSITION, _log(base_goal_turn @ self.base_turn.T) * BASE_TURN]
                )
            )
            self._target_rows(links, frames, goals, goal_turns, planted, rows, residuals)
            self._keep_apart(links, frames, rows, residuals)
            jac, res = np.vstack(rows), np.concatenate(residuals)
            normal = jac.T @ jac
            gradient = jac.T @ res
            # the two pulls on the joints (to the last frame's angles, to the zero pose) are one
            # row each per joint: added on the diagonal, not as 2n rows of a dense Jacobian
            joints = np.arange(6, 6 + n)
            normal[joints, joints] += smooth + REST
            gradient[6:] += smooth * (previous - q) + REST * (rest_q - q)
            # a one-way hinge bent the wrong way (a knee hyperextended: H1 allows 15 degrees)
            # only where nothing else reaches: pulled back to straight
            wrong = joints[ways * q < 0.0]
            normal[wrong, wrong] += HYPEREXTENDED
            gradient[wrong] -= HYPEREXTENDED * q[wrong - 6]
            normal[np.diag_indices_from(normal)] += DAMPING
            step = self._limited_step(normal, gradient, q, lower, upper)
            # a long step leaves the region where the linearisation holds (and the limits' clip
            # can make it worse): shortened, as a trust region would
            longest = max(np.abs(step[3:]).max() / MAX_TURN_STEP, np.abs(step[:3]).max() / MAX_MOVE_STEP, 1.0)
            step /= longest
            self.base_place = self.base_place + step[:3]
            self.base_turn = _exp(step[3:6]) @ self.base_turn
            q = np.clip(q + step[6:], lower, upper)
            if np.abs(step).max() < CONVERGED:
                break
        self.q[solved] = q
        return 0

    def _target_rows(self, links, frames, goals, goal_turns, planted, rows: list, residuals: list) -> None:
        """The targets' rows, all targets at once: each target point's move (targets, 3, 6 +
        solved) and its link's turn with the base and each joint of its chain (a loop over the
        targets before: the example humanoid's step on a walk 11.0 -> 9.0 ms p50, the same robot
        to 1e-14 m)."""
        n = len(self.solved)
        t = self._targets
        turns = links[self.links, :3, :3]
        points = np.einsum("kab,kb->ka", turns, self.points) + links[self.links, :3, 3]
        joint_frames = frames[self.solved]
        axes = np.einsum("jab,jb->ja", joint_frames[:, :3, :3], self._solved_axes)
        moved = np.cross(axes[None], points[:, None] - joint_frames[None, :, :3, 3])  # (targets, solved, 3)
        moved[:, self._solved_prismatic] = axes[self._solved_prismatic]
        moving = np.zeros((len(points), 3, 6 + n))
        moving[:, :, :3] = np.eye(3)
        moving[:, :, 3:6] = -_skews(points - self.base_place)
        moving[:, :, 6:] = (moved * self._in_chain[..., None]).transpose(0, 2, 1)
        weights = t.position * np.where(planted, PLANTED, 1.0)
        reach = weights > 0
        rows.append((moving[reach] * weights[reach, None, None]).reshape(-1, 6 + n))
        residuals.append(((goals[reach] - points[reach]) * weights[reach, None]).ravel())
        under = reach & t.contact & (points[:, 2] < self.ankle_height)  # a foot through the floor
        rows.append(moving[under, 2] * FLOOR)
        residuals.append((self.ankle_height - points[under, 2]) * FLOOR)
        if not (t.orientation > 0).any() and not (t.direction > 0).any():
            return
        turned = np.where(self._solved_prismatic[:, None], 0.0, axes)
        turning = np.zeros((len(points), 3, 6 + n))
        turning[:, :, 3:6] = np.eye(3)
        turning[:, :, 6:] = (turned[None] * self._in_chain[..., None]).transpose(0, 2, 1)
        for k in np.flatnonzero(t.orientation > 0):
            rows.append(turning[k] * t.orientation[k])
            residuals.append(_log(goal_turns[k] @ turns[k].T) * t.orientation[k])
        for k in np.flatnonzero(t.direction > 0):
            # the bone as the link carries it, turned to the person's; its twist left free (only
            # a turn across the bone moves it)
            bone = turns[k] @ self._rest_bones[k]
            person_bone = goal_turns[k] @ self._rest_bones[k]
            across = _cross(bone[None], person_bone[None])[0]
            sine = math.sqrt(float(across @ across))
            angle = math.atan2(sine, float(bone @ person_bone))
            across_only = (np.eye(3) - np.outer(bone, bone)) * t.direction[k]
            rows.append(across_only @ turning[k])
            residuals.append((across / sine * angle if sine > 1e-9 else np.zeros(3)) * t.direction[k])

    def _keep_apart(self, links: np.ndarray, frames: np.ndarray, rows: list, residuals: list) -> None:
        """A row for each pair of links closer than CLEARANCE: its clearance along the line
        between the closest points, to grow by what it lacks (one-sided: pairs further apart
        add nothing)."""
        gap, on_first, on_second = self.collision.contacts(links)
        for k in np.flatnonzero(gap < CLEARANCE):
            apart = on_first[k] - on_second[k]
            length = float(np.linalg.norm(apart))
            if length < 1e-9:  # axes crossing: no direction to push along
                continue
            normal = apart / length
            first, second = self.collision.pair_links(int(k))
            row = normal @ (
                self._point_rows(on_first[k], first, frames) - self._point_rows(on_second[k], second, frames)
            )
            rows.append(row[None] * COLLISION)
            residuals.append(np.array([(CLEARANCE - gap[k]) * COLLISION]))

    def _point_rows(self, point: np.ndarray, link: int, frames: np.ndarray) -> np.ndarray:
        """How a point fixed to a link moves (3, 6 + solved joints) with the base's place and
        turn and each solved joint."""
        rows = np.zeros((3, 6 + len(self.solved)))
        rows[:, :3] = np.eye(3)
        rows[:, 3:6] = -_skew(point - self.base_place)
        chain = np.array(self.model.chain(link), int)
        solved = np.isin(chain, self.solved)
        chain = chain[solved]
        if len(chain):
            moving = self.model.moving
            axes = np.einsum("kab,kb->ka", frames[chain, :3, :3], np.array([moving[i].axis for i in chain]))
            moved = _cross(axes, point - frames[chain, :3, 3])
            prismatic = np.array([moving[i].kind == "prismatic" for i in chain])
            moved[prismatic] = axes[prismatic]
            rows[:, 6 + np.searchsorted(self.solved, chain)] = moved.T
        return rows

    @staticmethod
    def _limited_step(normal: np.ndarray, gradient: np.ndarray, q, lower, upper) -> np.ndarray:
        """The Gauss-Newton step with the joints it would push past a limit held at that
        limit and the rest solved again for it (a few rounds of an active set): clipping the
        free step instead lets the other joints act as if the clipped ones had moved, and a
        planted foot slides."""
        step = np.zeros(len(gradient))
        free = np.ones(len(gradient), bool)
        for _ in range(4):
            rhs = gradient[free] - normal[np.ix_(free, ~free)] @ step[~free]
            step[free] = np.linalg.solve(normal[np.ix_(free, free)], rhs)
            moved = q + step[6:]
            over = free[6:] & ((moved < lower) | (moved > upper))
            if not over.any():
                break
            held = np.flatnonzero(over)
            step[6 + held] = np.clip(moved[held], lower[held], upper[held]) - q[held]
            free[6 + held] = False
        return step
