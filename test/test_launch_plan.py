"""What the launch file starts, without starting it: needs the launch and launch_ros Python
packages (a ROS install; no PyPI wheels, so it skips here) but no running nodes."""
import importlib.util
from pathlib import Path

import pytest

pytest.importorskip("launch_ros", reason="launch_ros is not installed (ROS install only)")
pytest.importorskip("launch.actions", reason="launch is not installed (ROS install only)")
pytest.importorskip("ament_index_python.packages", reason="ament_index_python is not installed (ROS install only)")


def _launch_module():
    path = Path(__file__).resolve().parents[1] / "launch" / "sparse_body.launch.py"
    spec = importlib.util.spec_from_file_location("sparse_body_launch", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_missing_robot_state_publisher_is_said_and_nothing_is_started_for_it(monkeypatch):
    """It used to fail after the estimator had started, leaving it running as an orphan."""
    from launch import LaunchContext
    from launch.actions import LogInfo
    from launch_ros.actions import Node
    module = _launch_module()
    monkeypatch.setattr(module, "_installed", lambda package: package != "robot_state_publisher")
    monkeypatch.setattr(module, "get_package_share_directory", lambda package: str(Path(__file__).resolve().parents[1]))
    context = LaunchContext()
    for name, value in {"sensors": "three_point", "estimator": "reference", "model_path": "", "height": "1.75",
                        "bag": "", "refine": "false", "robot_state_publisher": "true"}.items():
        context.launch_configurations[name] = value
    actions = module._nodes(context)
    assert any(isinstance(a, LogInfo) for a in actions)
    assert not any(isinstance(a, Node) and "robot_state_publisher" in str(getattr(a, "node_package", ""))
                   for a in actions)
    assert not module._installed("robot_state_publisher")
