"""What a run of robot poses and commands is worth, against the person it follows: the figures
`scripts/retarget_eval.py` files per clip and the tests hold.

retarget_quality scores the solver's poses (how near each target came to its scaled human
joint, limits, self-collision, planted feet). command_quality scores what a controller is sent
(robot/limits.py's commands): speeds and accelerations against the URDF's and the mapping's
limits, and whether the robot's knees follow the person's (Unitree's G1 held both knees locked
straight through a walk whose knees bent 29-71 degrees, issue 74; its knee angle against the
person's correlated 0.45).
"""

from __future__ import annotations

import numpy as np

from ..core.rotations import quat_to_matrix
from ..core.skeleton import JOINT_INDEX
from .mapping import SIDES
from .retarget import HumanoidRetarget, RobotPose

OVER = 1e-6  # relative: a speed this far past its limit is over it (rounding is not)
AT_LIMIT = 0.01  # rad: a joint this near a limit is at it
MOVING = 0.5  # rad/s: a person's knee turning this fast is moving


def retarget_quality(
    poses: list[RobotPose], retarget: HumanoidRetarget, contacts: np.ndarray, fps: float
) -> dict[str, float]:
    """What a run of robot poses is worth: each target's mean and 95th-percentile distance
    [cm] from its scaled human joint (feet: only while not planted, where the lock moves the
    goal), joint values outside the URDF's limits (a count), the frames where two of the
    robot's links overlap (robot/collision.py) and how deep the deepest 1 % go, and each foot
    target's skate [cm/s]: its mean horizontal speed while planted on consecutive frames once
    the start's ramp is over (the mapping's `ramp`: the commands ease from the robot's pose
    then, and an estimate's first frames jump: IK's feet moved 30-70 cm between its first two
    frames on the validation runs, each a skate of 10-44 m/s), beside the scaled person's on
    the same frames (the estimate's own skate, which a held foot lets go of past LET_GO)."""
    reached = np.array([p.reached for p in poses])
    wanted = np.array([p.wanted for p in poses])
    q = np.array([p.positions for p in poses])
    stamps = np.array([p.stamp for p in poses])
    settled = stamps >= stamps[0] + retarget.mapping.ramp if len(poses) else np.zeros(0, bool)
    out: dict[str, float] = {
        "frames": float(len(poses)),
        "limit violations": float(np.sum((q < retarget.lower - 1e-9) | (q > retarget.upper + 1e-9))),
    }
    clearance = np.array(
        [
            retarget.collision.distances(
                retarget.link_transforms(p.positions, p.base_position, quat_to_matrix(p.base_quat))
            ).min(initial=np.inf)
            for p in poses
        ]
    )
    out["self-collision frames [%]"] = float(np.mean(clearance < 0.0) * 100) if len(poses) else 0.0
    out["self-collision depth p99 [cm]"] = float(max(0.0, -np.percentile(clearance, 1)) * 100) if len(poses) else 0.0
    for k, target in enumerate(retarget.mapping.targets):
        if target.position <= 0:
            continue
        error = np.linalg.norm(reached[:, k] - wanted[:, k], axis=-1) * 100
        if target.contact:
            planted = contacts[:, SIDES.index(target.contact)]
            both = planted[1:] & planted[:-1] & settled[1:]
            robot_and_person = (
                (f"{target.name} skate [cm/s]", reached),
                (f"{target.name} skate, the person's [cm/s]", wanted),
            )
            for key, points in robot_and_person:
                speed = np.linalg.norm(np.diff(points[:, k, :2], axis=0), axis=-1) * fps * 100
                out[key] = float(speed[both].mean()) if both.any() else 0.0
            out[f"{target.name} below floor [cm]"] = float(
                max(0.0, retarget.ankle_height - reached[:, k, 2].min()) * 100
            )
            error = error[~planted]
        if len(error):
            out[f"{target.name} error [cm]"] = float(error.mean())
            out[f"{target.name} error p95 [cm]"] = float(np.percentile(error, 95))
    return out


def knee_joints(retarget: HumanoidRetarget) -> dict[str, tuple[int, float]]:
    """side -> (index among the robot's moving joints, +1 or -1: the way it bends) for the
    joints whose name holds `knee` and the side (Unitree's `left_knee_joint`); the way it bends
    is read from the limits (the longer side of zero), never assumed."""
    knees = {}
    for k, joint in enumerate(retarget.model.moving):
        for side in SIDES:
            if "knee" in joint.name and side in joint.name:
                knees[side] = (k, 1.0 if retarget.upper[k] >= -retarget.lower[k] else -1.0)
    return knees


def command_quality(
    commands: np.ndarray,
    velocities: np.ndarray,
    stamps: np.ndarray,
    retarget: HumanoidRetarget,
    human_local: np.ndarray,
) -> dict[str, float]:
    """What a controller is sent, (T, joints) commands and velocities at (T,) stamps, against
    the limits and the person's (T, 22, 3, 3) local joint turns: the share of velocity samples
    over the URDF's limit and the highest share of it, the highest acceleration as a share of
    the mapping's max_acceleration (where it gives one), and per knee, once the start's ramp
    is over (the mapping's `ramp`): the correlation of its bend with the person's knee's, and
    the share of the frames where the person's knee moves (over MOVING) in which the robot's
    sits at a limit; and the person's knee's range (5th to 95th percentile)."""
    limit = retarget.model.velocity_limits()
    share = np.abs(velocities) / limit
    out = {
        "velocity over limit [%]": float(np.mean(share > 1.0 + OVER) * 100),
        "velocity, highest share of limit": float(share.max(initial=0.0)),
    }
    if retarget.mapping.max_acceleration is not None and len(stamps) > 1:
        dt = np.maximum(np.diff(stamps), 1e-9)[:, None]
        accel = np.abs(np.diff(velocities, axis=0)) / dt
        out["acceleration, highest share of limit"] = float(accel.max() / retarget.mapping.max_acceleration)
    ramped = stamps >= stamps[0] + retarget.mapping.ramp if len(stamps) else np.zeros(0, bool)
    commands, stamps, human_local = commands[ramped], stamps[ramped], human_local[ramped]
    for side, (k, sign) in knee_joints(retarget).items():
        person = _angle(human_local[:, JOINT_INDEX[f"{side}_knee"]])
        robot = sign * commands[:, k]
        both_move = np.std(person) > 1e-6 and np.std(robot) > 1e-6
        out[f"{side} knee correlation"] = float(np.corrcoef(person, robot)[0, 1]) if both_move else float("nan")
        if len(person):  # (a knee that hardly moves has no correlation worth the name)
            out[f"{side} knee range, the person's [deg]"] = float(np.degrees(np.ptp(np.percentile(person, [5, 95]))))
        turning = np.abs(np.gradient(person, stamps)) > MOVING if len(stamps) > 2 else np.zeros(len(person), bool)
        at_limit = (commands[:, k] <= retarget.lower[k] + AT_LIMIT) | (commands[:, k] >= retarget.upper[k] - AT_LIMIT)
        out[f"{side} knee at a limit while the person's moves [%]"] = (
            float(np.mean(at_limit[turning]) * 100) if turning.any() else 0.0
        )
    return out


def _angle(turns: np.ndarray) -> np.ndarray:
    """(T,) the angle [rad] of (T, 3, 3) rotations."""
    return np.arccos(np.clip((np.trace(turns, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0))
