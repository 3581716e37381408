import numpy as np
import pytest
from conftest import random_rotations

from sparse_body.core.kinematics import forward_kinematics, global_to_local
from sparse_body.core.rotations import euler_to_matrix
from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.core.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS, Skeleton, joint_indices


def test_topology_is_smpl_body():
    assert NUM_JOINTS == 22 and len(PARENTS) == 22
    assert JOINT_NAMES[:4] == ("pelvis", "left_hip", "right_hip", "spine1")
    assert all(PARENTS[j] < j for j in range(1, 22))
    assert PARENTS[J["left_wrist"]] == J["left_elbow"] and PARENTS[J["head"]] == J["neck"]


def test_canonical_rest_pose_is_a_t_pose_facing_x():
    rest = Skeleton.canonical().rest_positions()
    assert rest[J["left_wrist"], 1] > 0.6 and rest[J["right_wrist"], 1] < -0.6  # arms along +-y
    assert rest[J["head"], 2] > 0.4 and rest[J["left_ankle"], 2] < -0.8  # z up
    assert rest[J["left_foot"], 0] > rest[J["left_ankle"], 0] + 0.1  # toes forward (+x)


def test_height_scaling():
    s = Skeleton.canonical()
    assert s.height() == pytest.approx(1.75, abs=0.01)
    tall = Skeleton.canonical(1.90)
    assert tall.height() == pytest.approx(1.90)
    np.testing.assert_allclose(tall.offsets, s.offsets * 1.90 / s.height())
    with pytest.raises(ValueError, match="height"):
        s.with_height(7.0)
    with pytest.raises(ValueError, match="finite"):
        Skeleton(np.full((22, 3), np.nan))
    with pytest.raises(ValueError, match="unknown joint 'knee'"):
        joint_indices(["knee"])


def test_fk_hand_computed_elbow_bend():
    s = Skeleton.canonical()
    local = np.tile(np.eye(3), (22, 1, 1))
    # Bend the left elbow 90 degrees about +z: the forearm (along +y) turns to -x.
    local[J["left_elbow"]] = euler_to_matrix([0, 0, np.pi / 2], "xyz")
    root = np.array([1.0, 2.0, 0.9])
    _, pos = forward_kinematics(local, root, s.offsets)
    rest = s.rest_positions() + root
    np.testing.assert_allclose(pos[J["left_elbow"]], rest[J["left_elbow"]], atol=1e-12)
    forearm = s.offsets[J["left_wrist"]][1]
    np.testing.assert_allclose(pos[J["left_wrist"]], rest[J["left_elbow"]] + [-forearm, 0, 0], atol=1e-12)
    np.testing.assert_allclose(pos[J["right_wrist"]], rest[J["right_wrist"]], atol=1e-12)


@pytest.mark.train
def test_numpy_and_torch_fk_agree(rng):
    import torch

    from sparse_body.train import torch_body

    s = Skeleton.canonical(1.6)
    local = random_rotations(rng, (8, 22))
    root = rng.normal(size=(8, 3))
    g_np, p_np = forward_kinematics(local, root, s.offsets)
    g_t, p_t = torch_body.forward_kinematics(
        torch.from_numpy(local), torch.from_numpy(root), torch.from_numpy(s.offsets)
    )
    np.testing.assert_allclose(g_t.numpy(), g_np, atol=1e-6)
    np.testing.assert_allclose(p_t.numpy(), p_np, atol=1e-6)
    np.testing.assert_allclose(global_to_local(g_np), local, atol=1e-10)


@pytest.mark.train
def test_torch_rotation_helpers_match_numpy(rng):
    import torch

    from sparse_body.core.rotations import matrix_to_6d, matrix_to_quat, sixd_to_matrix
    from sparse_body.train import torch_body

    m = random_rotations(rng, (16,))
    d6 = matrix_to_6d(m) + rng.normal(0, 0.1, (16, 6))
    np.testing.assert_allclose(torch_body.sixd_to_matrix(torch.from_numpy(d6)).numpy(), sixd_to_matrix(d6), atol=1e-6)
    np.testing.assert_allclose(torch_body.quat_to_matrix(torch.from_numpy(matrix_to_quat(m))).numpy(), m, atol=1e-6)
