"""What the tests read from a /tf message: each frame placed by composing down its tree."""

from __future__ import annotations

import numpy as np

from sparse_body.core.rotations import quat_to_matrix


def tf_tree(transforms) -> dict[str, np.ndarray]:
    """Each child frame of one /tf message in the message's root frame (4, 4), composed down
    the tree (messages of rclpy and of rosbags alike)."""
    parent, local = {}, {}
    for t in transforms:
        m = np.eye(4)
        r, v = t.transform.rotation, t.transform.translation
        m[:3, :3], m[:3, 3] = quat_to_matrix(np.array([r.x, r.y, r.z, r.w])), [v.x, v.y, v.z]
        parent[t.child_frame_id], local[t.child_frame_id] = t.header.frame_id, m

    def placed(frame: str) -> np.ndarray:
        return placed(parent[frame]) @ local[frame] if frame in parent else np.eye(4)

    return {frame: placed(frame) for frame in parent}
