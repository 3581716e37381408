"""The generated sparse_body interfaces over real rclpy and Fast DDS, between two processes."""

import os
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (run the setup command)")
msg = pytest.importorskip("sparse_body.msg", reason="the sparse_body interfaces are not generated")

pytestmark = pytest.mark.ros

PUBLISHER = """
import sys, time, rclpy
from sparse_body.msg import FootContact, FootContacts
rclpy.init()
node = rclpy.create_node("contact_talker")
pub = node.create_publisher(FootContacts, "foot_contacts", 10)
msg = FootContacts()
msg.header.frame_id = "world"
msg.contacts = [FootContact(name="left_foot", in_contact=True, probability=0.9),
                FootContact(name="right_foot", in_contact=False, probability=0.2)]
msg.contacts[0].contact_point.x = 1.5
end = time.time() + float(sys.argv[1])
while time.time() < end:
    pub.publish(msg)
    time.sleep(0.05)
node.destroy_node()
rclpy.shutdown()
"""


@pytest.fixture
def ros_domain(monkeypatch):
    from ros_helpers import isolated_domain

    domain = isolated_domain()
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    return domain


def test_foot_contacts_cross_processes_over_dds(ros_domain):
    talker = subprocess.Popen([sys.executable, "-c", PUBLISHER, "20"], env=os.environ.copy())
    received = []
    rclpy.init()
    try:
        node = rclpy.create_node("contact_listener")
        node.create_subscription(msg.FootContacts, "foot_contacts", received.append, 10)
        deadline = time.time() + 20
        while not received and time.time() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
        node.destroy_node()
    finally:
        rclpy.shutdown()
        talker.terminate()
        talker.wait(timeout=10)
    assert received, "no FootContacts message arrived within 20 s"
    got = received[0]
    assert got.header.frame_id == "world"
    assert [c.name for c in got.contacts] == ["left_foot", "right_foot"]
    assert got.contacts[0].in_contact and not got.contacts[1].in_contact
    assert got.contacts[0].probability == pytest.approx(0.9) and got.contacts[0].contact_point.x == 1.5


def test_cmake_configures_with_the_build_directory_outside_the_source_tree(tmp_path):
    """What colcon does (build/ beside the package), with the setup's .venv inside the package:
    numpy's headers under the source tree were refused in the exported targets."""
    import os
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    venv = Path(sys.prefix)
    if shutil.which("cmake") is None or not (venv / "share" / "ament_cmake" / "cmake").is_dir():
        pytest.skip("cmake or the ament CMake packages of the setup are not there")
    env = {
        **os.environ,
        "AMENT_PREFIX_PATH": str(venv),
        "CMAKE_PREFIX_PATH": str(venv),
        "PATH": f"{venv / 'bin'}:{os.environ['PATH']}",
        "_ROS_WHEELS_BOOTSTRAP_COMPLETE": "1",
    }
    out = subprocess.run(
        [
            "cmake",
            "-S",
            str(root),
            "-B",
            str(tmp_path / "build"),
            "-DBUILD_TESTING=OFF",
            "-DSPARSE_BODY_INSTALL_PYTHON=OFF",
            f"-DCMAKE_INSTALL_PREFIX={tmp_path / 'install'}",
            f"-DPython3_EXECUTABLE={sys.executable}",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, (out.stdout + out.stderr)[-3000:]
