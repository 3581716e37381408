"""The user's body from a T-pose, the tracker filter and the field protocol of `sparse-body eval`."""

import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sparse_body.core.body_shape import arm_length, arm_span, fit_skeleton, leg_length
from sparse_body.core.calibration import Calibration, CalibrationError
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.core.skeleton import Skeleton
from sparse_body.core.tracker_filter import NO_FILTER, FilterConfig, TrackerFilter
from sparse_body.core.types import TrackerFrame
from sparse_body.data.field_protocol import FIELD, FIELD_EXACT, LAB, Protocol, user_view
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import LOBSTR_NOISE, NO_NOISE
from sparse_body.evaluation import evaluate_motion


def _tpose_joints(skeleton: Skeleton) -> dict:
    rest = skeleton.rest_positions()
    rest[:, 2] -= rest[:, 2].min()
    sites = {
        "head": "head",
        "left_hand": "left_wrist",
        "right_hand": "right_wrist",
        "pelvis": "pelvis",
        "left_foot": "left_ankle",
        "right_foot": "right_ankle",
    }
    return {site: rest[J[joint]] for site, joint in sites.items()}


def test_fit_skeleton_recovers_arms_legs_and_torso_of_an_exact_tpose():
    person = Skeleton.canonical(1.68).offsets.copy()
    for side in ("left", "right"):
        person[J[f"{side}_elbow"]] *= 1.12  # long arms
        person[J[f"{side}_knee"]] *= 0.93  # short thighs
    person[J["spine3"]] *= 1.2
    person = Skeleton(person)
    fitted = fit_skeleton(_tpose_joints(person), person.height())
    assert abs(arm_span(fitted) - arm_span(person)) < 1e-6
    assert abs(leg_length(fitted) - leg_length(person)) < 0.001  # (the hip joints' drop is a prior)
    rest, truth = fitted.rest_positions(), person.rest_positions()
    for joint in ("head", "left_wrist", "right_ankle", "left_collar"):
        assert np.linalg.norm(rest[J[joint]] - truth[J[joint]]) < 0.005, joint
    # without pelvis and feet the torso-leg split is the canonical one, the sum still right
    three = fit_skeleton(
        {k: v for k, v in _tpose_joints(person).items() if k in ("head", "left_hand", "right_hand")}, person.height()
    )
    assert abs(three.height() - person.height()) < 0.01


@pytest.mark.mocap
@pytest.mark.parametrize("sensors", ["six_point", "four_point"])
def test_calibration_recovers_real_subjects_arms_legs_and_height(clip_index, sensors):
    """Noisy trackers, mounted as a user wears them, an imperfect T-pose: every validation and
    test subject (none trained on), two sessions each."""
    from sparse_body.data.catalog import load_clip, load_split

    split = load_split()
    first = {}
    for clip in split["validation"] + split["test"]:
        first.setdefault(clip_index[clip].subject, clip)
    assert len(first) >= 5
    config = load_sensor_config(sensors)
    for subject, clip in first.items():
        motion = load_clip(clip_index[clip]).slice(0, 30)
        truth = motion.skeleton
        for session in range(2):
            view = user_view(motion, config, FIELD, seed=session)
            body = view.skeleton
            where = f"subject {subject}, session {session}"
            assert abs(arm_length(body) - arm_length(truth)) < 0.015, where
            assert abs(leg_length(body) - leg_length(truth)) < 0.015, where
            assert abs(view.calibration.height - truth.height()) < 0.02, where
            assert abs(body.height() - truth.height()) < 0.02, where


