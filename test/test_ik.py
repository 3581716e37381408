import numpy as np
import pytest

from sparse_body.core.sensors import load_sensor_config, parse_sensor_config
from sparse_body.data.field_protocol import FIELD_EXACT
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.evaluation import evaluate_motion


@pytest.mark.parametrize("config,max_ee", [("three_point", 1.0), ("four_point", 1.0), ("six_point", 1.0)])
def test_ik_reaches_the_trackers(config, max_ee):
    metrics = evaluate_motion(synthetic_walk(2.0), "ik", load_sensor_config(config), FIELD_EXACT)
    assert metrics["End-effector PE [cm]"] < max_ee
    assert metrics["Hand PE [cm]"] < 1.0


def test_ik_with_feet_trackers_recovers_the_legs():
    motion = synthetic_walk(2.0)
    # the field without mounting error or failures: what the trackers alone give the legs
    six = evaluate_motion(motion, "ik", load_sensor_config("six_point"), FIELD_EXACT)
    four = evaluate_motion(motion, "ik", load_sensor_config("four_point"), FIELD_EXACT)
    assert six["Lower PE [cm]"] < 1.0 < four["Lower PE [cm]"]


def test_ik_takes_position_only_trackers():
    config = parse_sensor_config(
        {"sites": {"pelvis": {}, "left_hand": {"measures": "position"}, "right_hand": {"measures": "position"}}}
    )
    # exact mounting: without an orientation there is nothing to find a mounting error from
    metrics = evaluate_motion(synthetic_walk(2.0), "ik", config, FIELD_EXACT)
    assert np.isfinite(metrics["MPJPE [cm]"]) and metrics["Hand PE [cm]"] < 2.0
