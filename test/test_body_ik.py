"""The closed-form body IK (core/body_ik.py) and the estimator template it runs in."""

import numpy as np
import pytest
from conftest import random_rotations

from sparse_body.core.body_ik import LIMBS, SOFT_REACH, fit_spine, hinge_angle, reach_angle, soft_distance, solve_body
from sparse_body.core.kinematics import forward_kinematics
from sparse_body.core.rotations import axis_angle_to_matrix, rotation_about
from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.core.skeleton import Skeleton, standing_pose


def _limb_length(offsets, limb):
    return np.linalg.norm(offsets[limb.hinge]) + np.linalg.norm(offsets[limb.end])


def test_reach_angle_makes_the_limb_as_long_as_asked_for_bones_that_are_not_collinear(rng):
    for _ in range(200):
        a, w = rng.normal(size=3) * 0.3, rng.normal(size=3) * 0.3
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        lengths = [np.linalg.norm(a + rotation_about(axis, t) @ w) for t in np.linspace(-np.pi, np.pi, 721)]
        wanted = rng.uniform(min(lengths), max(lengths))
        t = reach_angle(a, w, axis, wanted, 0.0, None)
        assert abs(np.linalg.norm(a + rotation_about(axis, t) @ w) - wanted) < 1e-9


def test_solved_limbs_reach_reachable_targets_with_exact_hinges_within_limits(rng):
    skeleton = Skeleton.canonical(1.8)
    offsets = skeleton.offsets
    start = standing_pose()
    root = np.array([0.3, -0.2, 1.0])
    _, rest = forward_kinematics(start, root, offsets)
    for _ in range(50):
        targets = {}
        for end, limb in LIMBS.items():
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            # from a third of the limb's length to nearly straight
            targets[end] = rest[limb.upper] + direction * rng.uniform(0.35, 0.98) * _limb_length(offsets, limb)
        local, glob, pos = solve_body(start, root, offsets, targets)
        _, fk = forward_kinematics(local, root, offsets)
        np.testing.assert_allclose(fk, pos, atol=1e-12)  # what it returns is the pose's own FK
        for end, limb in LIMBS.items():
            assert np.linalg.norm(fk[end] - targets[end]) < 1e-6
            hinge = local[limb.hinge]
            angle = hinge_angle(hinge, limb.axis)
            np.testing.assert_allclose(hinge @ limb.axis, limb.axis, atol=1e-12)  # a rotation about its axis only
            assert limb.limits[0] - 1e-9 <= angle <= limb.limits[1] + 1e-9
        np.testing.assert_allclose(local[0], start[0])  # the root is not the limbs' to move


def test_a_target_out_of_reach_gets_the_stretched_limb_pointing_at_it():
    offsets = Skeleton.canonical().offsets
    root = np.zeros(3)
    _, rest = forward_kinematics(standing_pose(), root, offsets)
    limb = LIMBS[J["left_ankle"]]
    target = rest[limb.upper] + np.array([0.5, 0.2, -2.0])
    local, _, pos = solve_body(standing_pose(), root, offsets, {J["left_ankle"]: target})
    reached = pos[J["left_ankle"]] - pos[limb.upper]
    assert abs(np.linalg.norm(reached) - _limb_length(offsets, limb)) < 1e-6
    wanted = target - pos[limb.upper]
    assert np.degrees(np.arccos(reached @ wanted / np.linalg.norm(reached) / np.linalg.norm(wanted))) < 1e-3


