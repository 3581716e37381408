"""launch_testing test of the main launch file, for CI on a ROS machine (Humble, Jazzy).

It needs launch, launch_ros, launch_testing, robot_state_publisher and a colcon install of
this package; none of these exist as PyPI wheels, so here the whole module is skipped.
Run it with `launch_test test/test_launch.py` or colcon test.
"""
import os
import unittest

import pytest

launch_testing = pytest.importorskip("launch_testing", reason="launch_testing is not installed (ROS install only)")
pytest.importorskip("launch_ros", reason="launch_ros is not installed (ROS install only)")
ament_index = pytest.importorskip("ament_index_python.packages")
try:
    SHARE = ament_index.get_package_share_directory("sparse_body")
except Exception:  # noqa: BLE001 - PackageNotFoundError: not installed with colcon
    pytest.skip("sparse_body is not installed in a ROS workspace", allow_module_level=True)

import launch  # noqa: E402
import launch_testing.actions  # noqa: E402
import launch_testing.asserts  # noqa: E402
from launch.launch_description_sources import PythonLaunchDescriptionSource  # noqa: E402


@pytest.mark.launch_test
def generate_test_description():
    source = PythonLaunchDescriptionSource(os.path.join(SHARE, "launch", "sparse_body.launch.py"))
    return launch.LaunchDescription([
        launch.actions.IncludeLaunchDescription(source, launch_arguments={"sensors": "three_point", "estimator": "reference",
                                                                          "robot_state_publisher": "false"}.items()),
        launch_testing.actions.ReadyToTest(),
    ])


class TestEstimatorStarts(unittest.TestCase):
    def test_configured_and_publishing(self, proc_output):
        proc_output.assertWaitFor("configured: reference on three_point", timeout=300, stream="stderr")


@launch_testing.post_shutdown_test()
class TestShutdown(unittest.TestCase):
    def test_exit_codes(self, proc_info):
        launch_testing.asserts.assertExitCodes(proc_info, allowable_exit_codes=[0, -2, -15])
