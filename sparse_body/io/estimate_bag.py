"""The estimate bag: each pose output's message (io/pose_outputs.py: JointState,
FootContacts, EstimateStatus) and /tf per pose, written a chunk of poses at a time, so a
recording of any length is written in bounded memory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

from ..core.sensors import SensorConfig
from ..core.skeleton import Skeleton
from ..core.types import BodyPose, BodyPoses, TrackerStream
from . import cdr
from .bagio import TF_TYPE, bag_writer, log_times, typestore
from .output import (
    TransformTable,
    axis_link_table,
    body_table,
    joint_angles,
    tracker_sites,
    tracker_table,
)
from .pose_outputs import POSE_OUTPUTS, PoseBatch, pose_messages
from .topics import (
    DESCRIPTION_TOPIC,
    ESTIMATE_TOPICS,
    ROBOT_DESCRIPTION_TOPIC,
    ROBOT_JOINT_STATES_TOPIC,
    ROBOT_PREFIX,
    TF_TOPIC,
)
from .urdf import body_urdf

# robot_state_publisher's robot_description: kept for late subscribers, so `ros2 bag play`
# offers it as transient local and RViz gets it whenever it starts
LATCHED = Qos(
    QosHistory.KEEP_LAST,
    1,
    QosReliability.RELIABLE,
    QosDurability.TRANSIENT_LOCAL,
    QosTime(0, 0),
    QosTime(0, 0),
    QosLiveliness.AUTOMATIC,
    QosTime(0, 0),
    False,
)


def topic_types() -> dict[str, str]:
    """The message type of each topic an estimate bag writes a message a pose on: the pose
    outputs' (io/pose_outputs.py), then /tf."""
    return {**{o.topic: o.type_name for o in POSE_OUTPUTS}, TF_TOPIC: TF_TYPE}


def check_topics(topics: tuple[str, ...]) -> None:
    """ValueError naming the choices for topics an estimate bag cannot hold."""
    known = (*topic_types(), DESCRIPTION_TOPIC)
    unknown = sorted(set(topics) - set(known))
    if unknown or not topics:
        raise ValueError(f"topics {', '.join(unknown) or '(none)'}: choose from {', '.join(known)}")


