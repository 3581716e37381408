"""Core types <-> rclpy messages."""

from __future__ import annotations

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, TransformStamped
from sensor_msgs.msg import JointState

from sparse_body.msg import EstimateStatus, FootContact, FootContacts

from ..core.skeleton import Skeleton
from ..core.types import BodyPose
from ..io.output import (
    FOOT_NAMES,
    HELD,
    body_transforms,
    contact_points,
    joint_state_names,
    joint_state_positions,
    stamp_parts,
)

JOINT_NAMES = joint_state_names()


def to_time(seconds: float) -> Time:
    sec, nanosec = stamp_parts(seconds)
    return Time(sec=sec, nanosec=nanosec)


def to_seconds(stamp: Time) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def joint_state(pose: BodyPose, stamp: Time) -> JointState:
    msg = JointState()
    msg.header.stamp = stamp
    msg.name = JOINT_NAMES
    msg.position = joint_state_positions(pose).tolist()
    return msg


def foot_contacts(pose: BodyPose, skeleton: Skeleton, stamp: Time, frame_id: str) -> FootContacts:
    msg = FootContacts()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    points = contact_points(pose, skeleton)
    for k, name in enumerate(FOOT_NAMES):
        x, y, z = map(float, points[k])
        msg.contacts.append(
            FootContact(
                name=name,
                in_contact=bool(pose.contact[k]),
                probability=float(pose.contact_probability[k]),
                contact_point=Point(x=x, y=y, z=z),
            )
        )
    return msg


def estimate_status(pose: BodyPose, stamp: Time, frame_id: str, reason: str = "") -> EstimateStatus:
    msg = EstimateStatus(valid=bool(pose.valid), message="" if pose.valid else (reason or HELD))
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    return msg


def transforms(
    pose: BodyPose, skeleton: Skeleton, stamp: Time, fixed_frame: str, prefix: str, links: bool
) -> list[TransformStamped]:
    out = []
    for t in body_transforms(pose, skeleton, fixed_frame, prefix, links):
        msg = TransformStamped()
        msg.header.stamp, msg.header.frame_id, msg.child_frame_id = stamp, t.parent, t.child
        tr, q = msg.transform.translation, msg.transform.rotation
        tr.x, tr.y, tr.z = map(float, t.translation)
        q.x, q.y, q.z, q.w = map(float, t.rotation)
        out.append(msg)
    return out
