"""AMASS motions (.npz of SMPL / SMPL-H / SMPL-X parameters) for users who have AMASS and
an SMPL-family model file. Nothing licensed is shipped: the user gives both paths.

The model file must be a .npz (as distributed with AMASS, e.g. smplh/neutral/model.npz)
holding v_template, shapedirs and J_regressor; pickled .pkl models are refused because
weights are never loaded with pickle here.

SMPL's body frame is x left, y up, z forward; AMASS worlds are z-up. Body joints 0-21 of
SMPL are our 22 joints in the same order, so only the basis changes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.rotations import axis_angle_to_matrix, matrix_to_quat
from ..core.skeleton import NUM_JOINTS, PARENTS, Skeleton
from . import MotionFileError
from .motion import Motion
from .source import stem

# Our axes from SMPL's: x_ours = z_smpl (forward), y_ours = x_smpl (left), z_ours = y_smpl (up).
SMPL_TO_BODY = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _load_npz(path: Path, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    path = Path(path)
    if path.suffix == ".pkl":
        raise MotionFileError(path, "pickled model files are not loaded; use the .npz version of the model")
    from ..core.textfile import NPZ_ERRORS, FileTooLarge, open_npz, too_large

    try:
        with open_npz(path) as z:
            missing = [k for k in keys if k not in z.files]
            if missing:
                raise MotionFileError(path, f"lacks {', '.join(missing)}")
            return {k: z[k] for k in z.files if k in keys or k in ("betas", "mocap_framerate", "mocap_frame_rate")}
    except FileTooLarge as err:
        raise too_large(MotionFileError)(path, str(err).removeprefix(f"{path}: ")) from None
    except NPZ_ERRORS as err:
        raise MotionFileError(path, f"not a readable .npz, or damaged ({err})") from None


def smpl_rest_joints(model_path: Path, betas: np.ndarray | None) -> np.ndarray:
    """(22, 3) rest joint positions of the shaped model, in SMPL's body frame."""
    model = _load_npz(model_path, ("v_template", "shapedirs", "J_regressor"))
    verts = model["v_template"].astype(np.float64)
    if betas is not None and len(betas):
        shapedirs = model["shapedirs"]
        n = min(len(betas), shapedirs.shape[-1])
        verts = verts + shapedirs[..., :n] @ np.asarray(betas[:n], dtype=np.float64)
    joints = np.asarray(model["J_regressor"], dtype=np.float64) @ verts
    if joints.shape[0] < NUM_JOINTS:
        raise MotionFileError(model_path, f"J_regressor gives {joints.shape[0]} joints, need {NUM_JOINTS}")
    return joints[:NUM_JOINTS]


def load_amass(motion_path: Path, model_path: Path, fps: float | None = 60.0) -> Motion:
    motion_path, model_path = Path(motion_path), Path(model_path)
    if model_path.suffix == ".pkl":  # say so before reading anything else
        raise MotionFileError(model_path, "pickled model files are not loaded; use the .npz version of the model")
    data = _load_npz(motion_path, ("poses", "trans"))
    poses, trans = data["poses"].astype(np.float64), data["trans"].astype(np.float64)
    if poses.ndim != 2 or poses.shape[1] < NUM_JOINTS * 3 or trans.shape != (len(poses), 3):
        raise MotionFileError(motion_path, f"poses {poses.shape} / trans {trans.shape} are not (T, >=66) / (T, 3)")
    if not (np.all(np.isfinite(poses)) and np.all(np.isfinite(trans))):
        raise MotionFileError(motion_path, "non-finite values")
    rate = data.get("mocap_framerate", data.get("mocap_frame_rate"))
    if rate is None:
        raise MotionFileError(motion_path, "no mocap_framerate")
    rest = smpl_rest_joints(model_path, data.get("betas"))

    offsets = np.zeros((NUM_JOINTS, 3))
    for j in range(1, NUM_JOINTS):
        offsets[j] = SMPL_TO_BODY @ (rest[j] - rest[PARENTS[j]])
    rot = axis_angle_to_matrix(poses[:, : NUM_JOINTS * 3].reshape(len(poses), NUM_JOINTS, 3))
    local = SMPL_TO_BODY @ rot @ SMPL_TO_BODY.T
    # The root rotation maps SMPL's body frame into the (z-up) world: undo the basis change
    # on the body side only.
    local[:, 0] = rot[:, 0] @ SMPL_TO_BODY.T
    root = trans + rest[0]
    motion = Motion(stem(motion_path), float(rate), Skeleton(offsets), matrix_to_quat(local), root)
    return motion if fps is None else motion.resampled(fps)