class EstimateBagWriter:
    """Per pose: one JointState, one FootContacts, one EstimateStatus and one /tf message;
    once, first: the body's URDF on /robot_description (each only where `topics` has it). So
    that a viewer draws the bag as it is (Foxglove's 3D panel, or RViz with `ros2 bag play`),
    /tf holds every link of that URDF that has a shape (the body's) and, with `sensors` and
    each chunk's tracker frames, the trackers beside the body; with `axis_links`, the URDF's
    massless links inside each joint as well, which robot_state_publisher otherwise computes
    from /joint_states (they were 60 % of a bag: 49 against 35 MB for ten minutes). Each
    chunk's messages are encoded at once (io/cdr.py)."""

    def __init__(
        self,
        writer,
        skeleton: Skeleton,
        fixed_frame: str = "world",
        prefix: str = "",
        sensors: SensorConfig | None = None,
        topics: tuple[str, ...] = ESTIMATE_TOPICS,
        axis_links: bool = False,
        robot: tuple[str, str] | None = None,
    ) -> None:
        check_topics(topics)
        self.writer, self.skeleton, self.fixed_frame, self.prefix = writer, skeleton, fixed_frame, prefix
        self.sensors, self.topics, self.axis_links = sensors, tuple(topics), axis_links
        self.store = typestore()
        self.connections = {
            topic: writer.add_connection(topic, kind, typestore=self.store)
            for topic, kind in topic_types().items()
            if topic in topics
        }
        self._last_ns = -1  # the last receive time written: they only grow (see write)
        self._described = DESCRIPTION_TOPIC not in topics  # the URDF goes before the first pose
        self.robot = None
        self._robot_urdf: str | None = None
        if robot is not None:  # (mapping YAML, URDF): the robot's joints beside the body's
            from ..robot.limits import limiter_for
            from ..robot.retarget import load_retarget, robot_urdf_text
            from .robot_links import RobotLinks

            self.robot = load_retarget(robot[0], robot[1], skeleton)
            self.robot_links = RobotLinks(self.robot, fixed_frame, ROBOT_PREFIX)
            self.limiter = limiter_for(self.robot)  # the commands as a controller can follow them
            self.robot_connection = writer.add_connection(
                ROBOT_JOINT_STATES_TOPIC, "sensor_msgs/msg/JointState", typestore=self.store
            )
            self._robot_urdf = robot_urdf_text(robot[0], robot[1])  # on ROBOT_DESCRIPTION_TOPIC, first

    def write(self, poses: BodyPoses, trackers: TrackerStream | None = None) -> None:
        """The next poses, and (with sensors) the tracker frames they were made from."""
        if trackers is not None and len(trackers) != len(poses):
            raise ValueError(f"{len(poses)} poses but {len(trackers)} tracker frames")
        if not len(poses):
            return
        angles = joint_angles(poses.local_quats)
        robot, robot_base = self._robot_poses(poses) if self.robot is not None else (None, None)
        batch = PoseBatch.of(poses, self.skeleton, self.fixed_frame, angles=angles)
        per_frame = pose_messages(batch, self.topics)
        if TF_TOPIC in self.topics:
            shown = (self.sensors, trackers) if self.sensors is not None and trackers is not None else None
            per_frame[TF_TOPIC] = self._tf_messages(poses, angles if self.axis_links else None, shown, robot_base)
        log_ns = log_times(poses.stamps, self._last_ns)
        self._last_ns = log_ns[-1]
        if not self._described:
            c_urdf = self.writer.add_connection(
                DESCRIPTION_TOPIC, "std_msgs/msg/String", typestore=self.store, offered_qos_profiles=[LATCHED]
            )
            urdf = self.store.types["std_msgs/msg/String"](data=body_urdf(self.skeleton))
            self.writer.write(c_urdf, log_ns[0], self.store.serialize_cdr(urdf, "std_msgs/msg/String"))
            self._described = True
        if self.robot is not None and self._robot_urdf is not None:
            c_robot = self.writer.add_connection(
                ROBOT_DESCRIPTION_TOPIC, "std_msgs/msg/String", typestore=self.store, offered_qos_profiles=[LATCHED]
            )
            urdf = self.store.types["std_msgs/msg/String"](data=self._robot_urdf)
            self.writer.write(c_robot, log_ns[0], self.store.serialize_cdr(urdf, "std_msgs/msg/String"))
            self._robot_urdf = None
        written = [(connection, per_frame[topic]) for topic, connection in self.connections.items()]
        if robot is not None:
            written.append((self.robot_connection, robot))
        for i, ns in enumerate(log_ns):
            for connection, messages in written:
                self.writer.write(connection, ns, messages[i])

    def _robot_poses(self, poses: BodyPoses) -> tuple[list[bytes], TransformTable]:
        """The robot's JointState for each pose, retargeted in order (robot/retarget.py; an
        invalid pose holds the robot's last angles), and its links on /tf (fixed frame ->
        robot/<base link>, which a JointState cannot carry, and every link under it)."""
        assert self.robot is not None
        robot = [
            self.robot.step(
                BodyPose(
                    float(poses.stamps[i]),
                    poses.local_quats[i],
                    poses.roots[i],
                    poses.contact_probability[i],
                    poses.contact[i],
                    bool(poses.valid[i]),
                )
            )
            for i in range(len(poses))
        ]
        commands = [self.limiter(r.stamp, r.positions, r.fresh) for r in robot]
        messages = cdr.joint_state_messages(
            poses.stamps, self.robot.names, np.array([c for c, _ in commands]), np.array([v for _, v in commands])
        )
        bases = np.array([np.concatenate([r.base_position, r.base_quat]) for r in robot])
        return messages, self.robot_links.link_table(np.array([c for c, _ in commands]), bases)

    def _tf_messages(
        self,
        poses: BodyPoses,
        angles,
        trackers: tuple[SensorConfig, TrackerStream] | None,
        robot_base: TransformTable | None = None,
    ) -> list[bytes]:
        """One /tf message a pose: the body's links (and with `angles`, the URDF's massless
        links), and the trackers it was made from."""
        body = body_table(poses.local_quats, poses.roots, self.skeleton, self.fixed_frame, self.prefix)
        if angles is not None:
            body = body + axis_link_table(angles, self.skeleton, self.prefix)
        if robot_base is not None:
            body = body + robot_base
        tf: list[bytes] = [b""] * len(poses)
        shown = tracker_sites(*trackers) if trackers is not None else np.zeros((len(poses), 0), bool)
        for pattern, which in cdr.same_rows(shown):  # frames with the same trackers
            table = TransformTable(body.parents, body.children, body.values[which])
            if trackers is not None:
                table = table + tracker_table(*trackers, which, tuple(np.flatnonzero(pattern)))
            messages = cdr.tf_messages(poses.stamps[which], table.parents, table.children, table.values)
            for i, data in zip(which, messages, strict=True):
                tf[i] = data
        return tf


def write_estimate_bag(
    path: Path,
    poses: list[BodyPose],
    skeleton: Skeleton,
    fixed_frame: str = "world",
    prefix: str = "",
    overwrite: bool = False,
    inputs: tuple[Path, ...] = (),
    trackers: tuple[SensorConfig, TrackerStream] | None = None,
    made_with: str = "",
    topics: tuple[str, ...] = ESTIMATE_TOPICS,
    compression: str = "zstd",
    axis_links: bool = False,
) -> None:
    """A whole recording's poses as an estimate bag (EstimateBagWriter), with `trackers` (the
    sensor configuration and the input frames, one per pose) beside the body."""
    check_topics(topics)
    if trackers is not None and len(trackers[1]) != len(poses):
        raise ValueError(f"{len(poses)} poses but {len(trackers[1])} tracker frames")
    with bag_writer(path, overwrite, inputs, made_with, compression) as writer:
        out = EstimateBagWriter(
            writer, skeleton, fixed_frame, prefix, trackers[0] if trackers else None, topics, axis_links
        )
        out.write(BodyPoses.of(poses), trackers[1] if trackers else None)
