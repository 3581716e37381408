"""upright: the base estimator while the torso is upright, handed over to the fallback as the
body lies down; the tilt that decides it flags the lying frames and none of a walk."""

import numpy as np

from sparse_body.core.sensors import load_sensor_config
from sparse_body.data.floor import LYING, lying
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import NO_NOISE, synthesize_trackers
from sparse_body.methods.factory import create_estimator


def _run(estimator, motion, sensors):
    stream = synthesize_trackers(motion, sensors, NO_NOISE)
    poses, shares = [], []
    for frame in stream:
        poses.append(estimator.step(frame))
        shares.append(getattr(estimator, "share", 0.0))
    return poses, np.array(shares)


def test_a_walk_is_the_base_s_and_a_body_lying_down_is_handed_to_the_fallback():
    sensors = load_sensor_config("four_point")
    walk = synthetic_walk(2.0)
    upright = create_estimator("upright", sensors, walk.skeleton, foot_lock=False)
    base = create_estimator("lobstr", sensors, walk.skeleton, foot_lock=False)
    poses, shares = _run(upright, walk, sensors)
    alone, _ = _run(base, walk, sensors)
    assert shares.max() < 0.01  # upright throughout: nothing handed over
    assert max(np.abs(p.local_quats - q.local_quats).max() for p, q in zip(poses, alone, strict=True)) < 0.02
    fallback = create_estimator("ik", sensors, walk.skeleton, foot_lock=False)
    for how in LYING:
        lain = lying(walk, how)
        upright.reset()
        fallback.reset()
        poses, shares = _run(upright, lain, sensors)
        ik, _ = _run(fallback, lain, sensors)
        assert shares[60:].min() > 0.99, how  # lying: the fallback's, once settled (five time constants)
        late = slice(90, None)
        gap = max(np.abs(p.root_position - q.root_position).max() for p, q in zip(poses[late], ik[late], strict=True))
        assert gap < 0.01, how


def test_eval_says_each_estimator_s_worst_kind_against_ik():
    """Tables by kind, always: beside IK, each estimator's worst kind and its share of IK's."""
    from sparse_body.core.results import EvalResult, format_groups

    def result(name, values):
        clips = [
            {"clip": f"c{k}", "frames": 100, "category": kind, "MPJPE [cm]": value}
            for k, (kind, value) in enumerate(values)
        ]
        return EvalResult.from_json({"estimator": name, "sensors": "four_point", "split": "floor", "clips": clips})

    ik = result("ik", [("walk", 10.0), ("lying", 20.0)])
    text = format_groups([ik, result("upright", [("walk", 6.0), ("lying", 21.0)])], by="category", label="motion")
    assert "upright/four_point: worst kind lying, 1.05x IK's MPJPE [cm]" in text, text
