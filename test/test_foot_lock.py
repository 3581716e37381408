"""foot_lock (estimators/base.py, core/contact_hold.py): every estimator's feet held where
they touched down while its own contacts say so."""

import numpy as np
import pytest

from sparse_body.core.contacts import FOOT_JOINTS
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import Skeleton
from sparse_body.data.field_protocol import FIELD
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.evaluation import estimate_motion, score
from sparse_body.methods.factory import create_estimator


def test_a_locked_foot_stays_where_it_touched_down_while_in_contact():
    motion, sensors = synthetic_walk(6.0), load_sensor_config("six_point")
    plain = estimate_motion(motion, "ik", sensors, FIELD, foot_lock=False)
    locked = estimate_motion(motion, "ik", sensors, FIELD, foot_lock=True)
    assert np.array_equal(plain.contacts, locked.contacts)  # the method's own contacts, unchanged
    held = 0
    for side, toe in enumerate(FOOT_JOINTS):
        on = locked.contacts[:, side]
        both = on[1:] & on[:-1]  # frame to frame within one contact
        steps = np.linalg.norm(np.diff(locked.positions[:, toe], axis=0), axis=1)[both]
        held += both.sum()
        # mostly held to the micrometre; where the leg cannot reach its point it is let go
        assert (steps < 1e-6).mean() > 0.8, np.percentile(steps, [50, 80, 95])
    assert held > 60  # a walk plants each foot for many frames
    assert score(locked)["Skate [cm/s]"] < 0.2 * score(plain)["Skate [cm/s]"]


def test_foot_lock_takes_true_or_false():
    sensors, skeleton = load_sensor_config("four_point"), Skeleton.canonical(1.75)
    assert create_estimator("ik", sensors, skeleton).foot_lock is not None  # on by default
    assert create_estimator("ik", sensors, skeleton, foot_lock=False).foot_lock is None
    # LoBSTr's own contact IK holds its feet: not a second time, unless that is off
    assert create_estimator("lobstr", sensors, skeleton).foot_lock is None
    assert create_estimator("lobstr", sensors, skeleton, contact_ik=False).foot_lock is not None
    with pytest.raises(ValueError, match="foot_lock must be true or false"):
        create_estimator("ik", sensors, skeleton, foot_lock="yes")
