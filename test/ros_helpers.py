"""Running the real nodes as processes and listening to them over DDS, for the tests."""

from __future__ import annotations

import os
import random
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

# The ROS_DOMAIN_ID exported when the suite started: whoever set it chose where the suite's
# nodes talk (read at import, before any test sets its own).
EXPORTED_DOMAIN = os.environ.get("ROS_DOMAIN_ID", "").strip()


def isolated_domain() -> str:
    """The exported ROS_DOMAIN_ID when there is one; otherwise a DDS domain of this test's own
    that no participant on this machine uses, so neither another test run nor another ROS
    program hears it (discovery stays on this machine: conftest.py sets
    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)."""
    if EXPORTED_DOMAIN:
        return EXPORTED_DOMAIN
    rng = random.Random(os.getpid() + time.time_ns())
    for _ in range(100):
        domain = rng.randint(1, 200)
        if _unused(domain):
            break
    return str(domain)


def _unused(domain: int) -> bool:
    """No participant on this machine has bound the domain's discovery ports (RTPS: 7400 +
    250 * domain, multicast, and the first unicast one, + 10)."""
    for port in (7400 + 250 * domain, 7410 + 250 * domain):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(("0.0.0.0", port))
            except OSError:
                return False
    return True


def start_node(
    module: str, params: dict, node_name: str, tmp_path: Path, env: dict, remaps: dict | None = None
) -> subprocess.Popen:
    """python -m MODULE --ros-args --params-file FILE [-r FROM:=TO]: what a launch file gives the node."""
    params_file = tmp_path / f"{node_name}.yaml"
    params_file.write_text(yaml.safe_dump({node_name: {"ros__parameters": params}}))
    with open(tmp_path / f"{node_name}.log", "w") as log:  # the child holds its own copy
        remap_args = [a for src, dst in (remaps or {}).items() for a in ("-r", f"{src}:={dst}")]
        return subprocess.Popen(
            [sys.executable, "-m", module, "--ros-args", "--params-file", str(params_file), *remap_args],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
        )


def start_estimator(params: dict, tmp_path: Path, env: dict) -> subprocess.Popen:
    """The estimator node (sparse_body_estimator) as a process with these parameters."""
    return start_node("sparse_body.ros.estimator_node", params, "sparse_body_estimator", tmp_path, env)


def stop(*procs: subprocess.Popen) -> None:
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()


class Listener:
    """One rclpy node collecting what arrives on the topics it is given."""

    def __init__(self, rclpy, topics: dict[str, type], qos: dict | None = None) -> None:
        self.rclpy = rclpy
        self.node = rclpy.create_node("test_listener")
        self.received = {t: [] for t in topics}
        self.arrival = {t: [] for t in topics}
        self.arrival_wall = {t: [] for t in topics}  # time.time(): latency against header stamps
        for topic, msg_type in topics.items():
            self.node.create_subscription(msg_type, topic, self._keep(topic), (qos or {}).get(topic, 50))

    def _keep(self, topic):
        def callback(msg):
            self.received[topic].append(msg)
            self.arrival[topic].append(time.monotonic())
            self.arrival_wall[topic].append(time.time())

        return callback

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.rclpy.spin_once(self.node, timeout_sec=0.02)

    def spin_until(self, condition, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if condition():
                return True
            self.rclpy.spin_once(self.node, timeout_sec=0.02)
        return condition()

    def destroy(self) -> None:
        self.node.destroy_node()


class CpuBurners:
    """One process per core spinning in a Python loop: the busy machine a teleoperation
    computer is. A context manager; the processes end with it."""

    def __init__(self, count: int | None = None) -> None:
        self.count = count or os.cpu_count() or 2
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> CpuBurners:
        self.procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(self.count)]
        return self

    def __exit__(self, *exc) -> None:
        for p in self.procs:
            p.kill()
        for p in self.procs:
            p.wait(timeout=10)


# seconds a node may take to start, or a reply to come, on a starved machine (spin_until
# returns as soon as its condition holds, so a quiet machine waits no longer)
STARTUP_LIMIT = 300.0
# seconds a replay may take on a starved machine before the test gives up on it
PLAYBACK_LIMIT = 600.0


