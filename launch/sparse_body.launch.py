"""Trackers -> estimator -> JointState, contacts and TF, with robot_state_publisher for RViz.

    ros2 launch sparse_body sparse_body.launch.py sensors:=four_point estimator:=lobstr bag:=/path/to/trackers

Arguments: sensors, estimator, model_path, refine, step_budget, budget_fallback, foot_lock,
predict_ahead, robot and robot_urdf (the body as a humanoid robot's joints on robot/joint_states),
height, calibration (a T-pose calibration file: its fitted body replaces the height-scaled one),
bag (the tracker source; empty: trackers come from elsewhere on /tf), loop (replay the bag again and again), rviz,
robot_state_publisher, foxglove_port and foxglove_host (the live view). The estimator is a
lifecycle node; it is configured and activated here through its autostart parameter.
"""

import os

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
from launch.actions import DeclareLaunchArgument, LogInfo, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node

from launch import LaunchDescription
from sparse_body.methods.factory import estimator_names


def _installed(package: str) -> bool:
    try:
        get_package_share_directory(package)
        return True
    except PackageNotFoundError:
        return False


def _nodes(context):
    from sparse_body.core.calibration import person_body
    from sparse_body.io.urdf import body_urdf

    share = get_package_share_directory("sparse_body")
    arg = lambda name: LaunchConfiguration(name).perform(context)  # noqa: E731
    # every optional tool asked for is checked before any node starts: a launch that fails
    # after starting the estimator left it running as an orphan (parent pid 1)
    with_rviz = LaunchConfiguration("rviz", default="false").perform(context).lower() in ("true", "1")
    if with_rviz and not _installed("rviz2"):
        raise RuntimeError(
            "rviz:=true, but RViz (rviz2) is not installed: install ros-$ROS_DISTRO-rviz2, or leave rviz "
            "out (nothing was started)"
        )
    height = float(arg("height"))
    body = person_body(arg("calibration"), height)
    estimator_params = [
        os.path.join(share, "config", "estimator.yaml"),
        {
            "sensors": arg("sensors"),
            "estimator": arg("estimator"),
            "height": height,
            "calibration": arg("calibration"),
            "model_path": arg("model_path"),
            "step_budget": float(arg("step_budget")),
            "budget_fallback": arg("budget_fallback"),
            "predict_ahead": float(arg("predict_ahead")),
            "foot_lock": arg("foot_lock").lower() in ("true", "1"),
            "foxglove_port": int(arg("foxglove_port")),
            "foxglove_host": arg("foxglove_host"),
            "publish_link_tf": False,
            "autostart": True,
        },
    ]
    with_rsp = arg("robot_state_publisher").lower() in ("true", "1")
    notes = []
    if with_rsp and not _installed("robot_state_publisher"):
        # checked before anything starts: a failing node must not leave the estimator orphaned
        notes.append(
            LogInfo(
                msg="robot_state_publisher is not installed: the estimator publishes the body's "
                "link TF itself (install ros-$ROS_DISTRO-robot-state-publisher, or pass "
                "robot_state_publisher:=false to silence this)"
            )
        )
        with_rsp = False
    estimator_params[1]["publish_link_tf"] = not with_rsp
    consumers = ["sparse_body_estimator"]  # the nodes here that read the trackers' /tf
    nodes = notes + [
        LifecycleNode(
            package="sparse_body",
            executable="estimator_node",
            name="sparse_body_estimator",
            namespace="",
            output="screen",
            parameters=estimator_params,
        )
    ]
    if with_rsp:
        nodes.append(
            Node(
                package="robot_state_publisher",
                executable="robot_state_publisher",
                output="screen",
                parameters=[{"robot_description": body_urdf(body)}],
            )
        )
    if arg("refine").lower() in ("true", "1"):
        consumers.append("sparse_body_constraint")
        nodes.append(
            LifecycleNode(
                package="sparse_body",
                executable="constraint_node",
                name="sparse_body_constraint",
                namespace="",
                output="screen",
                parameters=[
                    {"sensors": arg("sensors"), "height": height, "calibration": arg("calibration"), "autostart": True}
                ],
                remappings=[("input/joint_states", "joint_states")],
            )
        )
    if arg("robot"):
        from sparse_body.core.sensors import load_sensor_config

        consumers.append("sparse_body_retarget")
        nodes.append(
            LifecycleNode(
                package="sparse_body",
                executable="retarget_node",
                name="sparse_body_retarget",
                namespace="",
                output="screen",
                parameters=[
                    {
                        "robot": arg("robot"),
                        "robot_urdf": arg("robot_urdf"),
                        "fixed_frame": load_sensor_config(arg("sensors")).fixed_frame,
                        "publish_link_tf": not with_rsp,
                        "autostart": True,
                    }
                ],
            )
        )
        if with_rsp:  # the robot's links from its JointState, under robot/ (the retarget node places its base)
            from sparse_body.robot.retarget import robot_urdf_text

            nodes.append(
                Node(
                    package="robot_state_publisher",
                    executable="robot_state_publisher",
                    name="robot_state_publisher_robot",
                    namespace="robot",
                    output="screen",
                    parameters=[
                        {
                            "robot_description": robot_urdf_text(arg("robot"), arg("robot_urdf")),
                            "frame_prefix": "robot/",
                        }
                    ],
                )
            )
    if arg("bag"):
        nodes.append(
            Node(
                package="sparse_body",
                executable="tracker_bridge",
                name="sparse_body_tracker_bridge",
                output="screen",
                parameters=[
                    os.path.join(share, "config", "tracker_bridge.yaml"),
                    {
                        "bag": arg("bag"),
                        "loop": arg("loop").lower() in ("true", "1"),
                        # the first frame is for the nodes started here, not for whoever subscribed first
                        "wait_for_nodes": consumers,
                    },
                ],
            )
        )
    if with_rviz:
        nodes.append(
            Node(
                package="rviz2",
                executable="rviz2",
                output="screen",
                arguments=["-d", os.path.join(share, "config", "sparse_body.rviz")],
            )
        )
    return nodes


