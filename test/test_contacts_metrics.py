"""Contact labels and every metric on hand-computed cases."""

import numpy as np
import pytest

from sparse_body.core import metrics as M
from sparse_body.core.contacts import contact_labels, estimate_floor, toe_speeds
from sparse_body.core.rotations import euler_to_matrix
from sparse_body.core.skeleton import JOINT_INDEX as J

LF, RF = J["left_foot"], J["right_foot"]


def _still(T=10):
    return np.zeros((T, 22, 3))


def test_contact_labels_from_height_and_speed():
    pos = _still(6)
    pos[:, RF, 2] = [0.0, 0.0, 0.1, 0.1, 0.0, 0.0]  # right foot lifted in frames 2-3
    pos[:, LF, 0] = np.arange(6) * 0.01  # left toe slides 1 cm/frame = 0.6 m/s at 60 Hz
    labels = contact_labels(pos, fps=60.0)
    np.testing.assert_array_equal(labels[:, 0], False)
    # frame 3 is still but 10 cm up; frames 2 and 4 move 6 m/s up and down
    np.testing.assert_array_equal(labels[:, 1], [True, True, False, False, False, True])
    assert toe_speeds(pos, 60.0)[3, 0] == pytest.approx(0.6)
    assert estimate_floor(pos) == pytest.approx(0.0)


def test_contact_labels_follow_a_floor_that_drifts_through_the_take_and_leave_a_raised_foot_out():
    fps, T = 60.0, 600  # ten seconds
    pos = _still(T)
    pos[:, [LF, RF], 2] = np.linspace(0.0, 0.045, T)[:, None]  # the floor rises 4.5 cm (CMU's walks drift so)
    pos[300:, RF, 2] += 0.12  # from 5 s the right foot is held still 12 cm up: a balance on one leg
    labels = contact_labels(pos, fps)
    assert labels[:, 0].all()  # the standing foot, though 2.5 cm over the take's lowest toe by 5 s
    assert labels[:300, 1].all() and not labels[301:, 1].any()
    first_version = (pos[:, [LF, RF], 2] - estimate_floor(pos) < 0.02).mean()  # one floor, 2 cm: what it missed
    assert first_version < 0.5


def test_position_velocity_and_jitter_errors():
    gt = _still(4)
    pred = gt.copy()
    pred[:, :, 0] += 0.03  # 3 cm everywhere
    assert M.mpjpe(pred, gt) == pytest.approx(3.0)
    pred[:, J["left_wrist"], 1] += 0.04  # left hand 5 cm off
    assert M.mpjpe(pred, gt, M.HAND) == pytest.approx(4.0)
    moving = gt.copy()
    moving[:, 0, 0] = np.arange(4) * 0.01  # root moves 1 cm/frame
    assert M.mpjve(moving, gt, fps=10) == pytest.approx(10.0 / 22)  # 10 cm/s on one joint of 22
    jerky = _still(5)
    jerky[:, 0, 2] = [0, 0, 0, 0.001, 0]  # one bump
    jerk = np.abs(np.diff(jerky[:, 0, 2], n=3)) * 10**3  # m/s^3 at 10 fps
    assert M.jitter(jerky, fps=10, joints=[0]) == pytest.approx(jerk.mean() / 100)


def test_rotation_errors():
    gt = np.tile(np.eye(3), (2, 22, 1, 1))
    pred = gt.copy()
    pred[:, J["left_knee"]] = euler_to_matrix([0, np.deg2rad(22), 0], "xyz")
    assert M.mpjre(pred, gt) == pytest.approx(1.0)
    assert M.mpjre(pred, gt, M.LOWER) == pytest.approx(22 / 8)


