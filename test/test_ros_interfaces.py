"""The generated sparse_body interfaces over real rclpy and Fast DDS, between two processes."""
import os
import random
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
    domain = str(random.randint(1, 100))
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