def test_calibration_file_keeps_the_fitted_body_and_refuses_a_broken_one(tmp_path):
    body = Skeleton.canonical(1.6)
    cal = Calibration(1.6, 0.3, {"head": np.array([0.0, 0.0, 0.0, 1.0])}, body)
    cal.save(tmp_path / "cal.yaml")
    back = Calibration.load(tmp_path / "cal.yaml")
    np.testing.assert_allclose(back.body().offsets, body.offsets, atol=1e-5)
    assert Calibration(1.6, 0.0).body().height() == pytest.approx(1.6)  # no fitted body: scaled by height
    import yaml

    data = yaml.safe_load((tmp_path / "cal.yaml").read_text())
    del data["skeleton"]["right_wrist"]
    (tmp_path / "short.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(CalibrationError, match="short.yaml: 'skeleton' must give"):
        Calibration.load(tmp_path / "short.yaml")
    data["skeleton"]["right_wrist"] = [0.0, -5.0, 0.0]
    (tmp_path / "giant.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(CalibrationError, match="giant.yaml: a skeleton offset of 5.00 m"):
        Calibration.load(tmp_path / "giant.yaml")
    data["skeleton"]["right_wrist"] = [0.0, "far", 0.0]
    (tmp_path / "word.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(CalibrationError, match="word.yaml: every skeleton offset"):
        Calibration.load(tmp_path / "word.yaml")


def _frame(t, pos, quat, valid=True):
    return TrackerFrame(t, ("head",), np.array([pos], float), np.array([quat], float), np.array([valid]))


def test_filter_follows_constant_velocity_without_lag_and_removes_noise(rng):
    f = TrackerFilter(FilterConfig(position_noise=0.01, rotation_noise=1.0), ("head",))
    out = [f(_frame(i / 60, [0.5 * i / 60, 0.0, 1.6], [0, 0, 0, 1])).positions[0] for i in range(240)]
    assert abs(out[-1][0] - 0.5 * 239 / 60) < 0.001  # walking at 0.5 m/s: no lag left
    f.reset()
    noisy, smooth = [], []
    spin = Rotation.from_euler("z", 0.3)
    for i in range(600):
        p = np.array([0.2, -0.1, 1.5]) + rng.normal(0, 0.01, 3)
        q = (Rotation.from_rotvec(rng.normal(0, np.deg2rad(1.0), 3)) * spin).as_quat()
        out = f(_frame(i / 60, p, q))
        noisy.append(p)
        smooth.append(out.positions[0])
        assert abs(np.linalg.norm(out.orientations[0]) - 1) < 1e-9
    smooth, noisy = np.array(smooth)[60:], np.array(noisy)[60:]
    assert np.std(smooth, axis=0).max() < 0.75 * np.std(noisy, axis=0).min()
    # what shows as shaking is the sample-to-sample change: most of it is gone
    assert np.std(np.diff(smooth, axis=0), axis=0).max() < 0.45 * np.std(np.diff(noisy, axis=0), axis=0).min()
    assert (Rotation.from_quat(out.orientations[0]) * spin.inv()).magnitude() < np.deg2rad(1.0)


def test_filter_passes_bad_samples_and_starts_over_after_a_jump_or_a_gap():
    f = TrackerFilter(FilterConfig(), ("head",))
    for i in range(30):
        f(_frame(i / 60, [0.0, 0.0, 1.6], [0, 0, 0, 1]))
    bad = f(_frame(0.5, [np.nan] * 3, [0, 0, 0, 1]))
    assert np.isnan(bad.positions[0]).all()  # passed through, not invented
    dropped = f(_frame(0.52, [9.0, 9.0, 9.0], [0, 0, 0, 1], valid=False))
    assert dropped.positions[0][0] == 9.0 and not dropped.valid[0]
    moved = f(_frame(0.54, [3.0, 0.0, 1.6], [0, 0, 0, 1]))  # relocalised: 3 m away
    assert moved.positions[0][0] == 3.0
    back = f(_frame(0.1, [0.0, 0.0, 1.6], [0, 0, 0, 1]))  # the clock went back
    assert back.positions[0][0] == 0.0
    off = TrackerFilter(NO_FILTER, ("head",))
    assert all(off(_frame(i / 60, [i, 2.0, 3.0], [0, 0, 0, 1])).positions[0][0] == i for i in range(5))
    with pytest.raises(ValueError, match="acceleration"):
        FilterConfig(acceleration=-1.0)


def test_the_compiled_filter_gives_the_python_filter_s_frames(rng):
    """Parity with the plain-Python filter it replaced (test/tracker_filter_python.py) within
    1e-9, on six noisy trackers with dropped, non-finite and denormalised samples, gaps,
    jumps and a clock that goes back, under the default and a noisy configuration."""
    import tracker_filter_python as reference

    sites = ("head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")
    t = np.cumsum(rng.choice([1 / 60, 1 / 90, 0.3, -0.5], size=1500, p=[0.8, 0.17, 0.02, 0.01]))
    positions = np.cumsum(rng.normal(0, 0.01, (len(t), 6, 3)), axis=0)
    positions[rng.random(len(t)) < 0.01] += 2.0  # a relocalised system: every tracker jumps
    orientations = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.05, (len(t) * 6, 3)), axis=0)).as_quat()
    orientations = orientations.reshape(len(t), 6, 4) * rng.choice(
        [1.0, 1.05, 0.5], size=(len(t), 6, 1), p=[0.9, 0.08, 0.02]
    )
    positions[rng.random((len(t), 6)) < 0.01] = np.nan
    valid = rng.random((len(t), 6)) > 0.03
    given = positions.copy(), orientations.copy()
    for config in (FilterConfig(), FilterConfig(position_noise=0.01, rotation_noise=1.5, gap=0.1)):
        ours, theirs = TrackerFilter(config, sites), reference.TrackerFilter(config, sites)
        for i in range(len(t)):
            frame = TrackerFrame(float(t[i]), sites, positions[i], orientations[i], valid[i])
            a, b = ours(frame), theirs(frame)
            np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-9, equal_nan=True)
            np.testing.assert_allclose(a.orientations, b.orientations, rtol=0, atol=1e-9, equal_nan=True)
    np.testing.assert_array_equal(positions, given[0])  # the input frames are left as they were
    np.testing.assert_array_equal(orientations, given[1])


