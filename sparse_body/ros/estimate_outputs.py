"""What the estimator node publishes, made at configure and destroyed at cleanup: every pose
output (io/pose_outputs.py: joint states, foot contacts, estimate status, under the node's
output namespace), the body on /tf, its URDF (latched), /diagnostics, and the live Foxglove
view when a port is given.

Each pose is encoded once, by the estimate bag's encoders, and the same bytes go to the topic
and to the live view: what a node publishes and what `process` writes to a bag are one message
builder, and an output added to POSE_OUTPUTS is published with nothing written here.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.qos_overriding_options import QoSOverridingOptions
from std_msgs.msg import String

from ..core.skeleton import Skeleton
from ..core.types import BodyPose, BodyPoses
from ..io import cdr
from ..io.output import HELD, axis_link_table, body_table, joint_angles
from ..io.pose_outputs import POSE_OUTPUTS, PoseBatch, pose_messages
from ..io.topics import ROBOT_DESCRIPTION_TOPIC
from ..io.urdf import body_urdf

if TYPE_CHECKING:
    from rclpy.lifecycle import LifecycleNode, LifecyclePublisher
    from rclpy.subscription import Subscription

    from .live_view import LiveView


def message_class(type_name: str) -> type:
    """The rclpy message class of "package/msg/Name"."""
    package, _, name = type_name.split("/")
    return getattr(import_module(f"{package}.msg"), name)


class EstimateOutputs:
    """The publishers of one configured estimator node (LiveViewError where its port is taken)."""

    def __init__(self, node: LifecycleNode, namespace: str, skeleton: Skeleton, frame_id: str, params: dict) -> None:
        from tf2_msgs.msg import TFMessage  # here, not at import: the stand-in exists only after setup

        self.node, self.skeleton, self.frame_id = node, skeleton, frame_id
        self.prefix, self.link_tf = params["frame_prefix"], params["publish_link_tf"]
        overrides = QoSOverridingOptions.with_default_policies()
        # one profile object per publisher: rclpy's QoS overrides change the object they are given
        self.outputs: dict[str, LifecyclePublisher] = {
            o.topic: node.create_lifecycle_publisher(
                message_class(o.type_name),
                namespace + o.topic.lstrip("/"),
                QoSProfile(depth=10),
                qos_overriding_options=overrides,
            )
            for o in POSE_OUTPUTS
        }
        self.tf = node.create_lifecycle_publisher(TFMessage, "/tf", QoSProfile(depth=100))
        self.diagnostics = node.create_lifecycle_publisher(DiagnosticArray, "/diagnostics", QoSProfile(depth=10))
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.description = node.create_publisher(String, namespace + "robot_description", latched)
        self.description.publish(String(data=body_urdf(skeleton)))
        self.live_view: LiveView | None = None
        self.robot_description: Subscription | None = None  # the retarget node's URDF, for the live view
        if params["foxglove_port"]:
            from .live_view import LiveView

            try:
                self.live_view = LiveView(params["foxglove_host"], params["foxglove_port"], body_urdf(skeleton))
            except Exception:
                self.destroy()
                raise
            self.robot_description = node.create_subscription(
                String, ROBOT_DESCRIPTION_TOPIC, lambda msg: self.live_view.robot_description(msg.data), latched
            )

    def publish(self, pose: BodyPose, stamp: float, reason: str) -> bytes:
        """One pose on every output (reason: why it is held or how it was made; empty: a
        valid pose); gives back the /tf message's bytes (the node's own, not to be read back)."""
        quats, root = pose.local_quats[None], pose.root_position[None]
        angles = joint_angles(quats)  # once: the JointState and the URDF's massless links
        poses = BodyPoses.of([pose])
        batch = PoseBatch.of(poses, self.skeleton, self.frame_id, [stamp], angles, reason or HELD, reason)
        messages = {topic: data for topic, (data,) in pose_messages(batch).items()}
        for topic, data in messages.items():
            self.outputs[topic].publish(data)
        links = body_table(quats, root, self.skeleton, self.frame_id, self.prefix, self.link_tf)
        if self.link_tf:  # the URDF's massless links too: RViz finds every link it draws
            links = links + axis_link_table(angles, self.skeleton, self.prefix)
        tf = cdr.tf_messages([stamp], links.parents, links.children, links.values)[0]
        self.tf.publish(tf)
        if self.live_view is not None:
            for topic, data in messages.items():
                self.live_view.log(topic, data, stamp)
            self.live_view.log("/tf", tf, stamp)
        return tf

    def publish_diagnostics(self, msg: DiagnosticArray, now: float) -> None:
        self.diagnostics.publish(msg)
        if self.live_view is not None:
            from rclpy.serialization import serialize_message

            self.live_view.log_description(now)
            self.live_view.log("/diagnostics", serialize_message(msg), now)

    def log_robot_tf(self, data: bytes, static: bool) -> None:
        """A /tf (or /tf_static) message of the robot's links, into the live view as it came."""
        if self.live_view is not None:
            now = self.node.get_clock().now().nanoseconds * 1e-9
            self.live_view.log("/tf_static" if static else "/tf", data, now)

    def destroy(self) -> None:
        for pub in (*self.outputs.values(), self.tf, self.diagnostics):
            self.node.destroy_lifecycle_publisher(pub)
        self.node.destroy_publisher(self.description)
        if self.robot_description is not None:
            self.node.destroy_subscription(self.robot_description)
            self.robot_description = None
        if self.live_view is not None:
            self.live_view.close()
            self.live_view = None