def test_the_swivel_follows_from_the_previous_pose_without_jumps():
    """A hand moved in small steps: the elbow moves in small steps too (no flips)."""
    offsets = Skeleton.canonical().offsets
    root = np.zeros(3)
    local = standing_pose()
    _, pos = forward_kinematics(local, root, offsets)
    shoulder = pos[J["left_shoulder"]]
    elbows, hands = [], []
    for t in np.linspace(0, 2 * np.pi, 400):  # a circle in front of the body
        target = shoulder + np.array([0.35 + 0.1 * np.cos(t), 0.15 * np.sin(t), -0.15 + 0.1 * np.sin(2 * t)])
        local, _, pos = solve_body(local, root, offsets, {J["left_wrist"]: target})
        elbows.append(pos[J["left_elbow"]])
        hands.append(pos[J["left_wrist"]])
    hand_step = np.linalg.norm(np.diff(hands, axis=0), axis=1).max()
    elbow_step = np.linalg.norm(np.diff(elbows, axis=0), axis=1).max()
    assert elbow_step < 3 * hand_step


def test_the_spine_puts_the_head_on_its_target_and_leaves_the_pelvis(rng):
    offsets = Skeleton.canonical().offsets
    root = np.array([0.0, 0.0, 1.0])
    _, rest = forward_kinematics(standing_pose(), root, offsets)
    spine_length = np.linalg.norm(rest[J["head"]] - rest[J["spine1"]])
    for _ in range(50):
        local = standing_pose()
        local[0] = random_rotations(rng, (1,))[0]
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        s1 = root + local[0] @ offsets[J["spine1"]]
        target = s1 + direction * spine_length * rng.uniform(0.85, 1.0)  # leaning and bending
        before = local.copy()
        fit_spine(local, root, offsets, target)
        _, pos = forward_kinematics(local, root, offsets)
        # exact, but for the soft reach's shortfall near full extension
        distance = np.linalg.norm(target - s1)
        short = distance - soft_distance(distance, spine_length)
        assert short <= 0.63 * SOFT_REACH + 1e-9
        assert np.linalg.norm(pos[J["head"]] - target) < short + 1e-4
        np.testing.assert_allclose(local[0], before[0])


def test_a_kept_spine_curve_stays_while_it_leaves_the_head_within_the_tolerance():
    """A bent spine whose head would land 1 cm short of the target: with the IK's 5 mm
    tolerance it is bent anew and the head reaches; with 1.5 cm (LoBSTr's) the curve is kept,
    only turned, and the head is the centimetre short."""
    offsets = Skeleton.canonical().offsets
    root = np.array([0.0, 0.0, 1.0])
    curved = standing_pose()
    for j in ("spine2", "spine3", "neck"):
        curved[J[j]] = rotation_about(np.array([0.0, 1.0, 0.0]), 0.25)
    _, pos = forward_kinematics(curved, root, offsets)
    s1 = pos[J["spine1"]]
    reach = pos[J["head"]] - s1
    target = s1 + rotation_about(np.array([1.0, 0.0, 0.0]), 0.3) @ reach * (1 + 0.01 / np.linalg.norm(reach))
    for tolerance, kept in ((0.005, False), (0.015, True)):
        local = curved.copy()
        fit_spine(local, root, offsets, target, keep_bend=True, tolerance=tolerance)
        _, solved = forward_kinematics(local, root, offsets)
        miss = np.linalg.norm(solved[J["head"]] - target)
        bends = [np.allclose(local[J[j]], curved[J[j]]) for j in ("spine2", "spine3", "neck")]
        assert all(bends) == kept and (miss == pytest.approx(0.01, abs=1e-6) if kept else miss < 1e-3), tolerance


def test_keep_shape_only_turns_a_decoded_elbow_about_its_axis(rng):
    offsets = Skeleton.canonical().offsets
    root = np.zeros(3)
    local = standing_pose()
    limb = LIMBS[J["right_wrist"]]
    local[limb.hinge] = rotation_about(limb.axis, 0.8) @ rotation_about(np.array([1.0, 0, 0]), 0.05)  # not a pure hinge
    _, pos = forward_kinematics(local, root, offsets)
    target = pos[J["right_wrist"]] + np.array([0.03, 0.02, 0.05])
    solved, _, solved_pos = solve_body(local, root, offsets, {J["right_wrist"]: target}, keep_shape=True)
    assert np.linalg.norm(solved_pos[J["right_wrist"]] - target) < 1e-6
    turn = local[limb.hinge].T @ solved[limb.hinge]  # the change is a turn about the hinge axis
    np.testing.assert_allclose(turn @ limb.axis, limb.axis, atol=1e-9)


