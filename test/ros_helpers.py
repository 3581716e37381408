"""Running the real nodes as processes and listening to them over DDS, for the tests."""
from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from pathlib import Path

import yaml


def isolated_domain() -> str:
    """A DDS domain of its own, so concurrent test runs do not hear each other."""
    return str(random.Random(os.getpid() + time.time_ns()).randint(1, 200))


def start_node(module: str, params: dict, node_name: str, tmp_path: Path, env: dict,
               remaps: dict | None = None) -> subprocess.Popen:
    """python -m MODULE --ros-args --params-file FILE [-r FROM:=TO]: what a launch file gives the node."""
    params_file = tmp_path / f"{node_name}.yaml"
    params_file.write_text(yaml.safe_dump({node_name: {"ros__parameters": params}}))
    log = open(tmp_path / f"{node_name}.log", "w")
    remap_args = [a for src, dst in (remaps or {}).items() for a in ("-r", f"{src}:={dst}")]
    return subprocess.Popen([sys.executable, "-m", module, "--ros-args", "--params-file", str(params_file),
                             *remap_args], stdout=log, stderr=subprocess.STDOUT, env=env)


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
        for topic, msg_type in topics.items():
            self.node.create_subscription(msg_type, topic, self._keep(topic), (qos or {}).get(topic, 50))

    def _keep(self, topic):
        def callback(msg):
            self.received[topic].append(msg)
            self.arrival[topic].append(time.monotonic())
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
