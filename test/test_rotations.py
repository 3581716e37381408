import numpy as np
import pytest
from conftest import random_rotations
from scipy.spatial.transform import Rotation

from sparse_body.core import rotations as R


def test_quaternion_matrix_round_trip_keeps_batch_shape(rng):
    m = random_rotations(rng, (5, 22))
    q = R.matrix_to_quat(m)
    assert q.shape == (5, 22, 4)
    np.testing.assert_allclose(R.quat_to_matrix(q), m, atol=1e-12)


def test_quaternions_are_xyzw():
    # 90 degrees about z: (0, 0, sin 45, cos 45) in x y z w order.
    q = R.matrix_to_quat(R.euler_to_matrix([0, 0, np.pi / 2], "xyz"))
    np.testing.assert_allclose(q, [0, 0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)


def test_six_d_round_trip_and_gram_schmidt_of_noisy_input(rng):
    m = random_rotations(rng, (100,))
    np.testing.assert_allclose(R.sixd_to_matrix(R.matrix_to_6d(m)), m, atol=1e-12)
    noisy = R.sixd_to_matrix(R.matrix_to_6d(m) + rng.normal(0, 0.05, (100, 6)))
    np.testing.assert_allclose(noisy @ np.swapaxes(noisy, -1, -2), np.broadcast_to(np.eye(3), (100, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(noisy), 1.0, atol=1e-12)


def test_axis_angle_and_euler_agree_with_scipy(rng):
    v = rng.normal(size=(10, 3))
    np.testing.assert_allclose(R.axis_angle_to_matrix(v), Rotation.from_rotvec(v).as_matrix())
    m = random_rotations(rng, (10,))
    np.testing.assert_allclose(R.euler_to_matrix(R.matrix_to_euler(m)), m, atol=1e-10)


def test_joint_euler_order_is_intrinsic_zyx():
    yaw, pitch, roll = 0.3, -0.2, 0.5
    rz = Rotation.from_euler("z", yaw).as_matrix()
    ry = Rotation.from_euler("y", pitch).as_matrix()
    rx = Rotation.from_euler("x", roll).as_matrix()
    np.testing.assert_allclose(R.euler_to_matrix([yaw, pitch, roll]), rz @ ry @ rx, atol=1e-12)


@pytest.mark.parametrize(
    "a,b", [([1, 0, 0], [0, 1, 0]), ([0, 0, -1], [0.3, 0.1, -0.9]), ([1, 0, 0], [-1, 0, 0]), ([0, 1, 0], [0, 1, 0])]
)
def test_rotation_between_maps_a_onto_b(a, b):
    m = R.rotation_between(a, b)
    np.testing.assert_allclose(m @ (np.array(a) / np.linalg.norm(a)), np.array(b) / np.linalg.norm(b), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=1e-12)


def test_angle_between_and_heading():
    a = R.euler_to_matrix([0.4, 0, 0], "zyx")
    assert R.angle_between(np.eye(3), a) == pytest.approx(0.4)
    assert R.heading(a) == pytest.approx(0.4)
    np.testing.assert_allclose(R.yaw_matrix(0.4), a, atol=1e-12)


def test_slerp_resample_hits_source_samples_and_midpoints():
    q = R.matrix_to_quat(R.euler_to_matrix(np.array([[0, 0, 0], [0, 0, 1.0]]), "xyz"))
    out = R.slerp_resample(q, np.array([0.0, 1.0]), np.array([0.0, 0.5, 1.0]))
    assert R.angle_between(np.eye(3), R.quat_to_matrix(out[1])) == pytest.approx(0.5)
    np.testing.assert_allclose(np.abs(out[[0, 2]]), np.abs(q), atol=1e-12)


def test_the_compiled_one_pose_conversions_equal_the_batched_numpy_ones(rng):
    """One pose's conversions run compiled (core/mat3.py), a batch's in numpy: the same
    numbers within 1e-12, near-identity and half-turn rotations included."""
    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.rotations import heading, rotations_to_quat, sixd_to_matrix, yaw_matrix, yaw_matrix_of
    from sparse_body.core.skeleton import Skeleton

    m = Rotation.random(300, random_state=1).as_matrix()
    m[:20] = Rotation.from_rotvec(rng.normal(size=(20, 3)) * 1e-9).as_matrix()
    m[20:40] = Rotation.from_rotvec(np.pi * Rotation.random(20, random_state=2).as_rotvec() / 3.0).as_matrix()
    np.testing.assert_allclose(rotations_to_quat(m), rotations_to_quat(m[None])[0], rtol=0, atol=1e-12)
    d6 = rng.normal(size=(300, 6))
    np.testing.assert_allclose(sixd_to_matrix(d6), sixd_to_matrix(d6[None])[0], rtol=0, atol=1e-12)
    for r in m[::10]:
        np.testing.assert_allclose(yaw_matrix_of(r), yaw_matrix(heading(r)), rtol=0, atol=1e-12)
    offsets = Skeleton.canonical().offsets
    local, root = m[:22], rng.normal(size=3)
    batch = np.stack([local, m[22:44], m[44:66]])  # three poses: compiled as a batch
    roots = rng.normal(size=(3, 3))
    reference = forward_kinematics(batch[None], roots[None], offsets)  # (1, 3, ...): numpy's loop
    for one, numpy_way in zip(
        forward_kinematics(local, root, offsets), forward_kinematics(local[None, None], root, offsets), strict=True
    ):
        np.testing.assert_allclose(one, numpy_way[0, 0], rtol=0, atol=1e-12)
    for compiled, numpy_way in zip(forward_kinematics(batch, roots, offsets), reference, strict=True):
        np.testing.assert_allclose(compiled, numpy_way[0], rtol=0, atol=1e-12)
