"""upright: the base estimator shown the body stood up as it lies down (or, with a fallback named,
handed over to it); the tilt that decides it flags the lying frames and none of a walk."""

import numpy as np

from sparse_body.core.sensors import load_sensor_config
from sparse_body.data.floor import LYING, lying
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import NO_NOISE, synthesize_trackers
from sparse_body.methods.factory import create_estimator


def _run(estimator, motion, sensors):
    stream = synthesize_trackers(motion, sensors, NO_NOISE)
    poses, shares = [], []
    for frame in stream:
        poses.append(estimator.step(frame))
        shares.append(getattr(estimator, "share", 0.0))
    return poses, np.array(shares)


def _leg_errors(poses, motion, skeleton):
    """Per frame, degrees between the estimate's and the body's left hip-to-ankle line."""
    from scipy.spatial.transform import Rotation

    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.skeleton import JOINT_INDEX as J

    def legs(local, root, offsets):
        _, p = forward_kinematics(local, root, offsets)
        v = p[:, J["left_ankle"]] - p[:, J["left_hip"]]
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    quats = np.stack([p.local_quats for p in poses])
    est = legs(Rotation.from_quat(quats.reshape(-1, 4)).as_matrix().reshape(len(poses), -1, 3, 3),
               np.stack([p.root_position for p in poses]), skeleton.offsets)  # fmt: skip
    true_local = Rotation.from_quat(motion.local_quats.reshape(-1, 4)).as_matrix().reshape(len(motion), -1, 3, 3)
    true = legs(true_local, motion.root_positions, motion.skeleton.offsets)
    return np.degrees(np.arccos(np.clip((est * true).sum(1), -1.0, 1.0)))


def test_a_walk_is_the_base_s_and_a_body_lying_down_is_stood_up_for_it():
    sensors = load_sensor_config("four_point")
    walk = synthetic_walk(2.0, speed=0.3)  # short strides: a body lying keeps its pelvis low
    upright = create_estimator("upright", sensors, walk.skeleton, foot_lock=False, base="lobstr")
    base = create_estimator("lobstr", sensors, walk.skeleton, foot_lock=False)
    poses, shares = _run(upright, walk, sensors)
    alone, _ = _run(base, walk, sensors)
    assert shares.max() < 0.01  # upright throughout: nothing turned
    assert max(np.abs(p.local_quats - q.local_quats).max() for p, q in zip(poses, alone, strict=True)) < 0.02
    standing = np.median(_leg_errors(alone, walk, walk.skeleton))
    stood, lost = {}, {}
    for how in LYING:
        lain = lying(walk, how)
        upright.reset()
        base.reset()
        poses, shares = _run(upright, lain, sensors)
        alone, _ = _run(base, lain, sensors)
        assert shares[60:].min() > 0.99, how  # lying: the whole tilt taken out, once settled
        assert all(p.valid and p.is_finite() for p in poses), how
        late = slice(90, None)
        stood[how] = np.median(_leg_errors(poses[late], lain.slice(90, len(lain)), walk.skeleton))
        lost[how] = np.median(_leg_errors(alone[late], lain.slice(90, len(lain)), walk.skeleton))
    # stood up, the base's legs are near its own on the walk whichever way the body lies; left
    # lying, some way of lying throws them far off
    assert max(stood.values()) < standing + 10.0, (stood, standing)
    assert max(stood.values()) < max(lost.values()) - 20.0, (stood, lost)


def test_a_named_fallback_is_handed_the_lying_body():
    sensors = load_sensor_config("four_point")
    walk = synthetic_walk(2.0, speed=0.3)  # short strides: a body lying keeps its pelvis low
    upright = create_estimator("upright", sensors, walk.skeleton, foot_lock=False, base="lobstr", fallback="ik")
    fallback = create_estimator("ik", sensors, walk.skeleton, foot_lock=False)
    for how in LYING:
        lain = lying(walk, how)
        upright.reset()
        fallback.reset()
        poses, shares = _run(upright, lain, sensors)
        ik, _ = _run(fallback, lain, sensors)
        assert shares[60:].min() > 0.99, how  # lying: the fallback's, once settled (five time constants)
        late = slice(90, None)
        gap = max(np.abs(p.root_position - q.root_position).max() for p, q in zip(poses[late], ik[late], strict=True))
        assert gap < 0.01, how


def test_eval_says_each_estimator_s_worst_kind_against_ik():
    """Tables by kind, always: beside IK, each estimator's worst kind and its share of IK's."""
    from sparse_body.core.results import EvalResult, format_groups

    def result(name, values):
        clips = [
            {"clip": f"c{k}", "frames": 100, "category": kind, "MPJPE [cm]": value}
            for k, (kind, value) in enumerate(values)
        ]
        return EvalResult.from_json({"estimator": name, "sensors": "four_point", "split": "floor", "clips": clips})

    ik = result("ik", [("walk", 10.0), ("lying", 20.0)])
    text = format_groups([ik, result("upright", [("walk", 6.0), ("lying", 21.0)])], by="category", label="motion")
    assert "upright/four_point: worst kind lying, 1.05x IK's MPJPE [cm]" in text, text


def test_a_body_bent_over_with_its_pelvis_high_is_not_lying():
    """Picking something up tilts the torso as far as lying down does, with the pelvis at a
    standing height: nothing is turned, the pose is the base's."""
    from scipy.spatial.transform import Rotation

    from sparse_body.core.skeleton import JOINT_INDEX as J
    from sparse_body.data.motion import Motion

    sensors = load_sensor_config("four_point")
    walk = synthetic_walk(2.0, speed=0.3)
    quats = np.array(walk.local_quats)
    spine = J["spine1"]
    quats[:, spine] = (Rotation.from_quat(quats[:, spine]) * Rotation.from_euler("y", 85, degrees=True)).as_quat()
    bent = Motion("bent", walk.fps, walk.skeleton, quats, walk.root_positions)
    upright = create_estimator("upright", sensors, walk.skeleton, foot_lock=False, base="lobstr")
    base = create_estimator("lobstr", sensors, walk.skeleton, foot_lock=False)
    poses, shares = _run(upright, bent, sensors)
    alone, _ = _run(base, bent, sensors)
    assert upright.tilted > 60.0  # tilted as a lying body is
    assert shares.max() < 0.01
    assert max(np.abs(p.local_quats - q.local_quats).max() for p, q in zip(poses, alone, strict=True)) < 0.02


def test_eval_counts_the_frames_upright_says_lie_outside_what_it_knows():
    """Issue 73: the out-of-depth score is said in eval's output as well as on estimate_status."""
    from sparse_body.evaluation import OUT_OF_DEPTH, estimate_motion, score

    sensors = load_sensor_config("four_point")
    walk = synthetic_walk(3.0)
    standing = estimate_motion(walk, "upright", sensors)
    lain = estimate_motion(lying(walk, "lying on the back"), "upright", sensors)
    assert standing.out_of_depth is not None and lain.out_of_depth is not None
    assert score(standing)[OUT_OF_DEPTH] < 5.0 < 80.0 < score(lain)[OUT_OF_DEPTH]
    ik = estimate_motion(walk, "ik", sensors)
    assert ik.out_of_depth is None and OUT_OF_DEPTH not in score(ik)  # (only upright says it)
