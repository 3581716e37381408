"""foot_lock (estimators/base.py, core/contact_hold.py): every estimator's feet held where
they touched down while its own contacts say so."""

import numpy as np
import pytest

from sparse_body.core.contacts import FOOT_JOINTS
from sparse_body.core.kinematics import forward_kinematics
from sparse_body.core.rotations import quat_to_matrix
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import Skeleton
from sparse_body.data.field_protocol import FIELD
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import synthesize_trackers
from sparse_body.evaluation import estimate_motion, score
from sparse_body.methods.factory import create_estimator, feet_tracked


def test_a_locked_foot_stays_where_it_touched_down_while_in_contact():
    # six-point IK's legs walk like the walk's, so its toe contacts are the walk's steps; the
    # factory never holds tracked feet (below), so the hold is turned on by hand here
    motion, sensors = synthetic_walk(6.0), load_sensor_config("six_point")
    stream = synthesize_trackers(motion, sensors, FIELD.noise, seed=1)
    runs = {}
    for on in (False, True):
        est = create_estimator("ik", sensors, motion.skeleton, fps=motion.fps, foot_lock=False)
        est.use_foot_lock(on)
        poses = est.process(stream)
        local = quat_to_matrix(np.stack([p.local_quats for p in poses]))
        _, pos = forward_kinematics(local, np.stack([p.root_position for p in poses]), motion.skeleton.offsets)
        runs[on] = pos, np.stack([p.contact for p in poses])
    (plain, contacts), (locked, locked_contacts) = runs[False], runs[True]
    assert np.array_equal(contacts, locked_contacts)  # the method's own contacts, unchanged
    held = 0
    for side, toe in enumerate(FOOT_JOINTS):
        both = contacts[1:, side] & contacts[:-1, side]  # frame to frame within one contact
        steps = np.linalg.norm(np.diff(locked[:, toe], axis=0), axis=1)[both]
        free = np.linalg.norm(np.diff(plain[:, toe], axis=0), axis=1)[both]
        held += both.sum()
        # mostly held to the micrometre; where the leg cannot reach its point it is let go
        assert (steps < 1e-6).mean() > 0.8, np.percentile(steps, [50, 80, 95])
        assert steps.sum() < 0.5 * free.sum()  # (the rest: a lifted foot let go over release_frames)
    assert held > 60  # a walk plants each foot for many frames


def test_tracked_feet_are_never_held():
    motion = synthetic_walk(2.0)
    for name, held in (("six_point", False), ("four_point_foot_imus", False), ("four_point", True)):
        sensors = load_sensor_config(name)  # (a hold would turn an IMU's ankle off what it measures)
        assert feet_tracked(sensors) is not held
        assert (create_estimator("ik", sensors, motion.skeleton).foot_lock is not None) is held
        assert create_estimator("ik", sensors, motion.skeleton, foot_lock=False).foot_lock is None
    six = load_sensor_config("six_point")
    np.testing.assert_equal(  # (NaN where a figure has no frame)
        score(estimate_motion(motion, "ik", six, FIELD)),
        score(estimate_motion(motion, "ik", six, FIELD, foot_lock=False)),
    )


def test_foot_lock_takes_true_or_false():
    sensors, skeleton = load_sensor_config("four_point"), Skeleton.canonical(1.75)
    assert create_estimator("ik", sensors, skeleton).foot_lock is not None  # on by default
    assert create_estimator("ik", sensors, skeleton, foot_lock=False).foot_lock is None
    # LoBSTr's own contact IK holds its feet: not a second time, unless that is off
    assert create_estimator("lobstr", sensors, skeleton).foot_lock is None
    assert create_estimator("lobstr", sensors, skeleton, contact_ik=False).foot_lock is not None
    with pytest.raises(ValueError, match="foot_lock takes true or false"):
        create_estimator("ik", sensors, skeleton, foot_lock="yes")
