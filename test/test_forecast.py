"""predict_ahead (core/forecast.py): the body forecast past its frame, and how it is scored."""

import math

import numpy as np
import pytest

from sparse_body.core.forecast import FADE, MAX_AHEAD, MAX_GAP, MAX_SPEED, MAX_TURN, PoseForecast, faded_seconds
from sparse_body.core.rotations import matrix_to_quat, rotation_about
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import Skeleton
from sparse_body.core.types import BodyPose
from sparse_body.data.field_protocol import FIELD
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.evaluation import estimate_motion, score
from sparse_body.methods.factory import create_estimator

FPS = 60.0


def _turning(t: float, spin: float = 2.0, speed=(0.8, 0.1, 0.0)) -> BodyPose:
    """Every joint turning at `spin` rad/s about its own tilted axis, the root moving steadily."""
    quats = np.array([matrix_to_quat(rotation_about(axis, spin * t)) for axis in np.eye(3)[np.arange(22) % 3]])
    return BodyPose(t, quats, np.array(speed) * t + [0.0, 0.0, 1.0])


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return 2 * np.arccos(np.clip(np.abs(np.sum(a * b, axis=1)), 0.0, 1.0))


def test_a_steady_motion_is_carried_on_exactly_without_fading_and_less_far_with_it():
    ahead = 0.1
    steady = PoseForecast(ahead, fade=math.inf)
    faded = PoseForecast(ahead)
    for k in range(5):
        pose = _turning(k / FPS)
        plain, less = steady.forecast(pose), faded.forecast(pose)
    truth = _turning(4 / FPS + ahead)
    assert plain.stamp == pytest.approx(truth.stamp) and plain.valid
    np.testing.assert_allclose(plain.root_position, truth.root_position, atol=1e-9)
    assert _angle(plain.local_quats, truth.local_quats).max() < 1e-6
    # fading: on the way, short of the steady guess, by what faded_seconds says
    share = faded_seconds(ahead, FADE) / ahead
    assert 0.5 < share < 1.0
    moved = np.linalg.norm(less.root_position - pose.root_position)
    assert moved == pytest.approx(share * np.linalg.norm(truth.root_position - pose.root_position))
    np.testing.assert_allclose(_angle(less.local_quats, pose.local_quats), share * 2.0 * ahead, atol=1e-6)


def test_no_velocity_no_forecast_the_first_pose_a_gap_and_an_invalid_one_are_restamped_as_they_are():
    forecast = PoseForecast(0.1)
    first = _turning(0.0)
    out = forecast.forecast(first)
    assert out.stamp == pytest.approx(0.1) and np.array_equal(out.local_quats, first.local_quats)
    late = _turning(MAX_GAP + 0.05)  # a gap: its velocity would be a guess over it
    out = forecast.forecast(late)
    assert np.array_equal(out.root_position, late.root_position)
    held = _turning(MAX_GAP + 0.05 + 1 / FPS).held(MAX_GAP + 0.05 + 1 / FPS)
    out = forecast.forecast(held)
    assert not out.valid and np.array_equal(out.root_position, held.root_position)
    after = _turning(MAX_GAP + 0.05 + 2 / FPS)  # the invalid pose gave no velocity either
    assert np.array_equal(forecast.forecast(after).root_position, after.root_position)
    assert not np.array_equal(forecast.forecast(_turning(MAX_GAP + 0.05 + 3 / FPS)).root_position, after.root_position)


def test_a_leap_in_the_input_moves_the_forecast_no_faster_than_a_person():
    forecast = PoseForecast(MAX_AHEAD)
    forecast.forecast(_turning(0.0))
    leap = _turning(1 / FPS, spin=5000.0, speed=(1e6, -1e6, 3e5))  # a kilometre-scale jump
    out = forecast.forecast(leap)
    carry = faded_seconds(MAX_AHEAD, FADE)
    assert np.isfinite(out.local_quats).all() and np.isfinite(out.root_position).all()
    assert np.linalg.norm(out.root_position - leap.root_position) <= MAX_SPEED * carry + 1e-9
    assert _angle(out.local_quats, leap.local_quats).max() <= MAX_TURN * carry + 1e-6


def test_predict_ahead_is_an_option_of_every_estimator_with_its_range():
    sensors, skeleton = load_sensor_config("six_point"), Skeleton.canonical(1.75)
    assert create_estimator("ik", sensors, skeleton, predict_ahead=0.05).ahead == 0.05
    for bad in (-0.01, MAX_AHEAD + 0.01, True, "soon"):
        with pytest.raises(ValueError, match="predict_ahead (must be|takes)"):
            create_estimator("ik", sensors, skeleton, predict_ahead=bad)


def test_forecast_poses_are_stamped_ahead_and_beat_the_present_pose_at_that_time():
    motion, sensors = synthetic_walk(6.0), load_sensor_config("six_point")
    ahead = 0.1
    forecast = estimate_motion(motion, "ik", sensors, FIELD, predict_ahead=ahead)
    present = estimate_motion(motion, "ik", sensors, FIELD, horizon=ahead)
    now = estimate_motion(motion, "ik", sensors, FIELD)
    assert forecast.horizon == present.horizon == round(ahead * FPS) and now.horizon == 0
    error = {name: score(run)["MPJPE [cm]"] for name, run in (("forecast", forecast), ("present", present))}
    assert error["forecast"] < 0.8 * error["present"], error
    assert score(now)["MPJPE [cm]"] < error["present"]  # the present pose, later, is worse than on time
    stamps = [
        p.stamp
        for p in create_estimator("ik", sensors, Skeleton.canonical(1.75), predict_ahead=ahead).process(
            forecast.view.stream
        )
    ]
    np.testing.assert_allclose(np.array(stamps) - forecast.view.stream.times, ahead)


