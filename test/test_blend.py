"""blend: two estimators' poses averaged, with the hand-over where they disagree (issue 33)."""

import numpy as np
import pytest

from sparse_body.core.rotations import slerp
from sparse_body.core.sensors import load_sensor_config
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import synthesize_trackers
from sparse_body.methods.factory import create_estimator

FOUR = load_sensor_config("four_point")


@pytest.fixture(scope="module")
def walk():
    motion = synthetic_walk(2.0)
    return motion, synthesize_trackers(motion, FOUR, seed=3)


def _run(spec, walk, **options):
    motion, stream = walk
    options = {"foot_lock": False, **options}  # the mean as it is (the blend's own lock would hold the first's feet)
    return create_estimator(spec, FOUR, motion.skeleton, fps=motion.fps, filter=False, **options).process(stream)


def _same(poses, others):
    return all(
        np.allclose(p.local_quats * np.sign(p.local_quats[:, 3:]), q.local_quats * np.sign(q.local_quats[:, 3:]))
        and np.allclose(p.root_position, q.root_position)
        for p, q in zip(poses, others, strict=True)
    )


def test_the_weight_goes_from_the_first_estimator_to_the_second(walk):
    ik, lobstr = _run("ik", walk), _run("lobstr", walk)
    assert not _same(ik, lobstr)  # two answers to blend
    assert _same(_run("blend", walk, first="ik", second="lobstr", weight=0.0), ik)
    always = {"agree_within": 9.0, "disagree_from": 10.0, "settle": 0.0}
    assert _same(_run("blend", walk, first="ik", second="lobstr", weight=1.0, **always), lobstr)
    half = _run("blend", walk, first="ik", second="lobstr", weight=0.5, **always)
    assert all(p.valid and p.is_finite() for p in half) and not _same(half, ik) and not _same(half, lobstr)
    # halfway: the root at the midpoint, contacts the first's
    assert np.allclose(half[30].root_position, (ik[30].root_position + lobstr[30].root_position) / 2)
    assert np.array_equal(half[30].contact, ik[30].contact)


def test_where_the_two_disagree_the_first_is_kept(walk):
    # every disagreement counts as too much: the share falls to nothing at once
    hand_over = {"agree_within": 0.0, "disagree_from": 1e-9, "settle": 0.0}
    assert _same(_run("blend", walk, first="ik", second="lobstr", weight=0.7, **hand_over), _run("ik", walk))
    # with a time constant the share falls over frames, never in one step
    motion, stream = walk
    est = create_estimator(
        "blend",
        FOUR,
        motion.skeleton,
        fps=motion.fps,
        filter=False,
        first="ik",
        second="lobstr",
        weight=0.7,
        agree_within=0.0,
        disagree_from=1e-9,
        settle=0.1,
    )
    est.reset()
    shares = []
    for t in range(24):
        est.step(stream.frame(t))
        shares.append(est.share)
    assert 0.0 < shares[0] < 0.7 and np.all(np.diff(shares) < 0) and shares[-1] < 0.1, shares


def test_the_first_estimator_in_its_own_thread_gives_the_poses_of_one_after_the_other(walk):
    """parallel (the default) steps the first estimator in a worker thread beside the second;
    the two share only the frame's targets, so the poses are exactly the serial ones."""
    together = _run("blend", walk)
    assert all(p.valid for p in together[5:])
    assert _same(together, _run("blend", walk, parallel=False))


def test_an_error_in_the_worker_thread_reaches_the_caller(walk):
    motion, stream = walk
    est = create_estimator("blend", FOUR, motion.skeleton, fps=motion.fps, filter=False)

    def fails(frame):
        raise RuntimeError("the first estimator failed")

    est.parts[0].step = fails
    with pytest.raises(RuntimeError, match="the first estimator failed"):
        est.step(stream.frame(0))


def test_slerp_takes_the_short_arc_and_stays_unit():
    a = np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, np.sin(0.5), np.cos(0.5)]])
    b = np.array([[0.0, 0.0, np.sin(0.5), np.cos(0.5)], [0.0, 0.0, 0.0, -1.0]])  # -identity: the same rotation
    half = slerp(a, b, 0.5)
    assert np.allclose(np.linalg.norm(half, axis=-1), 1.0)
    assert np.allclose(half[0], [0.0, 0.0, np.sin(0.25), np.cos(0.25)])
    assert np.allclose(np.abs(half[1]), [0.0, 0.0, np.sin(0.25), np.cos(0.25)])  # not the long way round
    assert np.allclose(slerp(a, a, 0.3), a)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"first": "blend"}, "cannot be 'blend'"),
        ({"agree_within": 0.3, "disagree_from": 0.2}, "must be above"),
        ({"weight": 1.5}, "weight"),
        ({"second": "bogus"}, "unknown estimator"),
    ],
)
def test_bad_options_are_refused_with_their_reason(walk, options, message):
    motion, _ = walk
    with pytest.raises(ValueError, match=message):
        create_estimator("blend", FOUR, motion.skeleton, fps=motion.fps, **options)