def test_lab_protocol_is_the_true_skeleton_and_exact_mounting():
    motion = synthetic_walk(2.0)
    config = load_sensor_config("six_point")
    lab = user_view(motion, config, LAB)
    assert lab.skeleton is motion.skeleton and lab.calibration is None
    field = user_view(motion, config, FIELD)
    assert field.calibration is not None and not np.allclose(field.skeleton.offsets, motion.skeleton.offsets)
    assert all(s.offset_rotation == (0.0, 0.0, 0.0, 1.0) for s in field.sensors.sites)  # calibrated away
    assert Protocol.named("oracle", "none") == LAB and Protocol.named() == FIELD_EXACT
    assert FIELD_EXACT.label == "field, vr noise" and LAB.label == "lab"
    with pytest.raises(ValueError, match="noise must be one of"):
        Protocol.named(noise="loud")


def test_the_field_preset_is_a_users_session_with_failures_and_worn_mounting_and_each_value_can_be_overridden():
    assert FIELD.skeleton == "calibrated" and FIELD.mounting_translation_std == 0.015 and FIELD.calibrate_mounting
    assert FIELD.noise.loss_probability > 0 and FIELD.noise.jump_probability > 0 and FIELD.noise.yaw_drift == 2.0
    assert FIELD.noise.lost_percent == pytest.approx(3.0)
    assert FIELD.label == (
        "field, vr noise, hands lost in 3 % of frames, 1 position jump a minute, IMU heading drift up to "
        "2 deg/min, 15 mm mounting error, mounting calibrated from movement"
    )
    # each flag overrides its own value only; None keeps the preset's
    quiet = Protocol.preset("field", lost_percent=0.0, jumps_per_minute=None)
    assert quiet.noise.loss_probability == 0 and quiet.noise.jump_probability == FIELD.noise.jump_probability
    assert Protocol.preset("field", lost_percent=0, jumps_per_minute=0, yaw_drift=0, mounting_error=0,
                           calibrate_mounting=False) == FIELD_EXACT  # fmt: skip
    # an oracle skeleton asked of the field comes with the true mounting (named() refuses a mounting error there)
    oracle = Protocol.preset("field", skeleton="oracle", noise="none")
    assert oracle.mounting_translation_std == 0 and not oracle.calibrate_mounting and oracle.noise.loss_probability > 0
    with pytest.raises(ValueError, match="an oracle skeleton comes with the true mounting"):
        Protocol.preset("field", skeleton="oracle", mounting_error=0.01)
    with pytest.raises(ValueError, match="protocol must be one of field, field-exact, lab"):
        Protocol.preset("kind")
    assert Protocol.preset("lab") == LAB and Protocol.preset("field-exact") == FIELD_EXACT


def test_six_point_ik_in_the_field_keeps_its_end_effectors_on_the_trackers():
    motion = synthetic_walk(4.0)
    config = load_sensor_config("six_point")
    lab = evaluate_motion(motion, "ik", config, LAB)
    field = evaluate_motion(motion, "ik", config, FIELD)
    assert field["End-effector PE [cm]"] < 0.5
    assert field["MPJPE [cm]"] < 1.5 * lab["MPJPE [cm]"] + 0.5
    # the filter, set for LoBSTr's noise, takes most of it out of the joints' velocities
    noisy = evaluate_motion(motion, "ik", config, Protocol("calibrated", LOBSTR_NOISE))
    raw = evaluate_motion(
        motion, "ik", config, Protocol("calibrated", LOBSTR_NOISE), filter_position_noise=0.0, filter_rotation_noise=0.0
    )
    assert noisy["MPJVE [cm/s]"] < 0.6 * raw["MPJVE [cm/s]"]
    assert noisy["Jitter [100m/s3]"] < 0.6 * raw["Jitter [100m/s3]"]
    clean = evaluate_motion(motion, "ik", config, Protocol("calibrated", NO_NOISE))
    assert clean["End-effector PE [cm]"] < field["End-effector PE [cm]"] + 0.1


