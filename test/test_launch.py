"""The launch file as a user of it relies on it, with launch_testing (CI runs it: `make setup`
installs launch, launch_ros, launch_testing and the `ros2` command from ../shared/ros).

For ik six-point, lobstr four-point and dragposer with the constraint node, the launch file's
own tracker bridge replays a bag (in a loop), and the tests check what arrives: JointState of
the 22-joint body (three axes of each joint below the pelvis, as the URDF names them), valid
estimates on estimate_status, foot contacts, the refined output, the body's link TF reaching
the fixed frame (robot_state_publisher is not installed here, so the
estimator publishes it); lifecycle transitions of the launched estimator; and, after the
launch is stopped with SIGINT, every process ending with exit code 0.
"""

import os
import tempfile
import time
import unittest
from pathlib import Path

import pytest

pytest.importorskip(
    "launch_testing",
    reason="launch_testing is not installed (a ROS install: ros-$ROS_DISTRO-launch-testing-ros; "
    "or SPARSE_BODY_ROS_TOOLS=FOLDER of its wheels at make setup, README Install)",
)
pytest.importorskip(
    "launch_ros",
    reason="launch_ros is not installed (a ROS install: ros-$ROS_DISTRO-launch-testing-ros; "
    "or SPARSE_BODY_ROS_TOOLS=FOLDER of its wheels at make setup, README Install)",
)
launch_testing_ros = pytest.importorskip("launch_testing_ros", reason="launch_testing_ros is not installed")
ament_index = pytest.importorskip("ament_index_python.packages")
try:
    SHARE = ament_index.get_package_share_directory("sparse_body")
except Exception:  # noqa: BLE001 - PackageNotFoundError: not in a ROS prefix
    pytest.skip("sparse_body is not in a ROS prefix (make setup, or a colcon install)", allow_module_level=True)

import launch_testing.actions  # noqa: E402
import launch_testing.asserts  # noqa: E402
import rclpy  # noqa: E402
import rclpy.executors  # noqa: E402
from launch.launch_description_sources import PythonLaunchDescriptionSource  # noqa: E402
from launch_testing_ros import WaitForTopics  # noqa: E402
from lifecycle_msgs.msg import State, Transition  # noqa: E402
from lifecycle_msgs.srv import ChangeState, GetState  # noqa: E402
from ros_helpers import isolated_domain  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402

import launch  # noqa: E402
from sparse_body.apps.offline import make_bag  # noqa: E402
from sparse_body.core.sensors import load_sensor_config  # noqa: E402
from sparse_body.core.skeleton import JOINT_NAMES  # noqa: E402
from sparse_body.data.synthetic import synthetic_walk  # noqa: E402
from sparse_body.io.output import joint_state_names  # noqa: E402
from sparse_body.io.tf_cache import TfCache  # noqa: E402
from sparse_body.msg import EstimateStatus, FootContacts  # noqa: E402

os.environ["ROS_DOMAIN_ID"] = isolated_domain()  # the launched processes and this one: a domain of their own
# seconds a launch may take to estimate on a starved machine (models load, DDS discovers)
STARTUP = float(os.environ.get("SPARSE_BODY_LAUNCH_TEST_TIMEOUT", 600))
ESTIMATOR = "/sparse_body_estimator"


def _bag() -> str:
    path = Path(tempfile.mkdtemp(prefix="sparse_body_launch_")) / "walk"
    make_bag(synthetic_walk(5.0), load_sensor_config("six_point"), path)
    return str(path)


@pytest.mark.launch_test
@launch_testing.parametrize(
    "estimator, sensors, refine",
    [("ik", "six_point", "false"), ("lobstr", "four_point", "false"), ("dragposer", "six_point", "true")],
)
def generate_test_description(estimator, sensors, refine):
    source = PythonLaunchDescriptionSource(os.path.join(SHARE, "launch", "sparse_body.launch.py"))
    arguments = {"estimator": estimator, "sensors": sensors, "refine": refine, "bag": _bag(), "loop": "true"}
    return launch.LaunchDescription(
        [
            launch.actions.IncludeLaunchDescription(source, launch_arguments=arguments.items()),
            launch_testing.actions.ReadyToTest(),
        ]
    )


def _until(condition, what: str, timeout: float = STARTUP):
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, f"no {what} within {timeout:.0f} s"
        time.sleep(0.2)


