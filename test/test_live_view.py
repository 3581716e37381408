"""The live view (issue 34): the estimator node's `foxglove_port` serves its outputs over the
Foxglove WebSocket protocol. A WebSocket client, as the Foxglove app is, connects while a bag
is replayed through the real bridge into the real node, is offered the channels, subscribes,
and receives JointState, TF (body links and trackers) and the URDF, which decode as ROS 2
messages with the schemas the server gave."""

import asyncio
import json
import socket
import struct
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (run the setup command)")
pytest.importorskip("foxglove", reason="foxglove-sdk is not installed (run the setup command)")
websockets = pytest.importorskip("websockets", reason="websockets is not installed (run the setup command)")

from ros_helpers import STARTUP_LIMIT, start_node, stop  # noqa: E402

from sparse_body.apps.live_record import record_tf  # noqa: E402
from sparse_body.apps.offline import make_bag  # noqa: E402
from sparse_body.apps.viewer import tf_bodies  # noqa: E402
from sparse_body.core.sensors import load_sensor_config  # noqa: E402
from sparse_body.data.synthetic import synthetic_walk  # noqa: E402
from sparse_body.io.bagio import typestore  # noqa: E402
from sparse_body.io.output import joint_state_names  # noqa: E402
from sparse_body.ros.live_view import SEEN, LiveView, LiveViewError  # noqa: E402

pytestmark = pytest.mark.ros
WANTED = ("/joint_states", "/tf", "/robot_description", "/estimate_status", "/diagnostics", "/robot/robot_description")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def collect(port: int, enough, limit: float) -> tuple[dict, dict]:
    """(the advertised channels by topic, the payloads received by topic) once enough(received)."""
    channels: dict[str, dict] = {}
    received: dict[str, list[bytes]] = {t: [] for t in WANTED}
    end = time.monotonic() + limit
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"]) as ws:
        by_subscription: dict[int, str] = {}
        while time.monotonic() < end and not enough(received):
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout=max(0.1, end - time.monotonic()))
            except TimeoutError:
                break
            if isinstance(frame, str):
                op = json.loads(frame)
                if op["op"] == "advertise":
                    fresh = [c for c in op["channels"] if c["topic"] in WANTED and c["topic"] not in channels]
                    channels.update({c["topic"]: c for c in op["channels"]})
                    first = len(by_subscription) + 1
                    subscriptions = [{"id": first + k, "channelId": c["id"]} for k, c in enumerate(fresh)]
                    by_subscription.update({s["id"]: c["topic"] for s, c in zip(subscriptions, fresh, strict=True)})
                    if subscriptions:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
            elif frame[0] == 1:  # a message: opcode, subscription id, log time, payload
                subscription, _ = struct.unpack_from("<IQ", frame, 1)
                received[by_subscription[subscription]].append(bytes(frame[13:]))
    return channels, received


def test_a_websocket_client_sees_the_body_trackers_and_robot_live(ros_env, tmp_path):
    """With a humanoid robot retargeted beside the body (issue 74), the live view shows it too:
    its URDF and its links on /tf, from the retarget node."""
    from sparse_body.robot.example import write_robot

    config = load_sensor_config("six_point")
    make_bag(synthetic_walk(4.0), config, tmp_path / "trackers")
    port = free_port()
    est = start_node(
        "sparse_body.ros.estimator_node",
        {"sensors": "six_point", "estimator": "ik", "autostart": True, "foxglove_port": port},
        "sparse_body_estimator",
        tmp_path,
        ros_env,
    )
    bridge = None
    retarget = start_node(
        "sparse_body.ros.retarget_node",
        {"robot": str(write_robot(tmp_path / "robot")), "autostart": True},
        "sparse_body_retarget",
        tmp_path,
        ros_env,
    )
    log = tmp_path / "sparse_body_estimator.log"
    try:
        end = time.monotonic() + STARTUP_LIMIT
        while "live view: open ws://" not in log.read_text() and time.monotonic() < end and est.poll() is None:
            time.sleep(0.2)
        assert "live view: open ws://" in log.read_text(), log.read_text()
        bridge = start_node(
            "sparse_body.ros.tracker_bridge_node",
            {"bag": str(tmp_path / "trackers"), "loop": True},
            "sparse_body_tracker_bridge",
            tmp_path,
            ros_env,
        )

        store = typestore()

        def enough(got):  # 20 valid estimates (before the trackers come, the node publishes a held pose)
            status = [store.deserialize_cdr(m, "sparse_body/msg/EstimateStatus") for m in got["/estimate_status"]]
            robot = [store.deserialize_cdr(m, "tf2_msgs/msg/TFMessage") for m in got["/tf"][-30:]]
            robot_links = any(t.child_frame_id.startswith("robot/") for m in robot for t in m.transforms)
            return (
                sum(m.valid for m in status) >= 20
                and got["/robot_description"]
                and got["/diagnostics"]
                and got["/robot/robot_description"]
                and robot_links
            )

        channels, received = asyncio.run(collect(port, enough, STARTUP_LIMIT))
        recorded, malformed = record_tf(f"ws://127.0.0.1:{port}", 3.0)  # `sparse-body view ws://...`
    finally:
        stop(est, retarget, *([bridge] if bridge else []))
    assert enough(received), log.read_text()[-2000:]
    assert {"/joint_states", "/tf", "/robot_description", "/foot_contacts", "/estimate_status"} <= set(channels)
    for topic in WANTED:
        assert channels[topic]["encoding"] == "cdr" and channels[topic]["schemaEncoding"] == "ros2msg"
        assert received[topic], (topic, log.read_text()[-2000:])
    joints = [store.deserialize_cdr(m, channels["/joint_states"]["schemaName"]) for m in received["/joint_states"]]
    assert all(list(m.name) == joint_state_names() and np.all(np.isfinite(m.position)) for m in joints)
    assert len({tuple(np.round(m.position, 6)) for m in joints}) > 10  # the body moves
    tf = [store.deserialize_cdr(m, "tf2_msgs/msg/TFMessage") for m in received["/tf"]]
    frames = {t.child_frame_id for m in tf for t in m.transforms}
    assert {"pelvis", "left_foot"} <= frames, frames
    assert {s.frame_id + SEEN for s in config.sites} & frames, frames  # the trackers beside the body
    urdf = store.deserialize_cdr(received["/robot_description"][0], "std_msgs/msg/String").data
    assert urdf.lstrip().startswith("<") and "<robot" in urdf
    diagnostics = store.deserialize_cdr(received["/diagnostics"][-1], "diagnostic_msgs/msg/DiagnosticArray")
    assert diagnostics.status[0].name.endswith(": estimator") and diagnostics.status[0].values
    robot_urdf = store.deserialize_cdr(received["/robot/robot_description"][0], "std_msgs/msg/String").data
    assert "test_humanoid" in robot_urdf or "<robot" in robot_urdf
    assert any(f.startswith("robot/") for f in frames), frames  # the robot's links beside the body

    positions, trackers, fps = tf_bodies(recorded, "live")  # what the page of a recorded live view draws
    assert malformed == 0 and len(positions) > 10 and np.all(np.isfinite(positions))
    assert len({tuple(np.round(p[0], 6)) for p in positions}) > 10  # the body moves
    assert trackers is not None and trackers.shape[1] == len(config.sites) and np.isfinite(trackers).any()


def test_a_taken_port_is_a_one_line_error():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        with pytest.raises(LiveViewError, match="cannot serve on 127.0.0.1"):
            LiveView("127.0.0.1", taken.getsockname()[1], "<robot/>")
