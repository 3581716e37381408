"""Retargeting real CMU clips onto the 22-joint body (needs ../shared/mocap)."""

import numpy as np
import pytest

from sparse_body.core.rotations import matrix_to_axis_angle
from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.data.asf_amc import load_amc, load_asf
from sparse_body.data.bvh import load_bvh
from sparse_body.data.retarget import retarget, retarget_error

pytestmark = pytest.mark.mocap

# Walking clips from each source layout (ASF/AMC of three subjects, and each BVH flavour).
CLIPS = ["02_01", "16_15", "35_01", "07_04", "131_01", "12_01"]


def _source(clip):
    if clip.format == "asf/amc":
        return load_amc(clip.path, load_asf(clip.skeleton_path), clip.fps)
    return load_bvh(clip.path)


@pytest.mark.parametrize("clip_id", CLIPS)
def test_retargeted_fk_reproduces_source_joints_within_1cm(clip_index, clip_id):
    source = _source(clip_index[clip_id])
    motion = retarget(source)
    err = retarget_error(source, motion)
    assert err.shape == (len(source.positions), 22)
    assert err.max() < 0.01, f"{clip_id}: max error {err.max() * 100:.2f} cm"


@pytest.mark.parametrize("clip_id", CLIPS)
def test_retargeted_body_is_upright_and_faces_forward(clip_index, clip_id):
    motion = retarget(_source(clip_index[clip_id]))
    rest = motion.skeleton.rest_positions()
    assert rest[J["left_hip"], 1] > 0.03 > -0.03 > rest[J["right_hip"], 1]  # left is +y
    assert rest[J["left_foot"], 0] - rest[J["left_ankle"], 0] > 0.05  # toes point +x
    assert 1.3 < motion.skeleton.height() < 2.0
    pos = motion.positions
    assert np.all(pos[:, J["head"], 2] > pos[:, J["pelvis"], 2])  # walking: head above pelvis
    assert 0.7 < np.median(pos[:, J["pelvis"], 2] - pos[:, J["left_foot"], 2]) < 1.2
    # Walking bends the knee forward: flexion is a positive rotation about +y.
    knee = matrix_to_axis_angle(motion.local_rotations[:, J["left_knee"]])
    assert np.degrees(knee[:, 1]).max() > 30 and np.degrees(knee[:, 1]).min() > -15


def test_resampling_to_60hz_keeps_positions(clip_index):
    source = _source(clip_index["02_01"])
    at_120, at_60 = retarget(source), retarget(source, fps=60.0)
    assert at_60.fps == 60.0 and len(at_60) == (len(at_120) - 1) // 2 + 1
    # Every second 120 Hz frame is a 60 Hz frame: slerp there returns the source sample.
    np.testing.assert_allclose(at_60.positions, at_120.positions[::2], atol=1e-6)
    mid = at_120.resampled(240.0)
    assert (
        np.abs(mid.positions[1::2][: len(at_120) - 1] - (at_120.positions[:-1] + at_120.positions[1:]) / 2).max() < 0.01
    )
