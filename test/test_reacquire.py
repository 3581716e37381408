"""A lost tracker carried with the body, and a returning one eased back (core/reacquire.py;
filter options filter_carry_lost and filter_reacquire_speed)."""

import numpy as np
import pytest

from sparse_body.core.reacquire import Reacquisition
from sparse_body.core.rotations import rotation_about

POSE, NONE = 1, 0
HEAD, HAND = 0, 1
JOINTS = np.array([15, 21])  # the head's and the right hand's joints
FPS = 60.0


def _frame(t: float, head: np.ndarray, yaw: float, hand: np.ndarray | None):
    positions = np.array([head, hand if hand is not None else np.zeros(3)], float)
    rotations = np.array([rotation_about(np.array([0.0, 0.0, 1.0]), yaw), np.eye(3)])
    kinds = np.array([POSE, POSE if hand is not None else NONE])
    return t, positions, rotations, kinds


def test_a_lost_hand_moves_and_turns_with_the_head_for_carry_seconds_then_is_missing():
    treat = Reacquisition(speed=0.0, carry=1.0)
    no_pose = lambda: None  # noqa: E731
    t, p, r, k = _frame(0.0, np.array([0.0, 0.0, 1.7]), 0.0, np.array([0.3, -0.2, 1.0]))
    treat.apply(t, p, r, k, (POSE,), JOINTS, no_pose)
    carried = []
    for i in range(1, 90):  # the head walks 1 m/s along x and turns 90 degrees a second
        t, p, r, k = _frame(i / FPS, np.array([i / FPS, 0.0, 1.7]), np.pi / 2 * i / FPS, None)
        treat.apply(t, p, r, k, (POSE,), JOINTS, no_pose)
        carried.append((t, p[HAND].copy(), k[HAND], r[HAND].copy()))
    t, hand, kind, rot = carried[59]  # after one second: 1 m on, turned a quarter
    assert kind == POSE
    np.testing.assert_allclose(hand, [1.0 + 0.2, 0.3, 1.0], atol=1e-9)  # (0.3, -0.2) turned a quarter
    np.testing.assert_allclose(rot, rotation_about(np.array([0.0, 0.0, 1.0]), np.pi / 2), atol=1e-9)
    assert all(kind == NONE for _, _, kind, _ in carried[62:])  # past carry_lost (1 s): missing


def test_a_lost_foot_is_not_carried_it_stays_missing():
    """A foot stays planted while the body moves on, or swings on its own: carried rigidly
    with the head it was a worse guess than none."""
    from sparse_body.core.skeleton import JOINT_INDEX

    foot = np.array([15, JOINT_INDEX["left_foot"]])  # the second site on a foot
    for joints, carried in ((foot, NONE), (JOINTS, POSE)):  # the same on a hand: carried
        treat = Reacquisition(speed=0.0, carry=1.0)
        t, p, r, k = _frame(0.0, np.array([0.0, 0.0, 1.7]), 0.0, np.array([0.1, 0.1, 0.05]))
        treat.apply(t, p, r, k, (POSE,), joints, lambda: None)
        for i in range(1, 10):
            t, p, r, k = _frame(i / FPS, np.array([i / FPS, 0.0, 1.7]), 0.0, None)
            treat.apply(t, p, r, k, (POSE,), joints, lambda: None)
            assert k[HAND] == carried


def test_a_returning_hand_starts_where_it_was_shown_and_catches_up_at_the_speed():
    treat = Reacquisition(speed=1.0, carry=0.0)
    shown = np.zeros((22, 3))
    shown[15] = [0.0, 0.0, 1.7]
    shown[21] = [0.5, 0.0, 1.0]  # where the method had the hand: 40 cm from its tracker's return
    hand = np.array([0.1, 0.0, 1.0])
    seen = []
    for i in range(60):
        lost = 10 <= i < 20
        t, p, r, k = _frame(i / FPS, np.array([0.0, 0.0, 1.7]), 0.0, None if lost else hand + [0.0, 0.01 * i, 0])
        treat.apply(t, p, r, k, (POSE,), JOINTS, lambda: shown)
        seen.append(p[HAND].copy())
    seen = np.array(seen)
    np.testing.assert_allclose(seen[20], shown[21], atol=1e-12)  # the return starts at the shown hand
    tracker = hand + np.outer(np.arange(60), [0.0, 0.01, 0.0])
    gap = np.linalg.norm(seen[20:] - tracker[20:], axis=-1)
    np.testing.assert_allclose(np.diff(gap)[:20], -1.0 / FPS, atol=1e-9)  # 1 m/s closer each frame
    assert gap[-1] == 0.0  # caught up
    np.testing.assert_array_equal(seen[:10], tracker[:10])  # before any loss: the tracker itself


def test_a_frozen_controller_resuming_is_a_leap_and_eased_and_nothing_changes_when_off():
    shown = np.zeros((22, 3))
    shown[15], shown[21] = [0.0, 0.0, 1.7], [0.2, 0.0, 1.0]
    for speed, expected in ((2.0, shown[21]), (0.0, [0.5, 0.0, 1.0])):
        treat = Reacquisition(speed=speed, carry=0.0, leap_speed=10.0)
        for i, x in enumerate([0.2, 0.2, 0.2, 0.5]):  # frozen at 0.2, then 30 cm in a frame (18 m/s)
            t, p, r, k = _frame(i / FPS, np.array([0.0, 0.0, 1.7]), 0.0, np.array([x, 0.0, 1.0]))
            treat.apply(t, p, r, k, (POSE,), JOINTS, lambda: shown)
        np.testing.assert_allclose(p[HAND], expected, atol=1e-12)