def _constant_root(velocities: np.ndarray, ahead: float) -> np.ndarray:
    """A stand-in root model for the plumbing: the newest velocity carried on."""
    return velocities[0] * ahead


def test_noise_on_a_steady_motion_is_averaged_out_of_the_velocities_and_the_motion_still_carried_on():
    """Velocities read from two noisy poses throw the forecast about (7.7x the present pose's
    jitter ahead, issue 74); averaged (the default SMOOTH, SMOOTH_ROOT) the forecast shakes far
    less and a steady motion is still carried the whole way."""
    rng = np.random.default_rng(3)
    ahead, frames = 0.1, 240
    raw, averaged = PoseForecast(ahead, smooth=0.0, smooth_root=0.0), PoseForecast(ahead)
    roots = {"raw": [], "averaged": []}
    for k in range(frames):
        pose = _turning(k / FPS)
        pose.root_position += rng.normal(0.0, 0.003, 3)  # 3 mm of tracker noise
        roots["raw"].append(raw.forecast(pose).root_position)
        roots["averaged"].append(averaged.forecast(pose).root_position)
    shake = {name: np.abs(np.diff(np.array(r)[60:], 2, axis=0)).mean() for name, r in roots.items()}
    assert shake["averaged"] < 0.5 * shake["raw"], shake
    truth = _turning((frames - 1) / FPS + ahead).root_position
    steady = np.linalg.norm(truth - _turning((frames - 1) / FPS).root_position) * faded_seconds(ahead, FADE) / ahead
    assert np.linalg.norm(roots["averaged"][-1] - _turning((frames - 1) / FPS).root_position) == pytest.approx(
        steady, abs=0.01
    )


def test_a_root_model_gets_the_velocities_newest_first_in_the_heading_frame_and_its_move_is_turned_back():
    seen = []

    def model(velocities, ahead):
        seen.append(velocities.copy())
        return _constant_root(velocities, ahead)

    forecast = PoseForecast(0.1, root_model=model, lags=3, smooth=0.0, smooth_root=0.0)  # the plumbing alone
    heading = matrix_to_quat(rotation_about([0.0, 0.0, 1.0], math.pi / 2))  # facing +y
    for k in range(4):  # the root walks along +y at 1 m/s: forwards in its heading frame
        pose = BodyPose(k / FPS, np.tile(heading, (22, 1)), np.array([0.0, k / FPS, 1.0]))
        out = forecast.forecast(pose)
    assert len(seen) == 1  # the first three poses have too few velocities: carried as the joints are
    np.testing.assert_allclose(seen[0], [[1.0, 0.0, 0.0]] * 3, atol=1e-9)
    np.testing.assert_allclose(out.root_position - pose.root_position, [0.0, 0.1, 0.0], atol=1e-9)


def test_a_root_model_that_answers_nonsense_cannot_throw_the_forecast_away():
    for answer in ([1e9, 0.0, 0.0], [np.nan, 0.0, 0.0]):
        forecast = PoseForecast(MAX_AHEAD, root_model=lambda v, a, answer=answer: np.array(answer), lags=1)
        forecast.forecast(_turning(0.0))
        out = forecast.forecast(_turning(1 / FPS))
        assert np.isfinite(out.root_position).all()
        assert np.linalg.norm(out.root_position - _turning(1 / FPS).root_position) <= MAX_SPEED * MAX_AHEAD + 1e-9


def test_the_shipped_learned_root_is_the_default_and_forecast_faded_turns_it_off():
    from sparse_body.estimators.base import learned_root_available

    if not learned_root_available():
        pytest.skip("no learned root forecast in models/ (make train-forecast)")
    sensors, skeleton = load_sensor_config("six_point"), Skeleton.canonical(1.75)
    assert create_estimator("ik", sensors, skeleton, predict_ahead=0.1).forecast.root_model is not None
    assert create_estimator("ik", sensors, skeleton, predict_ahead=0.1, forecast="faded").forecast.root_model is None
    assert create_estimator("ik", sensors, skeleton).forecast.root_model is None  # nothing ahead: nothing loaded
    with pytest.raises(ValueError, match="forecast must be one of learned, faded"):
        create_estimator("ik", sensors, skeleton, predict_ahead=0.1, forecast="psychic")


def test_the_learned_root_carries_a_walk_further_than_the_faded_velocity():
    """A steady walk: the learned move is close to the constant velocity's, the faded one falls short."""
    from sparse_body.estimators.base import learned_root_available
    from sparse_body.estimators.forecast_model import RootForecastModel

    if not learned_root_available():
        pytest.skip("no learned root forecast in models/ (make train-forecast)")
    model = RootForecastModel()
    walking = np.tile([1.2, 0.0, 0.0], (model.lags, 1))
    move = model(walking, 0.1)
    assert np.isfinite(move).all() and abs(move[0] - 0.12) < abs(1.2 * faded_seconds(0.1, FADE) - 0.12)
