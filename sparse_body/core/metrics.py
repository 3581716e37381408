"""The papers' metrics, on arrays of one sequence.

Positions are (T, 22, 3) metres, rotations (T, 22, 3, 3). Units follow the papers' tables:
centimetres, degrees, cm/s, and Jitter in 100 m/s^3 (AvatarPoser, AvatarJLM).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .contacts import FOOT_JOINTS
from .rotations import angle_between
from .skeleton import HANDS, JOINT_NAMES, LOWER_BODY, UPPER_BODY, joint_indices

LOWER = joint_indices(LOWER_BODY)
UPPER = joint_indices(UPPER_BODY)
HAND = joint_indices(HANDS)


def _sel(x: np.ndarray, joints) -> np.ndarray:
    return x if joints is None else x[:, list(joints)]


def mpjpe(pred_pos, gt_pos, joints=None) -> float:
    """Mean per-joint position error, cm."""
    return float(np.linalg.norm(_sel(pred_pos, joints) - _sel(gt_pos, joints), axis=-1).mean() * 100)


def mpjre(pred_rot, gt_rot, joints=None) -> float:
    """Mean per-joint rotation error (geodesic angle), degrees."""
    return float(np.rad2deg(angle_between(_sel(pred_rot, joints), _sel(gt_rot, joints))).mean())


def mpjre_axis_angle(pred_rot, gt_rot, joints=None) -> float:
    """Rotation error as the AvatarPoser family's evaluation code has it (AvatarPoser, AGRoL,
    AvatarJLM: their papers' MPJRE): both rotations as axis-angle vectors, their difference
    per component wrapped into [-180, 180) degrees, the mean absolute component. For a turn
    about one axis it is a third of the geodesic angle (mpjre), so it comes out smaller."""
    from scipy.spatial.transform import Rotation

    pred, gt = _sel(np.asarray(pred_rot), joints), _sel(np.asarray(gt_rot), joints)
    a = Rotation.from_matrix(pred.reshape(-1, 3, 3)).as_rotvec()
    b = Rotation.from_matrix(gt.reshape(-1, 3, 3)).as_rotvec()
    diff = (b - a + np.pi) % (2 * np.pi) - np.pi
    return float(np.rad2deg(np.abs(diff)).mean())


def mpjve(pred_pos, gt_pos, fps: float, joints=None) -> float:
    """Mean per-joint velocity error, cm/s."""
    if len(pred_pos) < 2:
        return float("nan")
    dv = np.diff(_sel(pred_pos, joints), axis=0) - np.diff(_sel(gt_pos, joints), axis=0)
    return float(np.linalg.norm(dv, axis=-1).mean() * fps * 100)


def jitter(pos, fps: float, joints=None) -> float:
    """Mean jerk (third derivative of position) magnitude, 100 m/s^3."""
    if len(pos) < 4:
        return float("nan")
    jerk = np.diff(_sel(pos, joints), n=3, axis=0) * fps**3
    return float(np.linalg.norm(jerk, axis=-1).mean() / 100)


def ground_penetration(pos, floor: float) -> float:
    """Mean depth (cm) of the lower toe below the floor, 0 for frames above it."""
    lowest = pos[:, FOOT_JOINTS, 2].min(axis=1)
    return float(np.maximum(floor - lowest, 0.0).mean() * 100)


def foot_skate(pos, contacts, fps: float) -> float:
    """Mean horizontal toe speed (cm/s) over the frames where that foot is in contact.

    contacts: (T, 2) booleans (ground-truth labels, so every method is judged on the same
    frames). NaN when no frame is in contact."""
    if len(pos) < 2:
        return float("nan")
    toes = pos[:, FOOT_JOINTS, :2]
    speed = np.linalg.norm(np.diff(toes, axis=0), axis=-1) * fps
    mask = contacts[1:] & contacts[:-1]
    return float(speed[mask].mean() * 100) if mask.any() else float("nan")


def contact_accuracy(pred_contacts, gt_contacts) -> float:
    """Share of (frame, foot) contact states predicted right, percent."""
    return float((np.asarray(pred_contacts) == np.asarray(gt_contacts)).mean() * 100)


def sequence_metrics(
    pred_pos,
    pred_glob,
    pred_local,
    gt_pos,
    gt_glob,
    gt_local,
    fps: float,
    floor: float,
    gt_contacts,
    pred_contacts=None,
    tracked_joints=(),
) -> dict[str, float]:
    """Every metric of one sequence, keyed by the names used in the tables."""
    out = {
        "MPJPE [cm]": mpjpe(pred_pos, gt_pos),
        "MPJRE [deg]": mpjre(pred_local, gt_local),  # geodesic angle of the local rotations
        "MPJRE-AA [deg]": mpjre_axis_angle(pred_local, gt_local),  # AvatarPoser / AvatarJLM code's definition
        "MPJRE-global [deg]": mpjre(pred_glob, gt_glob),  # geodesic angle of the global rotations
        "MPJVE [cm/s]": mpjve(pred_pos, gt_pos, fps),
        "Jitter [100m/s3]": jitter(pred_pos, fps),
        "Hand PE [cm]": mpjpe(pred_pos, gt_pos, HAND),
        "Upper PE [cm]": mpjpe(pred_pos, gt_pos, UPPER),
        "Lower PE [cm]": mpjpe(pred_pos, gt_pos, LOWER),
        "Root PE [cm]": mpjpe(pred_pos, gt_pos, [0]),
        "Lower RE [deg]": mpjre(pred_local, gt_local, LOWER),
        "Toe PE [cm]": mpjpe(pred_pos, gt_pos, FOOT_JOINTS),
        "End-effector PE [cm]": mpjpe(pred_pos, gt_pos, tracked_joints) if len(tracked_joints) else float("nan"),
        "Ground [cm]": ground_penetration(pred_pos, floor),
        "Skate [cm/s]": foot_skate(pred_pos, gt_contacts, fps),
        "Contact acc [%]": contact_accuracy(pred_contacts, gt_contacts) if pred_contacts is not None else float("nan"),
    }
    return out


def per_joint_metrics(pred_pos, gt_pos, pred_local, gt_local) -> dict[str, float]:
    """Each joint's position and rotation error (local rotation, as MPJRE), keyed
    "PE <joint> [cm]" and "RE <joint> [deg]": where a method's error sits. Their means over the
    joints are MPJPE and MPJRE."""
    pe = np.linalg.norm(pred_pos - gt_pos, axis=-1).mean(axis=0) * 100
    re = np.rad2deg(angle_between(pred_local, gt_local)).mean(axis=0)
    return {
        **{f"PE {name} [cm]": float(e) for name, e in zip(JOINT_NAMES, pe, strict=True)},
        **{f"RE {name} [deg]": float(e) for name, e in zip(JOINT_NAMES, re, strict=True)},
    }


# the settle time's band above a joint's usual error (metres), and how long it must stay in it
SETTLE_BAND, SETTLE_HOLD = 0.02, 0.1
RECOVERY_SECONDS = 0.5  # after a tracker returns, how long its joint is watched for a jump


def loss_metrics(pred_pos, gt_pos, lost: np.ndarray, joints, fps: float) -> dict[str, float]:
    """What a user sees when a tracker drops out of view and returns (lost: (T, S) frames each
    site was out of view; joints: each site's joint). "Lost PE": the sites' joints' error while
    out of view. "Recovery jump": the largest step of such a joint within RECOVERY_SECONDS after
    its tracker returns, beyond the true joint's own step (a hand that snaps back). "Settle
    time": the mean time from a return until the joint's error is back within SETTLE_BAND of
    its usual level (its median error in view) and stays there SETTLE_HOLD seconds; a return
    that never settles before the next loss or the clip's end counts the time it had. NaN where
    nothing was lost, or nothing returned."""
    err, jumps, settle = [], [], []
    window, hold = max(1, round(RECOVERY_SECONDS * fps)), max(1, round(SETTLE_HOLD * fps))
    for s, j in enumerate(joints):
        out = lost[:, s]
        if not out.any():
            continue
        error = np.linalg.norm(pred_pos[:, j] - gt_pos[:, j], axis=-1)
        err.append(error[out])
        step = np.linalg.norm(np.diff(pred_pos[:, j], axis=0), axis=-1)
        true_step = np.linalg.norm(np.diff(gt_pos[:, j], axis=0), axis=-1)
        usual = np.median(error[~out]) if (~out).any() else 0.0
        # settled[k]: frames k .. k + hold - 1 all within the band
        within = (error <= usual + SETTLE_BAND).astype(int)
        settled = np.convolve(within, np.ones(hold, dtype=int), "valid") == hold
        starts = np.flatnonzero(~out[:-1] & out[1:]) + 1  # the first frame of each loss
        for r in np.flatnonzero(out[:-1] & ~out[1:]) + 1:  # the first frame back in view
            span = slice(r - 1, min(r - 1 + window, len(step)))  # step[r - 1] moves into frame r
            jumps.append(float(np.max(step[span] - true_step[span])))
            end = next((k for k in starts if k > r), len(error))  # the next loss, or the end
            found = np.flatnonzero(settled[r : max(r, end - hold + 1)])
            settle.append((found[0] if len(found) else end - r) / fps)
    return {
        "Lost PE [cm]": float(np.concatenate(err).mean() * 100) if err else float("nan"),
        "Recovery jump [cm]": max(jumps) * 100 if jumps else float("nan"),
        "Settle time [s]": float(np.mean(settle)) if settle else float("nan"),
    }


def weighted_mean(rows: list[dict[str, float]], weights: Sequence[float]) -> dict[str, float]:
    """Frame-weighted mean of per-sequence metrics, ignoring NaN entries."""
    out = {}
    for key in rows[0]:
        vals = np.array([r[key] for r in rows], dtype=float)
        w = np.array(weights, dtype=float)
        ok = np.isfinite(vals)
        out[key] = float(np.sum(vals[ok] * w[ok]) / np.sum(w[ok])) if ok.any() else float("nan")
    return out
