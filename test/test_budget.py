"""A live step within its budget (estimators/budget.py, issue 52): the estimator's pose when it
comes in time, the fallback's for a frame it misses, the same poses as a plain estimator when
every step is in time."""

import math
import time

import numpy as np
import pytest

from sparse_body.core.sensors import load_sensor_config
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import synthesize_trackers
from sparse_body.estimators.base import Estimator
from sparse_body.estimators.budget import BudgetedStep
from sparse_body.methods.factory import create_estimator

FOUR = load_sensor_config("four_point")
FAR = math.inf  # no deadline


@pytest.fixture(scope="module")
def walk():
    motion = synthetic_walk(1.0)
    return motion, list(synthesize_trackers(motion, FOUR, seed=5))


def _make(name, motion):
    return create_estimator(name, FOUR, motion.skeleton, fps=motion.fps)


@pytest.fixture
def dragposer_over_ik(walk):
    """dragposer stepped within a budget, ik its fallback (reset; closed after the test)."""
    budgeted = BudgetedStep(_make("dragposer", walk[0]), _make("ik", walk[0]))
    budgeted.reset()
    yield budgeted
    budgeted.close()


def _same(a, b) -> bool:
    return np.allclose(a.local_quats, b.local_quats) and np.allclose(a.root_position, b.root_position)


def test_every_step_in_time_gives_the_estimators_own_poses(walk, dragposer_over_ik):
    motion, frames = walk
    plain = _make("dragposer", motion)
    plain.reset()
    for frame in frames[:40]:
        pose, over = dragposer_over_ik.step(frame, FAR)
        assert not over and _same(pose, plain.step(frame))


def test_a_missed_deadline_gives_the_fallbacks_pose_and_the_estimator_goes_on(walk, dragposer_over_ik):
    motion, frames = walk
    ik = _make("ik", motion)
    ik.reset()
    # a deadline already past: this frame is the fallback's, the estimator still steps it
    pose, over = dragposer_over_ik.step(frames[0], time.monotonic() - 1.0)
    assert over and pose.valid and pose.is_finite() and _same(pose, ik.step(frames[0]))
    dragposer_over_ik._settle()  # the late step ends; the next frame is the estimator's again
    pose, over = dragposer_over_ik.step(frames[1], FAR)
    assert not over and pose.is_finite()
    assert not _same(pose, ik.step(frames[1]))  # dragposer's, not ik's


def test_frames_that_come_while_the_estimator_is_busy_are_the_fallbacks_at_once(walk):
    motion, frames = walk
    budgeted = BudgetedStep(_Pausing(FOUR, motion.skeleton, pause=0.5), _make("ik", motion))
    budgeted.reset()
    try:
        assert budgeted.step(frames[0], time.monotonic() + 0.01)[1]  # over its budget
        started = time.monotonic()
        for frame in frames[1:4]:  # no deadline, but the estimator is busy: not waited for
            pose, over = budgeted.step(frame, FAR)
            assert over and pose.valid
        assert time.monotonic() - started < 0.25
        time.sleep(0.6)  # the late step has ended: the next frame is waited for again
        pose, over = budgeted.step(frames[4], FAR)
        assert not over and not pose.valid  # _Pausing's: it never has a pose
    finally:
        budgeted.close()


def test_without_a_fallback_every_step_is_waited_for(walk):
    motion, frames = walk
    budgeted = BudgetedStep(_make("ik", motion), None)
    budgeted.reset()
    pose, over = budgeted.step(frames[0], time.monotonic() - 1.0)
    assert not over and pose.valid


class _Pausing(Estimator):
    """An estimator whose step takes `pause` seconds, then raises or has no pose: the timing
    of a slow method, made certain."""

    name = "pausing"

    def __init__(self, sensors, skeleton, pause: float, fail: bool = False) -> None:
        super().__init__(sensors, skeleton)
        self.pause, self.fail = pause, fail

    def _estimate(self, frame):
        time.sleep(self.pause)
        if self.fail:
            raise RuntimeError("broken step")
        return None


def test_the_error_of_a_late_step_is_raised_at_the_next_step(walk):
    motion, frames = walk
    budgeted = BudgetedStep(_Pausing(FOUR, motion.skeleton, 0.05, fail=True), _make("ik", motion))
    budgeted.reset()
    try:
        _, over = budgeted.step(frames[0], time.monotonic())
        assert over
        time.sleep(0.2)
        with pytest.raises(RuntimeError, match="broken step"):
            budgeted.step(frames[1], FAR)
        budgeted.reset()  # the node starts the estimator over and goes on
        assert budgeted.step(frames[2], time.monotonic())[1]
    finally:
        budgeted.close()
