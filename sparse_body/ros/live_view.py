"""A live view without RViz: what the estimator node publishes, served to the Foxglove app
over its WebSocket protocol (the foxglove-sdk package), so a user with a headset and no ROS
desktop opens ws://HOST:PORT in Foxglove and sees the body move with its trackers. Clients
of both names of the protocol (foxglove.sdk.v1 and the older foxglove.websocket.v1) connect.

The channels carry the node's own CDR bytes (io/cdr.py) with ROS 2 message definitions as
their schemas ("ros2msg"), so Foxglove decodes them as it decodes a ROS bag: each pose output
(io/pose_outputs.py: /joint_states, /foot_contacts, /estimate_status), /tf (the body's links,
and the trackers the estimate used as `<tracker frame>_seen`), /robot_description (the URDF;
sent again every second, since a client only receives what is logged after it subscribed) and
/diagnostics (the node's own, once a second: its rate, latency and trackers). With a humanoid
robot retargeted beside it (the retarget node), the robot too: its links' /tf and /tf_static
messages (frames under robot/) as they arrive, and its URDF on /robot/robot_description."""

from __future__ import annotations

import numpy as np

from ..core.types import TrackerFrame
from ..io import cdr, pose_outputs
from ..io.bagio import typestore
from ..io.topics import ROBOT_DESCRIPTION_TOPIC
from .ws_front import WebSocketFront

# beside every pose output's channel (io/pose_outputs.py)
CHANNELS = {
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",  # a robot's fixed links (robot_state_publisher's)
    "/robot_description": "std_msgs/msg/String",
    ROBOT_DESCRIPTION_TOPIC: "std_msgs/msg/String",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}
SEEN = "_seen"  # suffix of the tracker frames drawn beside the body (the input /tf has the originals)


def _string(text: str) -> bytes:
    """A std_msgs/String's CDR bytes."""
    layout = cdr.Layout()
    layout.string(text)
    return bytes(layout.buf)


class LiveViewError(RuntimeError):
    """The live view cannot start (the package is missing, the port is taken)."""


class LiveView:
    """A Foxglove WebSocket server of its own (its own foxglove Context) with a channel per
    output topic."""

    def __init__(self, host: str, port: int, urdf: str) -> None:
        try:
            import foxglove
        except ImportError as err:
            raise LiveViewError(f"foxglove_port needs foxglove-sdk (pip install foxglove-sdk): {err}") from err
        self._context = foxglove.Context()
        # the SDK's server on loopback, behind a front on host:port that also lets in clients
        # of the protocol's older name (ros/ws_front.py)
        try:
            self.server = foxglove.start_server(name="sparse_body", host="127.0.0.1", port=0, context=self._context)
        except Exception as err:  # noqa: BLE001 - the SDK raises its own error types
            raise LiveViewError(f"the live view cannot start its server: {err}") from err
        try:
            self._front = WebSocketFront(host, port, int(self.server.port))
        except OSError as err:
            self.server.stop()
            raise LiveViewError(f"the live view cannot serve on {host}:{port}: {err.strerror or err}") from err
        store = typestore()
        self._channels = {
            topic: foxglove.Channel(
                topic,
                schema=foxglove.Schema(
                    name=typename, encoding="ros2msg", data=store.generate_msgdef(typename, ros_version=2)[0].encode()
                ),
                message_encoding="cdr",
                context=self._context,
            )
            for topic, typename in {**{o.topic: o.type_name for o in pose_outputs.POSE_OUTPUTS}, **CHANNELS}.items()
        }
        self._description = _string(urdf)
        self._robot_description: bytes | None = None  # a humanoid robot's, once the retarget node says it

    @property
    def port(self) -> int:
        return self._front.port

    def log(self, topic: str, data: bytes, stamp: float) -> None:
        self._channels[topic].log(data, log_time=int(stamp * 1e9))

    def log_trackers(self, frame: TrackerFrame, fixed_frame: str, frame_ids: list[str]) -> None:
        """The trackers with a usable pose, as transforms from the fixed frame to their TF
        frame's name + SEEN (frame_ids: the TF frame of each of frame.sites)."""
        finite = np.isfinite(frame.positions).all(axis=1) & np.isfinite(frame.orientations).all(axis=1)
        ok = frame.valid & finite
        if not ok.any():
            return
        children = [name + SEEN for name, shown in zip(frame_ids, ok, strict=True) if shown]
        values = np.concatenate([frame.positions[ok], frame.orientations[ok]], axis=1)[None]
        data = cdr.tf_messages([frame.stamp], [fixed_frame] * len(children), children, values)[0]
        self.log("/tf", data, frame.stamp)

    def log_description(self, stamp: float) -> None:
        self.log("/robot_description", self._description, stamp)
        if self._robot_description is not None:
            self.log(ROBOT_DESCRIPTION_TOPIC, self._robot_description, stamp)

    def robot_description(self, urdf: str) -> None:
        """The humanoid robot's URDF (the retarget node's, latched): sent with the body's."""
        self._robot_description = _string(urdf)

    def close(self) -> None:
        self._front.stop()
        self.server.stop()
