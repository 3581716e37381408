"""AMASS loading against a small SMPL-like model made here (no licensed file is needed)."""

import numpy as np
import pytest

from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.core.skeleton import PARENTS
from sparse_body.data import MotionFileError
from sparse_body.data.amass import load_amass


def _model(tmp_path, rng):
    # 22 "vertices", one per joint, placed like a T-pose in SMPL axes (x left, y up, z forward).
    from sparse_body.core.skeleton import Skeleton

    ours = Skeleton.canonical().rest_positions()
    smpl = ours[:, [1, 2, 0]]  # inverse of SMPL_TO_BODY
    path = tmp_path / "model.npz"
    np.savez(
        path,
        v_template=smpl,
        shapedirs=np.zeros((22, 3, 10)),
        J_regressor=np.eye(22),
        kintree_table=np.array([PARENTS, list(range(22))]),
    )
    return path, ours


def test_amass_rest_and_elbow_bend(tmp_path, rng):
    model, ours = _model(tmp_path, rng)
    poses = np.zeros((3, 156))
    poses[1, 3 * J["left_elbow"] + 1] = np.pi / 2  # 90 degrees about SMPL y = our z (up)
    trans = np.array([[0, 0, 0.0], [0.1, 0, 0], [0, 0, 0]])
    np.savez(tmp_path / "walk_poses.npz", poses=poses, trans=trans, betas=np.zeros(16), mocap_framerate=np.array(30.0))
    m = load_amass(tmp_path / "walk_poses.npz", model, fps=None)
    assert m.fps == 30.0 and len(m) == 3 and m.name == "walk_poses"
    # SMPL's root rotation maps its y-up body into AMASS's z-up world; a zero root rotation
    # leaves the body lying in that world: our up (z) points along world y.
    np.testing.assert_allclose(m.positions[0, J["head"]] - m.positions[0, 0], ours[J["head"]][[1, 2, 0]], atol=1e-9)
    forearm = ours[J["left_wrist"]] - ours[J["left_elbow"]]
    bent = m.positions[1, J["left_wrist"]] - m.positions[1, J["left_elbow"]]
    # Elbow turned 90 degrees about our up axis: the forearm (along +y) points along -x.
    expected = np.array([-forearm[1], 0, 0])[[1, 2, 0]]
    np.testing.assert_allclose(bent, expected, atol=1e-9)
    np.testing.assert_allclose(m.root_positions[1] - m.root_positions[0], [0.1, 0, 0])


def test_amass_refuses_pickle_and_reports_missing_keys(tmp_path, rng):
    model, _ = _model(tmp_path, rng)
    with pytest.raises(MotionFileError, match="pickled model files are not loaded"):
        load_amass(tmp_path / "x.npz", tmp_path / "model.pkl")
    np.savez(tmp_path / "bad.npz", poses=np.zeros((2, 156)))
    with pytest.raises(MotionFileError, match=r"bad\.npz: lacks trans"):
        load_amass(tmp_path / "bad.npz", model)