class TestWhatALaunchGives(unittest.TestCase):
    def test_joint_states_valid_estimates_contacts_and_link_tf(self, refine):
        topics = [
            ("joint_states", JointState),
            ("estimate_status", EstimateStatus),
            ("foot_contacts", FootContacts),
            ("/tf", TFMessage),
        ]
        if refine == "true":
            topics += [("refined/joint_states", JointState), ("refined/estimate_status", EstimateStatus)]
        with WaitForTopics(topics, timeout=STARTUP, messages_received_buffer_length=300) as wait:

            def valid(topic):
                return [m for m in wait.received_messages(topic) if m.valid]

            _until(lambda: len(valid("estimate_status")) >= 30, "30 valid estimates")
            statuses = wait.received_messages("estimate_status")
            first = next(k for k, m in enumerate(statuses) if m.valid)
            later = statuses[first:]
            self.assertGreaterEqual(
                sum(m.valid for m in later), 0.8 * len(later), {m.message for m in later if not m.valid}
            )
            # the URDF's joints: three axes of each of the 21 joints below the pelvis (the root is on TF)
            self.assertEqual({n.rsplit("_", 1)[0] for n in joint_state_names()}, set(JOINT_NAMES[1:]))
            for m in wait.received_messages("joint_states"):
                self.assertEqual(list(m.name), joint_state_names())
                self.assertEqual(len(m.position), 63)
            self.assertTrue(wait.received_messages("foot_contacts"))
            if refine == "true":
                _until(lambda: valid("refined/estimate_status"), "valid refined estimate")
                self.assertEqual(list(wait.received_messages("refined/joint_states")[-1].name), joint_state_names())
            # without robot_state_publisher the estimator's link TF brings every joint into the fixed frame
            cache = TfCache(JOINT_NAMES)
            for msg in wait.received_messages("/tf"):
                for tf in msg.transforms:
                    tr, q = tf.transform.translation, tf.transform.rotation
                    cache.set(
                        tf.header.frame_id,
                        tf.child_frame_id,
                        tf.header.stamp.sec + tf.header.stamp.nanosec * 1e-9,
                        (tr.x, tr.y, tr.z),
                        (q.x, q.y, q.z, q.w),
                    )
            unreached = [j for j in JOINT_NAMES if cache.lookup("world", j) is None]
            self.assertEqual(unreached, [])

    def test_lifecycle_transitions_of_the_launched_estimator(self, refine):
        context = rclpy.Context()
        rclpy.init(context=context)
        node = rclpy.create_node("launch_test_lifecycle_client", context=context)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        arrived = []
        node.create_subscription(JointState, "joint_states", lambda m: arrived.append(time.monotonic()), 10)
        try:

            def call(srv_type, name, request):
                client = node.create_client(srv_type, ESTIMATOR + name)
                self.assertTrue(client.wait_for_service(timeout_sec=STARTUP), name)
                future = client.call_async(request)
                executor.spin_until_future_complete(future, timeout_sec=60.0)
                self.assertTrue(future.done(), name)
                return future.result()

            def state():
                return call(GetState, "/get_state", GetState.Request()).current_state.id

            def spin_for(seconds):
                end = time.monotonic() + seconds
                while time.monotonic() < end:
                    executor.spin_once(timeout_sec=0.05)

            end = time.monotonic() + STARTUP
            while state() != State.PRIMARY_STATE_ACTIVE:  # autostart: configured and activated by itself
                self.assertLess(time.monotonic(), end, "the estimator never became active")
                time.sleep(0.5)
            _until_spun = time.monotonic() + STARTUP
            while not arrived:
                self.assertLess(time.monotonic(), _until_spun, "no joint_states while active")
                spin_for(0.2)
            self.assertTrue(
                call(
                    ChangeState,
                    "/change_state",
                    ChangeState.Request(transition=Transition(id=Transition.TRANSITION_DEACTIVATE)),
                ).success
            )
            self.assertEqual(state(), State.PRIMARY_STATE_INACTIVE)
            spin_for(2.0)  # what was under way is delivered
            arrived.clear()
            spin_for(3.0)
            self.assertEqual(arrived, [], "inactive, yet publishing")
            self.assertTrue(
                call(
                    ChangeState,
                    "/change_state",
                    ChangeState.Request(transition=Transition(id=Transition.TRANSITION_ACTIVATE)),
                ).success
            )
            end = time.monotonic() + STARTUP
            while not arrived:
                self.assertLess(time.monotonic(), end, "no joint_states after activating again")
                spin_for(0.2)
        finally:
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=context)


@launch_testing.post_shutdown_test()
class TestShutdown(unittest.TestCase):
    def test_every_process_exits_with_0(self, proc_info):
        launch_testing.asserts.assertExitCodes(proc_info)  # 0 only: a node dying of SIGINT (-2) fails