@pytest.mark.parametrize("beyond", [0.005, 0.03, 0.08])
def test_keep_shape_turns_the_collar_as_far_as_a_hand_just_out_of_reach_needs(beyond):
    """A predicted pose's shoulder a few centimetres off: the hand still lands (the IK's own
    single collar turn, kept for the baseline, leaves it short by centimetres)."""
    offsets = Skeleton.canonical().offsets
    root = np.zeros(3)
    local = standing_pose()
    limb = LIMBS[J["left_wrist"]]
    _, pos = forward_kinematics(local, root, offsets)
    down = np.array([0.0, 0.0, -1.0])  # a hanging arm, the hand just too far
    target = pos[limb.upper] + down * (_limb_length(offsets, limb) + beyond)
    solved, glob, solved_pos = solve_body(local, root, offsets, {limb.end: target}, keep_shape=True)
    assert np.linalg.norm(solved_pos[limb.end] - target) < 1e-6
    collar = J["left_collar"]
    turned = np.degrees(np.arccos(np.clip((np.trace(local[collar].T @ solved[collar]) - 1) / 2, -1, 1)))
    assert 0 < turned < 45  # the collar did it, and no more than needed
    _, _, ik_pos = solve_body(local, root, offsets, {limb.end: target})
    assert np.linalg.norm(ik_pos[limb.end] - target) > 0.5 * beyond


def test_the_estimator_template_holds_the_last_pose_and_starts_over_after_a_non_finite_result():
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.core.types import BodyPose
    from sparse_body.data.synthetic import synthetic_walk
    from sparse_body.data.virtual_trackers import synthesize_trackers
    from sparse_body.estimators.base import Estimator

    class Scripted(Estimator):
        """Returns what it is told to: a pose, None (too little input) or NaN."""

        name = "scripted"

        def __init__(self, *args):
            super().__init__(*args)
            self.resets, self.script = 0, []
            self.reset()

        def _reset(self):
            self.resets += 1

        def _estimate(self, frame):
            kind = self.script.pop(0)
            quats = np.tile([0.0, 0.0, 0.0, 1.0], (22, 1))
            if kind == "nan":
                quats[3] = np.nan
            return None if kind == "none" else BodyPose(frame.stamp, quats, np.full(3, frame.stamp))

    config = load_sensor_config("three_point")
    motion = synthetic_walk(1.0)
    stream = synthesize_trackers(motion, config)
    est = Scripted(config, motion.skeleton)
    est.script = ["pose", "none", "nan", "pose"]
    first, held, broken, again = (est.step(stream.frame(i)) for i in range(4))
    assert first.valid and not held.valid and not broken.valid and again.valid
    np.testing.assert_allclose(held.root_position, first.root_position)  # the last pose, at the new stamp
    assert held.stamp == stream.times[1]
    assert broken.is_finite() and est.resets == 2  # started over, nothing non-finite out
    np.testing.assert_allclose(broken.root_position, 0.0)  # after the reset: the starting pose


@pytest.mark.parametrize("sensors", ["three_point", "four_point", "six_point"])
def test_ik_puts_every_tracked_joint_on_its_tracker(sensors):
    from sparse_body.core.rotations import quat_to_matrix
    from sparse_body.core.sensors import SITE_JOINTS, load_sensor_config
    from sparse_body.data.synthetic import synthetic_walk
    from sparse_body.data.virtual_trackers import synthesize_trackers
    from sparse_body.methods.factory import create_estimator

    config = load_sensor_config(sensors)
    motion = synthetic_walk(3.0)
    stream = synthesize_trackers(motion, config)
    est = create_estimator("ik", config, motion.skeleton, filter=False)
    errors = []
    for i, frame in enumerate(stream):
        pose = est.step(frame)
        _, pos = forward_kinematics(quat_to_matrix(pose.local_quats), pose.root_position, motion.skeleton.offsets)
        errors.append(
            [np.linalg.norm(pos[J[SITE_JOINTS[s]]] - motion.positions[i, J[SITE_JOINTS[s]]]) for s in config.site_names]
        )
    # exact but for the soft reach of nearly straight legs and arms (at most 0.63 of it short)
    assert np.max(errors) < 0.63 * SOFT_REACH + 0.001, dict(zip(config.site_names, np.max(errors, axis=0), strict=True))
    assert np.mean(errors) < 0.002


