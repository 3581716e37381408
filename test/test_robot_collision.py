"""A robot's self-collisions (robot/collision.py): capsule distances against dense sampling,
the shapes read from a URDF's collision primitives (or a mesh link's inertia), the pairs a
robot touches by construction left out, and a pose reaching through itself found."""

from pathlib import Path

import numpy as np
import pytest

from sparse_body.robot.collision import SelfCollision, segment_distances
from sparse_body.robot.example import urdf
from sparse_body.robot.retarget import neutral_pose
from sparse_body.robot.urdf_model import load_urdf, parse_urdf

UNITREE = Path(__file__).resolve().parents[2] / "shared" / "robots" / "unitree"


def test_segment_distances_are_the_least_over_both_segments_parallel_and_point_ones_included():
    rng = np.random.default_rng(0)
    p1, q1, p2, q2 = (rng.normal(size=(2000, 3)) for _ in range(4))
    q1[:200] = p1[:200]  # points
    q2[200:400] = p2[200:400]
    q1[400:500], q2[400:500] = p1[400:500], p2[400:500]
    q2[500:700] = p2[500:700] + 0.7 * (q1[500:700] - p1[500:700])  # parallel
    found = segment_distances(p1, q1, p2, q2)
    u = np.linspace(0.0, 1.0, 401)
    a = p1[:, None] + u[None, :, None] * (q1 - p1)[:, None]
    b = p2[:, None] + u[None, :, None] * (q2 - p2)[:, None]
    sampled = np.linalg.norm(a[:, :, None] - b[:, None, :], axis=-1).min(axis=(1, 2))
    assert np.all(found <= sampled + 1e-9)  # never more than a pair of points shows
    assert np.all(sampled - found < 0.01)  # and within the sampling's step


def _check(model) -> SelfCollision:
    lower, upper = model.limits()
    return SelfCollision(model, [np.clip(0.0, lower, upper), neutral_pose(lower, upper)])


def _pose(model, **values) -> np.ndarray:
    lower, upper = model.limits()
    q = np.clip(0.0, lower, upper)
    for name, value in values.items():
        q[[j.name for j in model.moving].index(name)] = value
    return q


def test_thighs_pulled_across_each_other_collide_and_the_robots_own_poses_do_not():
    model = parse_urdf(urdf())
    assert len(model.capsules) == 11  # the example's collision cylinders
    check = _check(model)
    assert ("left_hip_pitch_link", "right_hip_pitch_link") in check.pairs  # the thighs
    assert ("pelvis", "torso_link") not in check.pairs  # a joint apart: always touching
    for q in (_pose(model), neutral_pose(*model.limits())):
        assert check.distances(model.forward(q, np.eye(4))[0]).min() > 0.0
    crossed = _pose(model, left_hip_roll_joint=-0.4, right_hip_roll_joint=0.4)
    clearance = check.distances(model.forward(crossed, np.eye(4))[0])
    assert clearance.min() < 0.0
    assert check.pairs[int(np.argmin(clearance))] == ("left_hip_pitch_link", "right_hip_pitch_link")


@pytest.mark.parametrize("name", ["g1_29dof", "h1", "h1_2_handless"])
def test_unitree_robots_get_a_shape_for_every_limb_and_none_touching_at_rest(name):
    if not (UNITREE / f"{name}.urdf").is_file():
        pytest.skip(f"Unitree's {name}.urdf (unitree_ros, BSD-3-Clause) is not installed beside the checkout")
    model = load_urdf(UNITREE / f"{name}.urdf")
    shaped = {model.links[c.link] for c in model.capsules}
    for side in ("left", "right"):  # meshes (G1, H1-2) or primitives (H1): every limb has a shape
        assert f"{side}_knee_link" in shaped and f"{side}_elbow_link" in shaped
    assert all(0.01 <= c.radius < 0.3 for c in model.capsules)
    check = _check(model)
    assert len(check.pairs) > 100
    assert check.distances(model.forward(neutral_pose(*model.limits()), np.eye(4))[0]).min() > 0.0


def _crossed_legs(skeleton, degrees: float):
    """A standing body whose legs are pulled across each other at the hips (its feet crossed)."""
    from sparse_body.core.rotations import matrix_to_quat, rotation_about
    from sparse_body.core.skeleton import JOINT_INDEX
    from sparse_body.core.types import BodyPose

    quats = np.tile([0.0, 0.0, 0.0, 1.0], (22, 1))
    for side, sign in (("left", -1.0), ("right", 1.0)):
        quats[JOINT_INDEX[f"{side}_hip"]] = matrix_to_quat(rotation_about([1.0, 0.0, 0.0], np.radians(sign * degrees)))
    return BodyPose(0.0, quats, np.array([0.0, 0.0, 0.95]))


def test_the_solver_keeps_the_thighs_apart_where_the_person_crosses_them(tmp_path, monkeypatch):
    """Reaching for crossed feet, the example robot's thighs would pass through each other;
    the solver's clearance rows hold them apart (with them off, the same pose overlaps)."""
    from sparse_body.core.skeleton import Skeleton
    from sparse_body.robot import retarget as solver
    from sparse_body.robot.example import write_robot

    skeleton = Skeleton.canonical(1.75)
    body = _crossed_legs(skeleton, 25.0)

    def clearance() -> float:  # the pose held for a sixth of a second, as a person holds it
        robot = solver.load_retarget(write_robot(tmp_path / "robot"), None, skeleton)
        for i in range(10):
            pose = robot.step(body.restamped(i / 60))
        links = robot.link_transforms(pose.positions, pose.base_position, robot.base_turn)
        return float(robot.collision.distances(links).min())

    kept = clearance()
    monkeypatch.setattr(solver, "COLLISION", 0.0)
    crossed = clearance()
    assert crossed < -0.02, crossed
    assert kept > -0.01, kept  # (9.6 cm into each other without; soft rows leave 5 mm)