@pytest.mark.mocap
def test_eval_command_runs_the_field_protocol_by_default_and_the_lab_on_request(tmp_path):
    common = [
        sys.executable,
        "-m",
        "sparse_body.cli",
        "eval",
        "--estimator",
        "ik",
        "--sensors",
        "six_point",
        "--limit",
        "2",
        "--quiet",
        "--no-compare",
    ]
    field = subprocess.run(common + ["--output", str(tmp_path / "f.json")], capture_output=True, text=True, timeout=600)
    lab = subprocess.run(
        common + ["--protocol", "lab", "--output", str(tmp_path / "l.json")],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert field.returncode == 0 and lab.returncode == 0, field.stderr + lab.stderr
    assert f"{FIELD.label} protocol" in field.stdout and "lab protocol" in lab.stdout
    import json

    field, lab = (json.loads((tmp_path / n).read_text())[0] for n in ("f.json", "l.json"))
    assert field["protocol"] == FIELD.label and lab["protocol"] == "lab"
    assert Protocol.from_json(field["protocol_spec"]) == FIELD
    assert field["summary"]["MPJPE [cm]"] > lab["summary"]["MPJPE [cm]"]
    assert lab["summary"]["End-effector PE [cm]"] < 0.2


def test_a_protocol_comes_back_equal_from_the_json_a_results_file_keeps():
    import json

    from sparse_body.data.field_protocol import FIELD, LAB, Protocol

    losing = Protocol.named("calibrated", "vr", lost_percent=10.0, loss_mode="frozen")
    for protocol in (FIELD, LAB, Protocol.named("height", "none", 5.0, 0.01, 10.0), losing):
        assert Protocol.from_json(json.loads(json.dumps(protocol.to_json()))) == protocol
    assert losing.label == "field, vr noise, hands frozen in 10 % of frames"


def test_a_motion_lying_on_the_floor_keeps_its_limbs_and_rests_its_lowest_joint_on_the_floor():
    """The floor part (eval --split floor): a clip's body on its back, side or front."""
    from scipy.spatial.transform import Rotation

    from sparse_body.core.skeleton import JOINT_INDEX
    from sparse_body.data.floor import FLOOR_CLEARANCE, LYING, lying

    walk = synthetic_walk(2.0)
    # which of the pelvis's own axes points up: forward (x) on the back, left (y) on the side
    faces_up = {"lying on the back": [1, 0, 0], "lying on the side": [0, 1, 0], "lying on the front": [-1, 0, 0]}
    for how in LYING:
        lain = lying(walk, how)
        p = lain.positions
        np.testing.assert_allclose(p[..., 2].min(axis=1), FLOOR_CLEARANCE, atol=1e-9)
        spine = p[:, JOINT_INDEX["head"]] - p[:, 0]
        assert np.all(np.abs(spine[:, 2]) < 0.15 * np.linalg.norm(spine, axis=1)), how  # the spine lies flat
        up = Rotation.from_quat(lain.local_quats[:, 0]).apply(faces_up[how])
        assert np.all(up[:, 2] > 0.9), how
        # the limbs move as in the clip: the joints' local turns are the clip's
        np.testing.assert_allclose(lain.local_quats[:, 1:], walk.local_quats[:, 1:])
        assert np.ptp(p[:, 0, :2], axis=0).max() < 1e-9  # held where the clip starts


def test_the_evaluation_puts_the_floor_where_the_lying_body_lies():
    """A user's play space has its floor where it is; estimated from the toes, as a motion
    capture's is, the floor part's floor sat where a lying body's lowest toe happened to be."""
    from sparse_body.core.contacts import estimate_floor
    from sparse_body.data.floor import FLOOR_CLEARANCE, lying
    from sparse_body.evaluation import floored

    walk = synthetic_walk(2.0)
    lain = lying(walk, "lying on the back")
    assert estimate_floor(lain.positions) > FLOOR_CLEARANCE + 0.02  # the toes' floor is not the floor
    on = floored(lain)
    np.testing.assert_allclose(on.root_positions, lain.root_positions)  # its own floor is z = 0 already
    np.testing.assert_allclose(on.positions[..., 2].min(axis=1), FLOOR_CLEARANCE, atol=1e-9)
    assert floored(walk).positions[:, [10, 11], 2].min() == pytest.approx(0.0, abs=0.03)  # a capture: from the toes
