"""Tracker bags in, estimate bags out, without ROS (real rosbag2 MCAP files via rosbags)."""
import numpy as np
import pytest

from sparse_body.bagio import (BagError, CONTACTS_TOPIC, JOINT_STATES_TOPIC, STATUS_TOPIC, TF_TOPIC, read_topic,
                               read_tracker_stream, write_tracker_bag)
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import synthesize_trackers
from sparse_body.offline import make_bag, process_bag
from sparse_body.output import joint_state_names


def test_make_bag_round_trips_the_trackers(tmp_path):
    motion = synthetic_walk(2.0)
    config = load_sensor_config("six_point")
    assert make_bag(motion, config, tmp_path / "trackers") == len(motion)
    stream = read_tracker_stream(tmp_path / "trackers", config)
    truth = synthesize_trackers(motion, config)
    assert len(stream) == len(motion) and stream.valid.all()
    np.testing.assert_allclose(stream.positions, truth.positions, atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(stream.orientations * truth.orientations, -1)), 1.0, atol=1e-9)
    np.testing.assert_allclose(stream.times - stream.times[0], np.arange(len(motion)) / 60.0, atol=1e-6)


def test_process_writes_one_estimate_per_frame(tmp_path):
    motion = synthetic_walk(2.0)
    config = load_sensor_config("six_point")
    make_bag(motion, config, tmp_path / "in")
    poses = process_bag(tmp_path / "in", tmp_path / "out", "ik", config, motion.skeleton, progress=False)
    states = read_topic(tmp_path / "out", JOINT_STATES_TOPIC)
    assert len(states) == len(poses) == len(motion)
    assert list(states[0].name) == joint_state_names() and len(states[0].name) == 63
    assert all(np.all(np.isfinite(s.position)) for s in states)
    assert len(read_topic(tmp_path / "out", CONTACTS_TOPIC)) == len(motion)
    assert all(s.valid for s in read_topic(tmp_path / "out", STATUS_TOPIC))
    tfs = read_topic(tmp_path / "out", TF_TOPIC)
    assert len(tfs) == len(motion) and len(tfs[0].transforms) == 22
    # The IK baseline puts the wrists where the controllers say.
    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.rotations import quat_to_matrix
    local = quat_to_matrix(np.stack([p.local_quats for p in poses]))
    _, pos = forward_kinematics(local, np.stack([p.root_position for p in poses]), motion.skeleton.offsets)
    err = np.linalg.norm(pos[:, J["left_wrist"]] - motion.positions[:, J["left_wrist"]], axis=-1)
    assert err.mean() < 0.01


def test_bad_tracker_samples_keep_one_finite_output_per_frame(tmp_path):
    motion = synthetic_walk(3.0)
    config = load_sensor_config("four_point")
    stream = synthesize_trackers(motion, config)
    stream.positions[20:25, 0] = np.nan                  # NaN headset poses
    stream.orientations[30, 1] = 0.0                     # a zero quaternion
    stream.valid[40:80, 3] = False                       # the pelvis tracker stops for 2/3 s
    stream.valid[90, :] = False                          # a frame with no tracker at all
    stream.valid[140:160, [0, 3]] = False                # headset and pelvis both gone
    stream.times[100], stream.times[101] = stream.times[101], stream.times[100]   # out of order
    stream.times[120:] -= 2.0                            # the clock jumps back (a bag loop)
    write_tracker_bag(tmp_path / "bad", stream, config)
    back = read_tracker_stream(tmp_path / "bad", config)
    # Frame 90 carried no transform at all, so it is no input frame; every other one is.
    assert len(back) == len(motion) - 1
    poses = process_bag(tmp_path / "bad", tmp_path / "out", "ik", config, motion.skeleton, progress=False)
    assert len(poses) == len(back)
    assert all(p.is_finite() for p in poses)
    valid = np.array([p.valid for p in poses])
    pelvis = back.sites.index("pelvis")
    assert not back.valid[50:78, pelvis].any()   # stale after 0.1 s
    assert valid[50:78].all()                    # ...and the root then hangs from the headset
    assert not valid[145:158].any()              # no headset, no pelvis: held and marked invalid
    assert valid[:20].all() and valid[-20:].all()
    statuses = read_topic(tmp_path / "out", STATUS_TOPIC)
    assert [s.valid for s in statuses] == list(valid)
    assert all(np.all(np.isfinite(s.position)) for s in read_topic(tmp_path / "out", JOINT_STATES_TOPIC))


def test_unreadable_bags_name_the_path(tmp_path):
    config = load_sensor_config("three_point")
    with pytest.raises(BagError, match="no such bag"):
        read_tracker_stream(tmp_path / "absent", config)
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "metadata.yaml").write_text("not: a bag\n")
    with pytest.raises(BagError, match=r"junk: cannot be read as a rosbag2"):
        read_tracker_stream(tmp_path / "junk", config)
    make_bag(synthetic_walk(0.5), load_sensor_config("six_point").subset(["pelvis"]), tmp_path / "other")
    with pytest.raises(BagError, match="no transforms of the tracker frames"):
        read_tracker_stream(tmp_path / "other", config)
