"""Bags that draw themselves (issue 34): a processed bag carries the body's URDF, every link
of it on /tf, and the trackers, so Foxglove's 3D panel or RViz shows the body as it moves."""

import xml.etree.ElementTree as ET

import numpy as np
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader

from sparse_body.apps.offline import make_bag, process_bag
from sparse_body.core.rotations import quat_to_matrix
from sparse_body.core.sensors import load_sensor_config
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.io.bagio import DESCRIPTION_TOPIC, JOINT_STATES_TOPIC, TF_TOPIC, read_topic
from sparse_body.io.output import joint_state_names


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _tf_poses(message, fixed: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every frame's (rotation, position) in the fixed frame by walking up its parents, as a
    viewer's TF buffer does; a frame whose chain does not reach the fixed frame is absent."""
    parent = {t.child_frame_id: t for t in message.transforms}
    poses = {fixed: (np.eye(3), np.zeros(3))}

    def pose(frame: str, depth: int = 0):
        if frame in poses:
            return poses[frame]
        t = parent.get(frame)
        if t is None or depth > 200:
            return None
        up = pose(t.header.frame_id, depth + 1)
        if up is None:
            return None
        q, v = t.transform.rotation, t.transform.translation
        rot = quat_to_matrix(np.array([q.x, q.y, q.z, q.w]))
        poses[frame] = (up[0] @ rot, up[0] @ np.array([v.x, v.y, v.z]) + up[1])
        return poses[frame]

    for frame in parent:
        pose(frame)
    return poses


def test_a_processed_bag_holds_the_urdf_its_links_on_tf_and_the_trackers(tmp_path):
    motion = synthetic_walk(1.5)
    config = load_sensor_config("six_point")
    make_bag(motion, config, tmp_path / "in")
    process_bag(tmp_path / "in", tmp_path / "out", "ik", config, motion.skeleton, progress=False)

    with Reader(tmp_path / "out") as reader:
        (description,) = [c for c in reader.connections if c.topic == DESCRIPTION_TOPIC]
        # offered as transient local: `ros2 bag play` latches it for a late RViz
        assert [q.durability for q in description.ext.offered_qos_profiles] == [QosDurability.TRANSIENT_LOCAL]
        first = next(iter(reader.messages()))[0].topic
    assert first == DESCRIPTION_TOPIC  # before any /tf, as robot_state_publisher starts
    (urdf,) = read_topic(tmp_path / "out", DESCRIPTION_TOPIC)
    robot = ET.fromstring(urdf.data)
    joints = {j.get("name"): j for j in robot.iter("joint")}
    links = [link.get("name") for link in robot.iter("link")]
    assert sorted(joints) == sorted(joint_state_names())

    states = read_topic(tmp_path / "out", JOINT_STATES_TOPIC)
    tfs = read_topic(tmp_path / "out", TF_TOPIC)
    assert len(tfs) == len(states) == len(motion)
    for k in (0, len(tfs) // 2, len(tfs) - 1):
        poses = _tf_poses(tfs[k], config.fixed_frame)
        missing = [name for name in links if name not in poses]
        assert not missing, f"frame {k}: links without a TF chain to {config.fixed_frame}: {missing[:5]}"
        assert {s.frame_id for s in config.sites} <= set(poses)  # the trackers beside the body
        # robot_state_publisher's view (URDF joints driven by the JointState) equals the TF
        angle = dict(zip(states[k].name, states[k].position, strict=True))
        for name, joint in joints.items():
            parent, child = joint.find("parent").get("link"), joint.find("child").get("link")
            xyz = np.array(joint.find("origin").get("xyz").split(), float)
            axis = np.array(joint.find("axis").get("xyz").split(), float)
            rot, pos = poses[parent]
            want_rot = rot @ _axis_rotation(axis, angle[name])
            np.testing.assert_allclose(poses[child][0], want_rot, atol=1e-6, err_msg=name)
            np.testing.assert_allclose(poses[child][1], pos + rot @ xyz, atol=1e-6, err_msg=name)
