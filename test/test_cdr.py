"""The output bag's messages, encoded for a whole recording at once (io/cdr.py), are byte for
byte what rosbags' serialize_cdr makes of the same messages built one by one."""

import contextlib
import functools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from rosbags.rosbag2 import Reader

from sparse_body.apps.offline import make_bag, process_bag
from sparse_body.core.sensors import load_sensor_config
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.io import cdr
from sparse_body.io.bagio import (
    CONTACTS_TOPIC,
    JOINT_STATES_TOPIC,
    STATUS_TOPIC,
    TF_TOPIC,
    _transform_msg,
    read_tracker_stream,
    typestore,
)
from sparse_body.io.output import (
    FOOT_NAMES,
    HELD,
    axis_link_table,
    body_table,
    foot_points,
    joint_angles,
    joint_state_names,
    published_precision,
    stamp_parts,
    tracker_sites,
    tracker_table,
)

STORE = typestore()
T = STORE.types


def body_transforms(pose, skeleton, fixed_frame):
    """One pose's transforms, as a message built one by one holds them."""
    return body_table(pose.local_quats[None], pose.root_position[None], skeleton, fixed_frame).frame(0)


def _stamp(seconds):
    sec, nanosec = stamp_parts(seconds)
    return T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _header(seconds, frame_id):
    return T["std_msgs/msg/Header"](stamp=_stamp(seconds), frame_id=frame_id)


def _tf(seconds, transforms):
    """The reference: rosbags' encoder of the messages the tracker bag writer builds."""
    msgs = [_transform_msg(STORE, seconds, t.parent, t.child, t.translation, t.rotation) for t in transforms]
    return STORE.serialize_cdr(T["tf2_msgs/msg/TFMessage"](transforms=msgs), "tf2_msgs/msg/TFMessage")


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.one_of(st.floats(0, 4e9), st.integers(0, 4_000_000_000).map(lambda s: s + 0.9999999996)),
        min_size=1,
        max_size=5,
    )
)
def test_stamps_split_as_one_by_one_including_the_carry_into_seconds(seconds):
    sec, nanosec = cdr.stamp_parts(np.array(seconds))
    assert list(zip(sec.tolist(), nanosec.tolist(), strict=True)) == [stamp_parts(s) for s in seconds]


def test_a_processed_bag_holds_exactly_the_messages_built_one_by_one(tmp_path):
    motion = synthetic_walk(3.0)
    config = load_sensor_config("six_point")
    make_bag(motion, config, tmp_path / "in", start=1_700_000_000.123456789)
    poses = process_bag(
        tmp_path / "in", tmp_path / "out", "ik", config, motion.skeleton, progress=False, keep_poses=True
    ).poses
    stream = read_tracker_stream(tmp_path / "in", config)
    assert any(p.contact.any() for p in poses) and any(not p.contact.all() for p in poses)
    poses[5] = poses[5].held(poses[5].stamp)  # an invalid estimate in the bag too
    stream.valid[7, 1] = False  # and a frame without its left hand
    from sparse_body.io.estimate_bag import write_estimate_bag

    write_estimate_bag(tmp_path / "out2", poses, motion.skeleton, "world", trackers=(config, stream), axis_links=True)
    with Reader(tmp_path / "out2") as reader:
        raw = {}
        for conn, _, data in reader.messages():
            raw.setdefault(conn.topic, []).append(bytes(data))
    write_estimate_bag(tmp_path / "out3", poses, motion.skeleton, "world", trackers=(config, stream))
    with Reader(tmp_path / "out3") as reader:  # the default: no massless links
        default_tf = [bytes(data) for conn, _, data in reader.messages() if conn.topic == TF_TOPIC]
    shown = tracker_sites(config, stream)
    for i, pose in enumerate(poses):
        js = T["sensor_msgs/msg/JointState"](
            header=_header(pose.stamp, ""),
            name=joint_state_names(),
            position=published_precision(joint_angles(pose.local_quats)),  # the published numbers
            velocity=np.zeros(0),
            effort=np.zeros(0),
        )
        assert raw[JOINT_STATES_TOPIC][i] == STORE.serialize_cdr(js, "sensor_msgs/msg/JointState"), i
        points = published_precision(foot_points(pose.local_quats, pose.root_position, motion.skeleton))
        contacts = T["sparse_body/msg/FootContacts"](
            header=_header(pose.stamp, "world"),
            contacts=[
                T["sparse_body/msg/FootContact"](
                    name=n,
                    in_contact=bool(pose.contact[k]),
                    probability=float(pose.contact_probability[k]),
                    contact_point=T["geometry_msgs/msg/Point"](*map(float, points[k])),
                )
                for k, n in enumerate(FOOT_NAMES)
            ],
        )
        assert raw[CONTACTS_TOPIC][i] == STORE.serialize_cdr(contacts, "sparse_body/msg/FootContacts"), i
        status = T["sparse_body/msg/EstimateStatus"](
            header=_header(pose.stamp, "world"), valid=bool(pose.valid), message="" if pose.valid else HELD
        )
        assert raw[STATUS_TOPIC][i] == STORE.serialize_cdr(status, "sparse_body/msg/EstimateStatus"), i
        links = axis_link_table(joint_angles(pose.local_quats)[None], motion.skeleton).frame(0)
        trackers = tracker_table(config, stream, np.array([i]), tuple(np.flatnonzero(shown[i]))).frame(0)
        transforms = body_transforms(pose, motion.skeleton, "world") + links + trackers
        assert raw[TF_TOPIC][i] == _tf(pose.stamp, transforms), i
        assert default_tf[i] == _tf(pose.stamp, body_transforms(pose, motion.skeleton, "world") + trackers), i
    assert len(raw[TF_TOPIC]) == len(poses) and b"left_controller" not in raw[TF_TOPIC][7]


