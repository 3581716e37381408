import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sparse_body.core.sensors import SensorConfigError, load_sensor_config, parse_sensor_config
from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import LOBSTR_NOISE, TrackerNoise, synthesize_trackers


@pytest.mark.parametrize(
    "name,sites",
    [
        ("three_point", ("head", "left_hand", "right_hand")),
        ("four_point", ("head", "left_hand", "right_hand", "pelvis")),
        ("six_point", ("head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")),
    ],
)
def test_shipped_configurations(name, sites):
    config = load_sensor_config(name)
    assert config.name == name and config.site_names == sites
    assert all(s.measures == "pose" for s in config.sites)
    assert config.site("head").frame_id == "hmd"


def test_unknown_site_is_named_with_the_file(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text("sites:\n  head: {frame: hmd}\n  left_knee: {frame: k}\n")
    with pytest.raises(SensorConfigError, match=r"mine\.yaml: unknown body site 'left_knee'; sites are head, "):
        load_sensor_config(path)
    path.write_text("sites:\n  head: {offset: {rotation: [0, 0, 0, 2]}}\n")
    with pytest.raises(SensorConfigError, match="unit quaternion"):
        load_sensor_config(path)
    path.write_text("sites:\n  head: {measures: velocity}\n")
    with pytest.raises(SensorConfigError, match="measures must be one of pose, orientation, position"):
        load_sensor_config(path)
    path.write_text("sites: [head\n")
    with pytest.raises(SensorConfigError, match="not valid YAML"):
        load_sensor_config(path)
    with pytest.raises(SensorConfigError, match="no sensor configuration 'seven_point'; shipped ones are four_point"):
        load_sensor_config("seven_point")
    path.write_text("sites:\n  head: {offset: [1, 2, 3]}\n")  # was an AttributeError
    with pytest.raises(SensorConfigError, match=r"mine\.yaml: site 'head': offset must be a mapping"):
        load_sensor_config(path)
    path.write_text("sites:\n  head: {true: 1}\n")  # found by make fuzz: a TypeError
    with pytest.raises(SensorConfigError, match="unknown key.s. True"):
        load_sensor_config(path)
    path.write_bytes(b"sites:\n  head: {frame: \xff\xfe}\n")  # not UTF-8: the file is named
    with pytest.raises(SensorConfigError, match=r"mine\.yaml: not UTF-8 text"):
        load_sensor_config(path)


def test_any_subset_can_be_written():
    config = parse_sensor_config({"name": "hip_hands", "sites": {"pelvis": {}, "left_hand": {}, "right_hand": {}}})
    assert config.site_names == ("pelvis", "left_hand", "right_hand")
    assert load_sensor_config("six_point").subset(["left_foot"]).site_names == ("left_foot",)


def test_clean_trackers_follow_joints_through_their_mounting():
    motion = synthetic_walk(2.0)
    config = load_sensor_config("six_point")
    stream = synthesize_trackers(motion, config)
    assert stream.positions.shape == (len(motion), 6, 3) and stream.valid.all()
    for s, site in enumerate(config.sites):
        j = site.joint_index
        expected = motion.positions[:, j] + np.einsum(
            "tab,b->ta", motion.global_rotations[:, j], site.offset_translation
        )
        np.testing.assert_allclose(stream.positions[:, s], expected, atol=1e-9)
        # Undoing the mounting recovers the joint.
        pos, rot = site.joint_pose(stream.positions[10, s], stream.orientations[10, s])
        np.testing.assert_allclose(pos, motion.positions[10, j], atol=1e-9)
        np.testing.assert_allclose(rot, motion.global_rotations[10, j], atol=1e-9)


def test_lobstr_noise_has_the_papers_scale():
    motion = synthetic_walk(10.0)
    config = load_sensor_config("four_point")
    clean = synthesize_trackers(motion, config)
    noisy = synthesize_trackers(motion, config, LOBSTR_NOISE, seed=3)
    diff = noisy.positions - clean.positions
    assert np.std(diff) == pytest.approx(0.01, rel=0.1)
    angle = (
        Rotation.from_quat(noisy.orientations.reshape(-1, 4)).inv()
        * Rotation.from_quat(clean.orientations.reshape(-1, 4))
    ).magnitude()
    assert np.degrees(angle).max() <= 1.5 + 1e-9 and np.degrees(angle).mean() > 0.5


def test_drops_occlusion_and_orientation_only():
    motion = synthetic_walk(10.0)
    config = parse_sensor_config({"sites": {"head": {}, "left_foot": {}, "right_hand": {"measures": "orientation"}}})
    noise = TrackerNoise(drop_probability=0.1, occlusion_probability=0.02, occlusion_frames=20)
    stream = synthesize_trackers(motion, config, noise, seed=1)
    dropped = ~stream.valid
    assert 0.05 < dropped.mean() < 0.15
    assert np.isnan(stream.positions[dropped]).all()
    # Occluded feet read origin and identity while claiming to be valid.
    foot = stream.sites.index("left_foot")
    at_origin = stream.valid[:, foot] & np.all(stream.positions[:, foot] == 0.0, axis=-1)
    assert at_origin.sum() >= 20
    np.testing.assert_array_equal(stream.orientations[at_origin, foot], [[0, 0, 0, 1]] * int(at_origin.sum()))
    assert not np.all(stream.positions[:, stream.sites.index("head")] == 0.0, axis=-1).any()
    hand = stream.sites.index("right_hand")
    assert (
        np.isnan(stream.positions[:, hand]).all()
        and np.isfinite(stream.orientations[stream.valid[:, hand], hand]).all()
    )
    bounded = synthesize_trackers(
        motion, config, TrackerNoise(occlusion_probability=0.05, occlusion_mode="bounded"), seed=2
    )
    err = np.linalg.norm(bounded.positions[:, foot] - motion.positions[:, J["left_ankle"]], axis=-1)
    assert err.max() <= motion.skeleton.leg_length() + 0.1 and err.max() > 0.1


@pytest.mark.parametrize("mode", ["lost", "frozen"])
def test_hands_out_of_view_for_a_share_of_frames_lost_or_frozen_and_nothing_else_moves(mode):
    from sparse_body.data.synthetic import synthetic_walk
    from sparse_body.data.virtual_trackers import VR_NOISE, synthesize_trackers

    motion = synthetic_walk(120.0)
    config = load_sensor_config("three_point")
    noise = VR_NOISE.losing_hands(20.0, mode)
    assert noise.lost_percent == pytest.approx(20.0)
    plain, losing = synthesize_trackers(motion, config, VR_NOISE, 3), synthesize_trackers(motion, config, noise, 3)
    assert plain.lost is None and losing.lost is not None
    head, hands = config.site_names.index("head"), [config.site_names.index(h) for h in ("left_hand", "right_hand")]
    assert not losing.lost[:, head].any()
    np.testing.assert_array_equal(losing.positions[:, head], plain.positions[:, head])  # drawn after the rest
    for s in hands:
        out = losing.lost[:, s]
        assert 0.12 < out.mean() < 0.28, out.mean()  # about 20 % of the frames
        edges = np.flatnonzero(np.diff(np.r_[0, out.astype(int), 0]))
        lengths = (edges[1::2] - edges[::2])[edges[1::2] < len(out)]  # the clip's end cuts its last one
        assert lengths.min() >= 0.2 * 60 - 1 and lengths.max() <= 2.0 * 60 + 1  # 0.2-2 s at a time
        np.testing.assert_array_equal(losing.positions[~out, s], plain.positions[~out, s])
        if mode == "lost":
            assert not losing.valid[out, s].any() and np.isnan(losing.positions[out, s]).all()
        else:  # valid, and the sample before the loss again
            assert losing.valid[out, s].all()
            for start, end in zip(edges[::2], edges[1::2], strict=True):
                if start > 0:
                    assert (losing.positions[start:end, s] == plain.positions[start - 1, s]).all()


def test_reflection_jumps_move_positions_a_few_centimetres_for_a_few_frames_and_nothing_else():
    from sparse_body.data.field_protocol import Protocol
    from sparse_body.data.virtual_trackers import VR_NOISE

    motion = synthetic_walk(120.0)
    config = load_sensor_config("six_point")
    noise = VR_NOISE.jumping(6.0)  # about six a minute on each tracker
    plain, jumping = synthesize_trackers(motion, config, VR_NOISE, 3), synthesize_trackers(motion, config, noise, 3)
    np.testing.assert_array_equal(jumping.orientations, plain.orientations)  # positions only, drawn last
    np.testing.assert_array_equal(jumping.valid, plain.valid)
    for s in range(len(config.sites)):
        moved = np.linalg.norm(jumping.positions[:, s] - plain.positions[:, s], axis=-1)
        out = moved > 0
        edges = np.flatnonzero(np.diff(np.r_[0, out.astype(int), 0]))
        lengths = edges[1::2] - edges[::2]
        assert 6 <= len(lengths) <= 24, len(lengths)  # about 12 in two minutes
        assert lengths.min() >= 2 and lengths.max() <= 8
        assert moved[out].min() >= 0.02 - 1e-12 and moved.max() <= 0.08 + 1e-12
    assert "6 position jumps a minute" in Protocol(noise=noise).label
    with pytest.raises(ValueError, match="jumps per minute must be from 0 to 600"):
        VR_NOISE.jumping(-1.0)


def test_imu_heading_drifts_about_the_vertical_at_a_steady_rate_and_pose_trackers_do_not():
    from sparse_body.data.virtual_trackers import NO_NOISE

    motion = synthetic_walk(60.0)
    config = load_sensor_config("four_point_foot_imus")
    plain = synthesize_trackers(motion, config, NO_NOISE, 1)
    drifting = synthesize_trackers(motion, config, NO_NOISE.drifting(5.0), 1)
    imus = [s for s, site in enumerate(config.sites) if not site.has_position]
    assert imus, "the configuration has orientation-only sensors"
    for s in range(len(config.sites)):
        if s not in imus:
            np.testing.assert_array_equal(drifting.orientations[:, s], plain.orientations[:, s])
            continue
        turn = Rotation.from_quat(drifting.orientations[:, s]) * Rotation.from_quat(plain.orientations[:, s]).inv()
        rotvec = turn.as_rotvec()
        assert np.allclose(rotvec[:, :2], 0, atol=1e-9)  # about the vertical only
        yaw = np.rad2deg(rotvec[:, 2])
        rate = np.polyfit(np.arange(len(yaw)) / motion.fps / 60, yaw, 1)[0]
        assert 0 < abs(rate) <= 5.0 and np.allclose(yaw, rate * np.arange(len(yaw)) / motion.fps / 60, atol=1e-6)
