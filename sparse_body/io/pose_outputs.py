"""The messages made of each estimated pose, one entry a topic: the estimator node publishes
every entry (under its output namespace) and `process` writes every entry to the estimate bag,
from the same bytes. An added output is a function from a PoseBatch to one CDR message a pose
and its line in POSE_OUTPUTS; the node's publisher, the bag's connection, `--topics` and the
live view follow from the list. /tf and the URDF are not here: their contents depend on who
writes them (the links the node or the bag shows, the trackers a bag holds).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..core.skeleton import Skeleton
from ..core.types import BodyPoses
from . import cdr
from .output import FOOT_NAMES, HELD, foot_points, joint_angles, joint_state_names, published_precision
from .topics import CONTACTS_TOPIC, JOINT_STATES_TOPIC, STATUS_TOPIC


@dataclass(frozen=True)
class PoseBatch:
    """Poses to encode, with what every output needs to say about them."""

    poses: BodyPoses
    skeleton: Skeleton
    fixed_frame: str
    stamps: np.ndarray  # seconds, one a pose
    angles: np.ndarray  # the poses' joint_angles, computed once (the URDF's link TF needs them too)
    held_message: str = HELD  # an invalid pose's status message
    valid_message: str = ""  # a valid one's (live: which estimator made a pose over budget)

    @classmethod
    def of(
        cls,
        poses: BodyPoses,
        skeleton: Skeleton,
        fixed_frame: str,
        stamps=None,
        angles: np.ndarray | None = None,
        held_message: str = HELD,
        valid_message: str = "",
    ) -> PoseBatch:
        return cls(
            poses,
            skeleton,
            fixed_frame,
            np.asarray(poses.stamps if stamps is None else stamps, dtype=np.float64),
            joint_angles(poses.local_quats) if angles is None else angles,
            held_message,
            valid_message,
        )


@dataclass(frozen=True)
class PoseOutput:
    topic: str  # as a bag names it; the node publishes it under its namespace ("/joint_states" -> "joint_states")
    type_name: str  # "sensor_msgs/msg/JointState": the node's publisher and the bag's connection type
    encode: Callable[[PoseBatch], list[bytes]]  # one CDR message a pose


def joint_states(batch: PoseBatch) -> list[bytes]:
    return cdr.joint_state_messages(batch.stamps, joint_state_names(), published_precision(batch.angles))


def foot_contacts(batch: PoseBatch) -> list[bytes]:
    poses = batch.poses
    points = published_precision(foot_points(poses.local_quats, poses.roots, batch.skeleton))
    return cdr.foot_contact_messages(
        batch.stamps, batch.fixed_frame, list(FOOT_NAMES), poses.contact, poses.contact_probability, points
    )


def estimate_status(batch: PoseBatch) -> list[bytes]:
    return cdr.status_messages(
        batch.stamps, batch.fixed_frame, batch.poses.valid, batch.held_message, batch.valid_message
    )


POSE_OUTPUTS: list[PoseOutput] = [
    PoseOutput(JOINT_STATES_TOPIC, "sensor_msgs/msg/JointState", joint_states),
    PoseOutput(CONTACTS_TOPIC, "sparse_body/msg/FootContacts", foot_contacts),
    PoseOutput(STATUS_TOPIC, "sparse_body/msg/EstimateStatus", estimate_status),
]


def pose_messages(batch: PoseBatch, topics=None) -> dict[str, list[bytes]]:
    """Every output's messages (or those of `topics`), by topic."""
    return {o.topic: o.encode(batch) for o in POSE_OUTPUTS if topics is None or o.topic in topics}
