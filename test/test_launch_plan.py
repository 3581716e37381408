"""What the launch file starts, without starting it: needs the launch and launch_ros Python
packages (not on PyPI: make setup installs them from ../shared/ros, or a ROS install) but no
running nodes."""

import importlib.util
from pathlib import Path

import pytest

pytest.importorskip(
    "launch_ros",
    reason="launch_ros is not installed (a ROS install, or the wheels of README Install)",
)
pytest.importorskip(
    "launch.actions",
    reason="launch is not installed (a ROS install, or the wheels of README Install)",
)
pytest.importorskip("ament_index_python.packages", reason="ament_index_python is not installed (make setup)")


def _launch_module():
    path = Path(__file__).resolve().parents[1] / "launch" / "sparse_body.launch.py"
    spec = importlib.util.spec_from_file_location("sparse_body_launch", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# every launch argument, as the launch file declares them with their defaults
ARGUMENTS = {
    "sensors": "six_point",
    "estimator": "auto",
    "model_path": "",
    "height": "1.75",
    "calibration": "",
    "bag": "",
    "refine": "false",
    "robot_state_publisher": "true",
    "foxglove_port": "0",
    "foxglove_host": "127.0.0.1",
    "step_budget": "0.0",
    "budget_fallback": "ik",
    "predict_ahead": "0.0",
    "foot_lock": "false",
    "robot": "",
    "robot_urdf": "",
    "rviz": "false",
}


def _context(**given):
    """A launch context holding the launch arguments, these given ones over the defaults."""
    from launch import LaunchContext

    context = LaunchContext()
    for name, value in {**ARGUMENTS, **given}.items():
        context.launch_configurations[name] = value
    return context


def test_a_missing_robot_state_publisher_is_said_and_nothing_is_started_for_it(monkeypatch):
    """It used to fail after the estimator had started, leaving it running as an orphan."""
    from launch.actions import LogInfo
    from launch_ros.actions import Node

    module = _launch_module()
    monkeypatch.setattr(module, "_installed", lambda package: package != "robot_state_publisher")
    monkeypatch.setattr(module, "get_package_share_directory", lambda package: str(Path(__file__).resolve().parents[1]))
    context = _context(sensors="three_point", estimator="reference")
    actions = module._nodes(context)
    assert any(isinstance(a, LogInfo) for a in actions)
    assert not any(
        isinstance(a, Node) and "robot_state_publisher" in str(getattr(a, "node_package", "")) for a in actions
    )
    assert not module._installed("robot_state_publisher")


def test_a_calibration_file_is_the_body_of_the_estimator_and_of_robot_state_publisher(monkeypatch, tmp_path):
    from sparse_body.core.calibration import Calibration
    from sparse_body.core.skeleton import Skeleton
    from sparse_body.io.urdf import body_urdf

    module = _launch_module()
    monkeypatch.setattr(module, "_installed", lambda package: True)
    monkeypatch.setattr(module, "get_package_share_directory", lambda package: str(Path(__file__).resolve().parents[1]))
    # what each node is given, as the launch file gives it
    monkeypatch.setattr(module, "LifecycleNode", lambda **kw: ("lifecycle", kw))
    monkeypatch.setattr(module, "Node", lambda **kw: ("node", kw))
    offsets = Skeleton.canonical(1.62).offsets.copy()
    offsets[18] *= 1.2  # a long left upper arm
    Calibration(1.62, 0.0, {}, Skeleton(offsets)).save(tmp_path / "me.yaml")
    context = _context(estimator="ik", calibration=str(tmp_path / "me.yaml"), foxglove_host="0.0.0.0")
    actions = module._nodes(context)
    estimator = next(kw for kind, kw in actions if kind == "lifecycle")
    assert estimator["parameters"][1]["calibration"] == str(tmp_path / "me.yaml")
    assert estimator["parameters"][1]["foxglove_host"] == "0.0.0.0"  # it was silently ignored
    assert estimator["parameters"][1]["foot_lock"] is False and estimator["parameters"][1]["predict_ahead"] == 0.0
    rsp = next(kw for kind, kw in actions if kind == "node" and kw["package"] == "robot_state_publisher")
    assert rsp["parameters"][0]["robot_description"] == body_urdf(Calibration.load(tmp_path / "me.yaml").body())
    assert rsp["parameters"][0]["robot_description"] != body_urdf(Skeleton.canonical(1.62))


def test_robot_starts_the_retarget_node_with_the_mapping_and_the_sensors_fixed_frame(monkeypatch, tmp_path):
    from sparse_body.robot.example import write_robot

    module = _launch_module()
    monkeypatch.setattr(module, "_installed", lambda package: True)
    monkeypatch.setattr(module, "get_package_share_directory", lambda package: str(Path(__file__).resolve().parents[1]))
    monkeypatch.setattr(module, "LifecycleNode", lambda **kw: ("lifecycle", kw))
    monkeypatch.setattr(module, "Node", lambda **kw: ("node", kw))
    settings = {
        "sensors": "four_point",
        "estimator": "ik",
        "model_path": "",
        "height": "1.75",
        "calibration": "",
        "bag": "",
        "refine": "false",
        "robot_state_publisher": "false",
        "foxglove_port": "0",
        "foxglove_host": "127.0.0.1",
        "step_budget": "0.0",
        "budget_fallback": "ik",
        "predict_ahead": "0.1",
        "foot_lock": "true",
        "robot": "unitree_h1",
        "robot_urdf": "/robots/h1.urdf",
    }
    context = _context(**settings)
    started = [kw for kind, kw in module._nodes(context) if kind == "lifecycle"]
    retarget = next(kw for kw in started if kw["executable"] == "retarget_node")
    assert retarget["parameters"][0] == {
        "robot": "unitree_h1",
        "robot_urdf": "/robots/h1.urdf",
        "fixed_frame": "world",
        "publish_link_tf": True,  # no robot_state_publisher: the retarget node places every robot link
        "autostart": True,
    }
    assert not [
        kw for kind, kw in module._nodes(context) if kind == "node" and kw["package"] == "robot_state_publisher"
    ]
    # with robot_state_publisher, one more for the robot, under robot/, from its URDF
    robot = write_robot(tmp_path / "robot")
    context = _context(**{**settings, "robot_state_publisher": "true", "robot": str(robot), "robot_urdf": ""})
    started = module._nodes(context)
    retarget = next(kw for kind, kw in started if kind == "lifecycle" and kw["executable"] == "retarget_node")
    assert retarget["parameters"][0]["publish_link_tf"] is False
    publishers = [kw for kind, kw in started if kind == "node" and kw["package"] == "robot_state_publisher"]
    assert len(publishers) == 2
    (for_robot,) = [kw for kw in publishers if kw["parameters"][0].get("frame_prefix") == "robot/"]
    assert for_robot["parameters"][0]["robot_description"] == (tmp_path / "robot" / "test_humanoid.urdf").read_text()
    context.launch_configurations["robot"] = ""  # none: no retarget node
    assert not [
        kw for kind, kw in module._nodes(context) if kind == "lifecycle" and kw["executable"] == "retarget_node"
    ]


def test_rviz_asked_for_and_not_installed_refuses_the_launch_before_any_node_starts(monkeypatch):
    """The launch used to exit 1 ("package 'rviz2' not found") after starting the estimator,
    which then kept publishing with parent pid 1: a second launch saw two estimators."""

    module = _launch_module()
    monkeypatch.setattr(module, "_installed", lambda package: package != "rviz2")
    monkeypatch.setattr(module, "get_package_share_directory", lambda package: str(Path(__file__).resolve().parents[1]))
    started = []
    monkeypatch.setattr(module, "LifecycleNode", lambda **kw: started.append(kw) or ("lifecycle", kw))
    monkeypatch.setattr(module, "Node", lambda **kw: started.append(kw) or ("node", kw))
    context = _context(sensors="six_point", estimator="ik", robot_state_publisher="true", rviz="true")
    with pytest.raises(RuntimeError, match=r"rviz2\) is not installed.*nothing was started"):
        module._nodes(context)
    assert started == []
    monkeypatch.setattr(module, "_installed", lambda package: True)  # installed: started last, with our config
    actions = module._nodes(context)
    rviz = [kw for kind, kw in actions if kind == "node" and kw["package"] == "rviz2"]
    assert len(rviz) == 1 and rviz[0]["arguments"][1].endswith("sparse_body.rviz")


def test_the_rviz_config_draws_the_body_and_the_robot_and_follows_the_pelvis():
    """Both bodies from their descriptions (the robot's frames under robot/, as the retarget
    node or robot_state_publisher puts them), and a view that keeps the walking body in sight."""
    import yaml

    config = yaml.safe_load((Path(__file__).resolve().parents[1] / "config" / "sparse_body.rviz").read_text())
    manager = config["Visualization Manager"]
    models = {
        d["Description Topic"]["Value"]: d
        for d in manager["Displays"]
        if d["Class"] == "rviz_default_plugins/RobotModel" and d["Enabled"]
    }
    assert set(models) == {"/robot_description", "/robot/robot_description"}
    assert models["/robot/robot_description"]["TF Prefix"] == "robot"
    assert manager["Views"]["Current"]["Target Frame"] == "pelvis"
    assert manager["Global Options"]["Fixed Frame"] == "world"


def test_the_launch_arguments_default_to_the_nodes_own_defaults():
    """An argument the launch file passes on to the estimator as a parameter of the same name
    starts where the node itself does (a launched node and one started by hand agree)."""
    pytest.importorskip("rclpy")
    from launch.actions import DeclareLaunchArgument

    from sparse_body.ros.estimator_node import PARAMETERS

    declared = {
        a.name: "".join(getattr(s, "text", "") for s in a.default_value)
        for a in _launch_module().generate_launch_description().entities
        if isinstance(a, DeclareLaunchArgument)
    }
    shared = sorted(set(declared) & set(PARAMETERS))
    assert {"predict_ahead", "foot_lock", "step_budget", "budget_fallback", "estimator", "sensors"} <= set(shared)
    for name in shared:
        default = PARAMETERS[name][0]
        wanted = str(default).lower() if isinstance(default, bool) else str(default)
        assert declared[name] == wanted, (name, declared[name], wanted)
