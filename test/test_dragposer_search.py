"""DragPoser's compiled search (methods/dragposer/search.py) against the ONNX Runtime search it
replaced and the constraint classes it packs: same residuals, same decoder, same poses."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sparse_body.core.kinematics import forward_kinematics
from sparse_body.core.resources import models_dir
from sparse_body.core.rotations import quat_to_matrix
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import Skeleton
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import synthesize_trackers
from sparse_body.methods.dragposer.constraints import (
    AboveFloor,
    AngleLimit,
    ConstraintSet,
    LookAt,
    Orientation,
    OverPoint,
    Position,
)
from sparse_body.methods.dragposer.estimator import PoseVaeRuntime
from sparse_body.methods.dragposer.search import (
    CompiledSearch,
    _residual,
    decode_jacobian,
    decode_sixd,
    mlp_weights,
    pack,
)
from sparse_body.methods.factory import create_estimator


@pytest.fixture(scope="module")
def vae():
    return PoseVaeRuntime(models_dir())


def _pose(rng):
    local = Rotation.from_rotvec(rng.normal(0, 0.6, (22, 3))).as_matrix()
    glob, pos = forward_kinematics(local, rng.normal(0, 0.5, 3), Skeleton.canonical().offsets)
    return local, glob, pos


def test_packed_constraints_give_the_residuals_of_the_constraint_classes(rng):
    for _ in range(20):
        local, glob, pos = _pose(rng)
        _, target_glob, target_pos = _pose(rng)
        constraints = ConstraintSet()
        constraints.add(Position("left_wrist", 1.5, target=tuple(target_pos[20])))
        constraints.add(OverPoint("pelvis", 0.3, target=(0.2, -0.1)))
        constraints.add(Orientation("head", 0.3, target=target_glob[15]))
        constraints.add(AboveFloor("left_foot", 1.0, height=float(pos[10, 2]) + rng.normal(0, 0.1)))
        constraints.add(LookAt("head", 0.5, target=tuple(rng.normal(0, 2, 3)), axis=(0.0, 0.6, 0.8)))
        constraints.add(AngleLimit("left_knee", 2.0, max_angle=float(rng.uniform(0, 1.5))))
        ours = np.empty(3 + 2 + 3 + 1 + 3 + 1)
        _residual(*pack(constraints), local, glob, pos, ours)
        np.testing.assert_allclose(ours, constraints.residual(glob, pos, local), atol=1e-12)


def test_the_decoder_in_numba_is_the_onnx_decoder_and_its_jacobian_its_derivative(vae, rng):
    weights = mlp_weights(vae.dir / "dragposer_decoder.onnx")
    assert weights is not None
    search = CompiledSearch(weights, Skeleton.canonical().offsets, Skeleton.canonical().parents)
    zs = rng.normal(0, 1.0, (8, 24))
    ours = np.array([search.pose(z, np.zeros(3), 0.0)[0] for z in zs])
    np.testing.assert_allclose(ours, vae.decode(zs), atol=2e-5)  # ONNX Runtime runs in float32
    z, h = zs[0], 1e-5
    jac = decode_jacobian(z, *weights)
    central = np.stack(
        [(decode_sixd(z + h * e, *weights) - decode_sixd(z - h * e, *weights)) / (2 * h) for e in np.eye(24)], -1
    )
    np.testing.assert_allclose(jac, central, atol=1e-6 * np.abs(central).max())
    assert np.abs(jac).max() > 1e-3  # a derivative, not zeros


def test_graphs_that_are_not_the_decoder_mlp_are_left_to_onnx_runtime(vae):
    assert mlp_weights(vae.dir / "dragposer_encoder.onnx") is None  # its input is not the latent
    assert mlp_weights(vae.dir / "dragposer_temporal.onnx") is None


@pytest.mark.parametrize("sensors", ["six_point", "four_point"])
def test_the_compiled_search_lands_where_the_onnx_runtime_search_does(sensors):
    motion = synthetic_walk(4.0)
    config = load_sensor_config(sensors)
    stream = synthesize_trackers(motion, config, seed=3)
    positions, used = {}, {}
    for compiled in (True, False):
        est = create_estimator("dragposer", config, motion.skeleton, compiled=compiled)
        assert (est.search is not None) == compiled
        poses = est.process(stream)
        positions[compiled] = np.array(
            [
                forward_kinematics(quat_to_matrix(p.local_quats), p.root_position, motion.skeleton.offsets)[1]
                for p in poses
            ]
        )
        used[compiled] = est.iterations_used
    gap = np.linalg.norm(positions[True] - positions[False], axis=-1)
    assert gap.mean() < 0.001 and gap.max() < 0.02, (gap.mean(), gap.max())  # metres
    assert abs(np.mean(used[True]) - np.mean(used[False])) < 0.1  # the same stopping rule


def test_the_search_ends_where_its_jacobian_predicts_the_next_step_to_barely_help():
    """cost_tolerance: one step a frame on a walk where the budget allows three, and poses
    that differ from the three steps' by a tenth of a degree."""
    motion = synthetic_walk(3.0)
    config = load_sensor_config("four_point")
    stream = synthesize_trackers(motion, config, seed=4)
    runs = {}
    for tolerance in (0.0, 1e-3):
        est = create_estimator("dragposer", config, motion.skeleton, cost_tolerance=tolerance)
        poses = est.process(stream)
        runs[tolerance] = (np.array([p.local_quats for p in poses]), np.mean(est.iterations_used[1:]))
    assert runs[0.0][1] == 3  # without the rule: every step the budget allows
    assert runs[1e-3][1] < 1.2  # with it: most frames stop after the first
    a, b = runs[0.0][0], runs[1e-3][0]
    angle = 2 * np.degrees(np.arccos(np.clip(np.abs((a * b).sum(-1)), 0, 1)))
    assert np.median(angle) < 0.1 and angle.max() < 5.0, (np.median(angle), angle.max())