def test_without_leap_speed_a_leap_is_given_as_it_is_and_a_return_still_eased():
    """By default a leap is believed (a boxer's punch passes 11 m/s; an occluded foot at the
    origin is for the method to judge): the method gets the sample itself."""
    shown = np.zeros((22, 3))
    shown[15], shown[21] = [0.0, 0.0, 1.7], [0.2, 0.0, 1.0]
    treat = Reacquisition(speed=2.0, carry=0.0)
    for i, x in enumerate([0.2, 0.2, 0.2, 0.5]):
        t, p, r, k = _frame(i / FPS, np.array([0.0, 0.0, 1.7]), 0.0, np.array([x, 0.0, 1.0]))
        treat.apply(t, p, r, k, (POSE,), JOINTS, lambda: shown)
    np.testing.assert_allclose(p[HAND], [0.5, 0.0, 1.0], atol=1e-12)  # the leap as given
    for i in range(4, 8):  # lost for three frames, then back 30 cm from where it was shown
        t, p, r, k = _frame(i / FPS, np.array([0.0, 0.0, 1.7]), 0.0, None if i < 7 else np.array([0.5, 0.0, 1.0]))
        treat.apply(t, p, r, k, (POSE,), JOINTS, lambda: shown)
    np.testing.assert_allclose(p[HAND], shown[21], atol=1e-12)  # the return starts at the shown hand


@pytest.mark.parametrize("mode", ["lost", "frozen"])
def test_carried_and_eased_hands_never_snap_back_for_any_three_point_method(mode):
    """A walk with hands out of view 20 % of the time, reported lost or frozen: with the
    options, every three-point method's largest recovery jump is a few centimetres (measured
    1.8-3.0), where without them the hands snapped back 7-203 cm (AvatarJLM's with its whole
    body, held while a hand was lost; a frozen hand wherever the method had believed it)."""
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.data.field_protocol import Protocol
    from sparse_body.data.synthetic import synthetic_walk
    from sparse_body.evaluation import evaluate_motion

    motion = synthetic_walk(30.0)
    sensors = load_sensor_config("three_point")
    protocol = Protocol.named(lost_percent=20, loss_mode=mode)
    eased = {"filter_reacquire_speed": 1.0, "filter_carry_lost": 2.0, "filter_frozen_after": 0.1}
    off = {"filter_reacquire_speed": 0.0, "filter_carry_lost": 0.0}
    for name in ("ik", "avatarjlm", "dragposer"):
        plain = evaluate_motion(motion, name, sensors, protocol, **off)
        treated = evaluate_motion(motion, name, sensors, protocol, **eased)
        assert treated["Recovery jump [cm]"] < 5.0, (name, treated["Recovery jump [cm]"])
        assert treated["Recovery jump [cm]"] < 0.5 * plain["Recovery jump [cm]"]
        assert treated["Lost PE [cm]"] < 10.0  # carried with the body: near the true hand
        if mode == "lost":  # the defaults carry and ease (a frozen hand is caught only with frozen_after)
            default = evaluate_motion(motion, name, sensors, protocol)
            assert default["Recovery jump [cm]"] < 5.0 and default["Lost PE [cm]"] < 10.0, (name, default)


def test_a_sample_repeated_bit_for_bit_is_lost_after_frozen_after_and_a_live_one_never():
    from sparse_body.core.reacquire import FreezeGuard
    from sparse_body.core.types import TrackerFrame

    guard = FreezeGuard(0.1)
    rng = np.random.default_rng(0)
    sites = ("head", "right_hand", "left_foot")  # a live head, a frozen hand, a frozen IMU (no position)
    hand, imu = np.array([0.3, 0.0, 1.0]), np.array([0.0, 0.0, 0.0, 1.0])
    valid = []
    for i in range(30):
        head = np.array([0.0, 0.0, 1.7]) + rng.normal(0, 1e-3, 3)
        positions = np.array([head, hand, [np.nan] * 3])
        orientations = np.array([[0, 0, 0, 1.0], [0, 0, 0, 1.0], imu])
        frame = guard(TrackerFrame(i / FPS, sites, positions, orientations, np.ones(3, dtype=bool)))
        valid.append(frame.valid.copy())
    valid = np.array(valid)
    assert valid[:, 0].all()  # its noise keeps a live tracker alive
    frozen_from = int(np.ceil(0.1 * FPS - 1e-9))  # repeated since frame 0: lost from 0.1 s on
    for s in (1, 2):
        assert valid[:frozen_from, s].all() and not valid[frozen_from + 1 :, s].any(), valid[:, s]


def test_the_loss_options_are_range_checked():
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.core.skeleton import Skeleton
    from sparse_body.methods.factory import create_estimator

    sensors = load_sensor_config("three_point")
    for option, bad, message in (
        ("filter_carry_lost", 11.0, r"filter: carry_lost must be from 0 to 10 \(seconds\)"),
        ("filter_reacquire_speed", 101.0, r"filter: reacquire_speed must be from 0 to 100 \(m/s\)"),
        ("filter_frozen_after", -1.0, r"filter: frozen_after must be from 0 to 10 \(seconds\)"),
    ):
        with pytest.raises(ValueError, match=message):
            create_estimator("ik", sensors, Skeleton.canonical(), **{option: bad})