_names = st.text(alphabet=st.characters(codec="utf-8", exclude_characters="\x00"), max_size=12)


@settings(max_examples=150, deadline=None)
@given(
    st.lists(
        st.tuples(
            _names,
            _names,
            st.integers(-(2**31), 2**31 - 1),
            st.integers(0, 999_999_999),
            st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=7, max_size=7),
        ),
        max_size=6,
    ),
    st.booleans(),
)
def test_read_tf_gives_what_rosbags_decodes_either_byte_order(transforms, little_endian):
    """read_tf (the live /tf reader's and the bag reader's) against rosbags' deserializer."""
    msg = T["tf2_msgs/msg/TFMessage"](
        transforms=[
            T["geometry_msgs/msg/TransformStamped"](
                header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec, nanosec), frame_id=parent),
                child_frame_id=child,
                transform=T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](*values[:3]),
                    rotation=T["geometry_msgs/msg/Quaternion"](*values[3:]),
                ),
            )
            for parent, child, sec, nanosec, values in transforms
        ]
    )
    data = bytes(STORE.serialize_cdr(msg, "tf2_msgs/msg/TFMessage", little_endian=little_endian))
    rows = cdr.read_tf(data)
    assert len(rows) == len(transforms)
    for (parent, child, stamp, values), (p, c, sec, nanosec, v) in zip(rows, transforms, strict=True):
        assert (parent, child, stamp) == (p, c, sec + nanosec * 1e-9)
        assert np.array_equal(values, v, equal_nan=True)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400), st.integers(0, 400))
def test_read_tf_refuses_bytes_that_are_no_tfmessage_with_its_own_error(junk, cut):
    """Whatever the network sends: MalformedMessage or rows, never another exception."""
    real = _real_tf()
    for data in (junk, b"\x00\x01\x00\x00" + junk, real[:cut], real[:cut] + junk):
        with contextlib.suppress(cdr.MalformedMessage):
            cdr.read_tf(data)


@functools.cache
def _real_tf() -> bytes:
    from sparse_body.core.types import BodyPose

    motion = synthetic_walk(0.1)
    pose = BodyPose(0.0, motion.local_quats[0], motion.root_positions[0], valid=True)
    return bytes(_tf(1.5, body_transforms(pose, motion.skeleton, "world")))


def test_the_bag_s_topics_are_the_pose_outputs_then_tf_and_the_description():
    """`--topics` and the bag's defaults name what io/pose_outputs.py lists: they cannot drift."""
    from sparse_body.io.pose_outputs import POSE_OUTPUTS
    from sparse_body.io.topics import DESCRIPTION_TOPIC, ESTIMATE_TOPICS, TF_TOPIC

    assert (*(o.topic for o in POSE_OUTPUTS), TF_TOPIC, DESCRIPTION_TOPIC) == ESTIMATE_TOPICS