def replay_bag(
    rclpy, ros_env, tmp_path: Path, motion, config, estimator_params: dict, until_valid: int = 0, watch_tf: bool = True
):
    """A tracker bag of `motion` played by the real tracker bridge into the real estimator
    node (default parameters but those given); returns the Listener after the whole bag has
    played (deadlines generous enough for a starved CPU). until_valid=N: the bridge loops the
    bag until N valid estimates have arrived instead, for a test that needs N whatever
    rate a starved machine leaves the estimator. watch_tf=False: the listener leaves /tf
    alone (decoding the node's link TF in Python starves a listener measuring latency), and
    playback is told by the stamps of the estimates made from tracker input."""
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage

    from sparse_body.apps.offline import make_bag
    from sparse_body.msg import EstimateStatus, FootContacts

    make_bag(motion, config, tmp_path / "trackers")
    est = start_node(
        "sparse_body.ros.estimator_node",
        {"sensors": config.name, "autostart": True, **estimator_params},
        "sparse_body_estimator",
        tmp_path,
        ros_env,
    )
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    from diagnostic_msgs.msg import DiagnosticArray

    listener = Listener(
        rclpy,
        {
            "joint_states": JointState,
            "estimate_status": EstimateStatus,
            "robot_description": String,
            # all but what latency needs: a listener busy decoding is late in taking JointState
            **({"/tf": TFMessage, "foot_contacts": FootContacts, "/diagnostics": DiagnosticArray} if watch_tf else {}),
        },
        qos={
            "robot_description": latched,
            **{t: max(500, 2 * len(motion)) for t in ("/tf", "joint_states", "estimate_status")},
        },
    )
    frames = {s.frame_id for s in config.sites}
    listener.tracker_stamps = []
    bridge = None
    try:
        # configured (the description) and ticking (its first status, held for input) before
        # the bag plays: its /tf subscription is matched from configure on, and on a starved
        # machine activation can come seconds later (once, a DragPoser node's whole 3 s bag
        # went by while it said "held: no tracker input yet")
        started = lambda: listener.received["robot_description"] and listener.received["estimate_status"]  # noqa: E731
        assert listener.spin_until(started, STARTUP_LIMIT), "estimator did not start"
        bridge = start_node(
            "sparse_body.ros.tracker_bridge_node",
            {
                "bag": str(tmp_path / "trackers"),
                "min_subscribers": 2 if watch_tf else 1,  # the estimator, and this listener when it takes /tf
                "start_delay": 0.5,
                "loop": until_valid > 0,
            },
            "sparse_body_tracker_bridge",
            tmp_path,
            ros_env,
        )

        def tracker_messages():
            if not watch_tf:
                return len(motion)
            return sum(any(tf.child_frame_id in frames for tf in m.transforms) for m in listener.received["/tf"])

        # Until the whole bag has played and arrived, however long a loaded machine takes to start
        # the bridge and play it (within a generous limit: a bag is seconds long), then a little more.
        bridge_log = tmp_path / "sparse_body_tracker_bridge.log"
        if until_valid:
            finished = lambda: sum(s.valid for s in listener.received["estimate_status"]) >= until_valid  # noqa: E731
            listener.spin_until(finished, PLAYBACK_LIMIT)
        else:
            finished = lambda: "finished playing" in bridge_log.read_text()  # noqa: E731
            listener.spin_until(finished, PLAYBACK_LIMIT)
            # what is still in flight; a listener starved by other work may have lost some /tf
            # messages (the bridge keeps 100), which the tests that need every frame check themselves
            listener.spin_until(lambda: tracker_messages() >= len(motion), 10.0)
            listener.spin_for(1.0)
        played = finished()
    finally:
        listener.destroy()
        stop(est, *([bridge] if bridge else []))
    what = f"{until_valid} valid estimates did not arrive" if until_valid else "the bridge did not play the whole bag"
    assert played, f"{what} within {PLAYBACK_LIMIT} s: " + bridge_log.read_text()[-2000:]
    listener.tracker_stamps = sorted(
        {  # estimates made from tracker input carry its stamp
            stamp_key(m.header.stamp)
            for m in listener.received["estimate_status"]
            if not m.message.startswith("held: no tracker input")
        }
        if not watch_tf
        else {
            stamp_key(tf.header.stamp)
            for m in listener.received["/tf"]
            for tf in m.transforms
            if tf.child_frame_id in frames
        }
    )
    return listener


def latencies_ms(listener, topic: str) -> np.ndarray:
    """Receive time minus header stamp of a topic's messages during playback, in ms (the
    bridge stamps trackers with the wall clock, and outputs carry the tracker stamp used)."""
    first, last = listener.tracker_stamps[0], listener.tracker_stamps[-1]
    return 1000.0 * np.array(
        [
            arrived - (m.header.stamp.sec + m.header.stamp.nanosec * 1e-9)
            for m, arrived in zip(listener.received[topic], listener.arrival_wall[topic], strict=True)
            if first <= stamp_key(m.header.stamp) <= last
        ]
    )


def diagnostic_values(listener, name_part: str) -> dict:
    """The newest value of each key on /diagnostics from statuses whose name contains name_part."""
    values = {}
    for d in listener.received["/diagnostics"]:
        for st in d.status:
            if name_part in st.name:
                values.update({kv.key: kv.value for kv in st.values})
    return values


def stamp_key(stamp) -> int:
    """A header stamp to the nearest 10 us (stamps travel as float seconds inside the node:
    0.5 us resolution at today's epoch)."""
    return round((stamp.sec + stamp.nanosec * 1e-9) * 1e5)


def after_first_valid(listener) -> list:
    """The estimate statuses from the first valid one on (before it the node waits for input)."""
    statuses = listener.received["estimate_status"]
    first = next((i for i, s in enumerate(statuses) if s.valid), len(statuses))
    return statuses[first:]


def during_playback(listener, topic: str) -> list:
    """The messages of a topic stamped from the first to the last tracker sample."""
    first, last = listener.tracker_stamps[0], listener.tracker_stamps[-1]
    return [m for m in listener.received[topic] if first <= stamp_key(m.header.stamp) <= last]