def generate_launch_description():
    return LaunchDescription(
        [
            DeclareLaunchArgument("sensors", default_value="six_point", description="sensor configuration"),
            DeclareLaunchArgument(
                "estimator",
                default_value="auto",
                description=f"estimation method: auto (the one recommended for the sensors), "
                f"{', '.join(estimator_names())} (options as NAME:key=value)",
            ),
            DeclareLaunchArgument(
                "model_path", default_value="", description="model file of a learned estimator (empty: the shipped one)"
            ),
            DeclareLaunchArgument(
                "step_budget",
                default_value="0.0",
                description="seconds a step may take before budget_fallback's pose is published for "
                "that frame (0: three quarters of the output period)",
            ),
            DeclareLaunchArgument(
                "budget_fallback",
                default_value="ik",
                description="the cheaper estimator for a frame over budget (empty: every step is waited for)",
            ),
            DeclareLaunchArgument(
                "foot_lock",
                default_value="true",
                description="hold each foot where it touched down while the estimator calls it planted",
            ),
            DeclareLaunchArgument(
                "predict_ahead",
                default_value="0.0",
                description="seconds past the trackers' stamp the body is forecast and stamped (0 to 0.2; 0: none)",
            ),
            DeclareLaunchArgument(
                "robot",
                default_value="",
                description="a humanoid robot's mapping (unitree_h1, unitree_h1_2, unitree_g1_29dof, unitree_g1_23dof "
                "or a YAML path): its joints on robot/joint_states (empty: none)",
            ),
            DeclareLaunchArgument(
                "robot_urdf", default_value="", description="the robot's URDF (empty: the file its mapping names)"
            ),
            DeclareLaunchArgument("height", default_value="1.75", description="the person's height in metres"),
            DeclareLaunchArgument(
                "calibration",
                default_value="",
                description="T-pose calibration file (tracker bridge ~/calibrate): its body is used",
            ),
            DeclareLaunchArgument("bag", default_value="", description="rosbag2 of tracker TF to replay"),
            DeclareLaunchArgument("loop", default_value="false", description="replay the bag again and again"),
            DeclareLaunchArgument("rviz", default_value="false", description="start RViz"),
            DeclareLaunchArgument(
                "foxglove_port",
                default_value="0",
                description="serve the body live to the Foxglove app on this WebSocket port (0: off)",
            ),
            DeclareLaunchArgument(
                "foxglove_host",
                default_value="127.0.0.1",
                description="address the live view listens on: 127.0.0.1, this machine only (the node logs "
                "the address it serves); 0.0.0.0, every network",
            ),
            DeclareLaunchArgument(
                "refine",
                default_value="false",
                description="also start the constraint node (DragPoser refinement, refined/ topics)",
            ),
            DeclareLaunchArgument(
                "robot_state_publisher",
                default_value="true",
                description="start robot_state_publisher (else, or when it is not installed, the "
                "estimator publishes link TF)",
            ),
            OpaqueFunction(function=_nodes),
        ]
    )