def test_the_axis_angle_definition_of_the_avatarposer_family_beside_the_geodesic_one():
    from scipy.spatial.transform import Rotation

    def about_x(angles):  # (T, 22, 3, 3): every joint turned by angles[t] about x
        return np.broadcast_to(
            Rotation.from_rotvec(np.outer(angles, [1.0, 0.0, 0.0])).as_matrix()[:, None], (len(angles), 22, 3, 3)
        )

    turned, still = about_x(np.full(4, np.deg2rad(30.0))), about_x(np.zeros(4))
    assert M.mpjre(turned, still) == pytest.approx(30.0)
    assert M.mpjre_axis_angle(turned, still) == pytest.approx(10.0)  # 30 degrees on one of three components
    # 174 degrees about +x against 174 about -x: the components differ by 348 degrees, which
    # wraps to 12, as does the geodesic angle between them
    a, b = about_x(np.full(2, np.deg2rad(174.0))), about_x(np.full(2, -np.deg2rad(174.0)))
    assert M.mpjre(a, b) == pytest.approx(12.0) and M.mpjre_axis_angle(a, b) == pytest.approx(4.0)


def test_ground_skate_and_contact_accuracy():
    pos = _still(3)
    pos[:, LF, 2] = [-0.02, 0.0, 0.05]
    pos[:, RF, 2] = 0.1
    assert M.ground_penetration(pos, floor=0.0) == pytest.approx(2 / 3)  # 2 cm in one of three frames
    pos[:, LF, 0] = [0.0, 0.01, 0.03]
    contacts = np.array([[True, False], [True, False], [True, False]])
    # Left toe moves 1 then 2 cm between contact frames at 10 fps: 10 and 20 cm/s.
    assert M.foot_skate(pos, contacts, fps=10) == pytest.approx(15.0)
    assert np.isnan(M.foot_skate(pos, np.zeros((3, 2), bool), fps=10))
    assert M.contact_accuracy([[1, 0], [1, 1]], [[1, 0], [0, 1]]) == pytest.approx(75.0)


def test_weighted_mean_skips_nan():
    rows = [{"a": 1.0, "b": float("nan")}, {"a": 4.0, "b": 2.0}]
    out = M.weighted_mean(rows, [1, 2])
    assert out["a"] == pytest.approx(3.0) and out["b"] == pytest.approx(2.0)


def test_a_hand_that_snaps_back_when_its_tracker_returns_is_measured_by_its_jump():
    T = 120
    gt = np.zeros((T, 22, 3))
    gt[:, :, 0] = 0.01 * np.arange(T)[:, None]  # everything walks 1 cm a frame
    pred = gt.copy()
    lost = np.zeros((T, 1), dtype=bool)
    lost[40:60] = True
    hand = J["left_wrist"]
    pred[40:60, hand] = gt[39, hand]  # held where it was last seen: 1 to 20 cm behind
    out = M.loss_metrics(pred, gt, lost, [hand], fps=60.0)
    assert out["Lost PE [cm]"] == pytest.approx(np.mean(np.arange(1, 21)))
    # back in view at frame 60: from 20 cm behind to the truth, 21 cm in one frame where the truth moved 1
    assert out["Recovery jump [cm]"] == pytest.approx(20.0)
    assert out["Settle time [s]"] == 0.0  # back on the truth at once
    nothing = M.loss_metrics(pred, gt, np.zeros((T, 1), dtype=bool), [hand], fps=60.0)
    assert np.isnan(nothing["Lost PE [cm]"]) and np.isnan(nothing["Recovery jump [cm]"])
    assert np.isnan(nothing["Settle time [s]"])


