"""A busy machine: the real bridge and estimator with every core kept busy by other work.

CPU starvation must show up as latency, never as lost or invalid estimates: with the
default parameters, a replayed bag still gives at least 95 % valid estimates while it
plays. (Rates and latencies are measured by `sparse-body bench`, not asserted here.)"""

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (run the setup command)")
pytest.importorskip("tf2_msgs.msg", reason="tf2_msgs is not available (run the setup command)")

from ros_helpers import CpuBurners, during_playback, replay_bag  # noqa: E402

from sparse_body.core.sensors import load_sensor_config  # noqa: E402
from sparse_body.data.synthetic import synthetic_walk  # noqa: E402

pytestmark = pytest.mark.ros


@pytest.mark.parametrize("estimator,sensors", [("ik", "six_point"), ("lobstr", "four_point")])
def test_replay_under_cpu_burners_gives_valid_estimates(ros_env, tmp_path, estimator, sensors):
    motion = synthetic_walk(8.0)
    config = load_sensor_config(sensors)
    with CpuBurners():
        listener = replay_bag(rclpy, ros_env, tmp_path, motion, config, {"estimator": estimator})
    statuses = during_playback(listener, "estimate_status")
    assert len(statuses) >= 30, (len(statuses), (tmp_path / "sparse_body_estimator.log").read_text())
    valid = sum(s.valid for s in statuses)
    assert valid >= 0.95 * len(statuses), (valid, len(statuses), {s.message for s in statuses if not s.valid})
    assert all(np.all(np.isfinite(m.position)) for m in listener.received["joint_states"])