def _random_problem(rng, offsets):
    """A pose (random, near rest or far from it), a root and targets for some of head, hands
    and feet: near the current ends (tracking), a limb's length away or far out of reach."""
    local = standing_pose()
    spread = rng.choice([0.05, 0.4, 3.0])
    local[1:] = (
        random_rotations(rng, (21,)) if spread == 3.0 else axis_angle_to_matrix(rng.normal(size=(21, 3)) * spread)
    )
    local[0] = random_rotations(rng, (1,))[0]
    root = rng.normal(size=3)
    _, pos = forward_kinematics(local, root, offsets)
    ends = [J["head"], J["left_wrist"], J["right_wrist"], J["left_ankle"], J["right_ankle"]]
    targets = {j: pos[j] + rng.normal(size=3) * rng.choice([0.005, 0.1, 0.6]) for j in ends if rng.random() < 0.8}
    return local, root, targets


def test_the_compiled_solver_gives_the_numpy_solver_s_poses(rng):
    """Parity with the numpy implementation it replaced (test/body_ik_numpy.py): whole solves
    both ways, a held toe (LoBSTr's contact IK) and the spine alone, within 1e-9. A hinge
    solved at full extension is the exception: there the angle is an arccos of a number a
    rounding away from 1, which turns the last bit of a sum (numpy's order against ours)
    into 1e-7 (found in 1 of 900 solves here); those stay within 1e-6."""
    import body_ik_numpy as reference

    from sparse_body.core import body_ik

    differences = []
    for height in (1.5, 1.8, 2.0):
        offsets = Skeleton.canonical(height).offsets
        for _ in range(150):
            local, root, targets = _random_problem(rng, offsets)
            worst = 0.0
            for keep in (False, True):
                for ours, theirs in zip(
                    body_ik.solve_body(local, root, offsets, targets, keep_shape=keep),
                    reference.solve_body(local, root, offsets, targets, keep_shape=keep),
                    strict=True,
                ):
                    worst = max(worst, float(np.abs(ours - theirs).max()))
            glob, pos = forward_kinematics(local, root, offsets)
            for end, exact in ((J["left_ankle"], True), (J["right_wrist"], False)):
                limb, toe = LIMBS[end], offsets[end] + local[end] @ offsets[J["left_foot"]]
                target = pos[end] + rng.normal(size=3) * 0.2
                ours_local, theirs_local = local.copy(), local.copy()
                ours = body_ik.reach(ours_local, glob[0], pos[limb.upper], offsets, limb, target, toe, exact)
                theirs = reference.reach(
                    theirs_local, glob[0], pos[limb.upper], offsets, reference.LIMBS[end], target, toe, exact
                )
                worst = max(
                    worst, float(np.abs(ours_local - theirs_local).max()), float(np.abs(ours[0] - theirs[0]).max())
                )
            if J["head"] in targets:
                ours_local, theirs_local = local.copy(), local.copy()
                body_ik.fit_spine(ours_local, root, offsets, targets[J["head"]], keep_bend=True, tolerance=0.02)
                reference.fit_spine(theirs_local, root, offsets, targets[J["head"]], keep_bend=True, tolerance=0.02)
                worst = max(worst, float(np.abs(ours_local - theirs_local).max()))
            differences.append(worst)
    differences = np.array(differences)
    assert differences.max() < 1e-6
    assert np.mean(differences < 1e-9) > 0.98, np.sort(differences)[-10:]