def test_the_settle_time_is_how_long_a_returned_hand_takes_to_come_back_to_its_usual_error():
    """A hand 1 cm off in view; held 20 cm off while lost and for a while after its return, it
    closes the gap by 1 cm a frame from frame 70: within 2 cm of its usual 1 cm once 2.5 cm off
    (frame 87), which it stays: 27 frames after the return at frame 60. A second return that
    never settles before the clip ends counts the time it had."""
    T, fps, hand = 200, 60.0, J["left_wrist"]
    gt = np.zeros((T, 22, 3))
    pred = gt.copy()
    pred[:, hand, 0] = 0.01
    lost = np.zeros((T, 1), dtype=bool)
    lost[40:60] = True
    pred[40:70, hand, 0] = 0.20
    pred[70:90, hand, 0] = 0.195 - 0.01 * np.arange(20)
    pred[90:, hand, 0] = 0.01
    out = M.loss_metrics(pred, gt, lost, [hand], fps=fps)
    assert out["Settle time [s]"] == pytest.approx(27 / fps)
    lost[150:180] = True
    pred[150:, hand, 0] = 0.20  # lost again, and never back
    out = M.loss_metrics(pred, gt, lost, [hand], fps=fps)
    assert out["Settle time [s]"] == pytest.approx((27 / fps + (T - 180) / fps) / 2)


def test_live_contacts_change_only_once_the_rule_has_held_for_50_ms():
    from sparse_body.core.contacts import LIVE_SPEED, ToeContacts

    fps = 60.0
    live = ToeContacts(fps)
    toes = np.zeros((2, 3))
    assert live(toes).all()  # both standing from the first frame
    step = np.array([[2 * LIVE_SPEED / fps, 0.0, 0.0], [0.0, 0.0, 0.0]])  # the left toe moves at twice the limit
    said = [live(toes := toes + step)[0] for _ in range(4)]
    assert said == [True, True, False, False]  # taken on the third frame in a row: 50 ms at 60 Hz
    toes[0, 2] = 0.2  # then lifted and held still 20 cm up: not in contact
    assert not any(live(toes)[0] for _ in range(5))
    toes[0, 2] = 0.0
    assert [live(toes)[0] for _ in range(4)] == [False, False, False, True]  # the move down, then 3 still frames
    assert live(toes)[1]  # the right foot never moved


def test_the_published_contact_probability_is_a_probability_that_beats_the_flags_on_a_walk():
    """LoBSTr published only 0 or 1 (issue 73): every estimator's contact_probability is now the
    fitted chance that the foot is on the floor, from its toe's height, speed and held state."""
    from sparse_body.core.contacts import ToeContacts
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.data.synthetic import synthetic_walk
    from sparse_body.evaluation import estimate_motion

    walk = estimate_motion(synthetic_walk(6.0), "ik", load_sensor_config("six_point"))
    p, flags = walk.contact_probability, walk.contacts.astype(float)
    labels = contact_labels(walk.motion.positions, walk.motion.fps)
    assert np.all((p > 0.0) & (p < 1.0)) and len(np.unique(np.round(p, 3))) > 20  # graded, not two values
    assert np.mean((p - labels) ** 2) < np.mean((flags - labels) ** 2)  # Brier score
    assert p[labels].mean() > p[~labels].mean() + 0.3
    toes = ToeContacts(60.0)
    toes(np.zeros((2, 3)))
    low = toes.probability.copy()
    toes(np.array([[0.0, 0.0, 0.0], [0.0, 0.3, 0.25]]))  # the right toe lifted 25 cm and swung
    assert toes.probability[1] < low[1] - 0.3 and toes.probability[0] >= low[0] - 0.05


def test_the_live_contact_probability_is_the_fitted_models():
    """The live path (plain floats) and the fit's terms (arrays) are one model."""
    from sparse_body.core.contacts import CONTACT_LOGIT, contact_probability, contact_terms

    rng = np.random.default_rng(3)
    heights, speeds, held = rng.uniform(-0.8, 0.8, 200), rng.uniform(-1, 7, 200), rng.random(200) < 0.5
    terms = np.column_stack(np.broadcast_arrays(*contact_terms(heights, speeds, held.astype(float))))
    fitted = 1 / (1 + np.exp(-terms @ np.array(CONTACT_LOGIT)))
    live = [contact_probability(h, s, bool(k)) for h, s, k in zip(heights, speeds, held, strict=True)]
    np.testing.assert_allclose(live, fitted, rtol=1e-12)
