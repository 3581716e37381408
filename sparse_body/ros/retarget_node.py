"""The estimated body as a humanoid robot's joints, as a lifecycle node (issue 54).

Input: the estimator's `joint_states` and its root on TF (`<input_prefix>pelvis` in
fixed_frame, matched to the JointState by stamp), its `foot_contacts` (a planted foot is held
on the floor), its `estimate_status` (a body held for lack of input holds the robot too), and
the body's `robot_description` (latched: the body the estimator publishes, so a calibrated
person is retargeted as they are). Output, one per body estimate:
`robot/joint_states` (the URDF's moving joints, in its order, always within its limits),
the robot's links on /tf (fixed_frame -> <frame_prefix><base link>, and with publish_link_tf
every link under its neighbour, io/robot_links.py) and the robot's URDF on
`robot/robot_description` (latched): a viewer draws the robot from these alone, or
robot_state_publisher with frame_prefix places the links instead (publish_link_tf false).

configure: read the mapping and the URDF (a bad file fails configure with one line), create
the publishers and subscriptions; activate: publish; deactivate: stop; cleanup: release
everything. Input from the network never stops the node: a JointState that is not the body's,
non-finite values or a body URDF that is not one are counted on /diagnostics and dropped.
"""

from __future__ import annotations

import functools

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.lifecycle import LifecycleNode, LifecyclePublisher, LifecycleState, TransitionCallbackReturn
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from sparse_body.msg import EstimateStatus, FootContacts

from ..core.rotations import quat_to_matrix
from ..io import cdr
from ..io.cdr import MalformedMessage, read_tf
from ..io.output import TransformTable, pose_from_joint_state, published_precision
from ..io.robot_links import RobotLinks
from ..io.urdf import body_skeleton
from ..robot.limits import CommandLimiter, limiter_for
from ..robot.retarget import MAX_BASE, HumanoidRetarget, load_retarget, robot_urdf_text
from ..robot.urdf_model import RobotFileError
from .dropped import DroppedInputs
from .messages import to_seconds
from .node_options import RetargetOptions
from .parameters import declare, problems, table
from .spin import init, start_and_spin

PARAMETERS, RANGES = table(RetargetOptions)


def _guarded(where: str):
    """A callback that never raises out: input from the network must never stop the node. What
    the checks did not foresee is dropped and counted like any refused input."""

    def wrap(callback):
        @functools.wraps(callback)
        def guarded(self, *args):
            try:
                return callback(self, *args)
            except Exception as err:  # noqa: BLE001 - counted on /diagnostics and said once in the log
                self._drop(f"{where}: {type(err).__name__}: {str(err)[:200]}")
                return None

        return guarded

    return wrap


SAME = 1000  # ns: stamps this close are the same estimate's
KEPT = 30  # body JointStates waiting for their root on /tf (half a second: the two come together, or nearly)


class RetargetNode(LifecycleNode):
    NAME = "sparse_body_retarget"

    # Made in on_configure, destroyed in _release.
    retarget: HumanoidRetarget | None = None
    links: RobotLinks | None = None  # the robot's links on /tf, for the body the retarget was made for
    limiter: CommandLimiter | None = None  # the commands eased and held to the robot's limits
    pub_joints: LifecyclePublisher | None = None
    pub_tf: LifecyclePublisher | None = None
    pub_diag: LifecyclePublisher | None = None
    pub_description: Publisher | None = None
    subs: list[Subscription] = []
    diag_timer: Timer | None = None

    def __init__(self, **kwargs) -> None:
        super().__init__(self.NAME, **kwargs)
        self._refused_at_start = declare(self, PARAMETERS, RANGES)
        self._release()

    # -- lifecycle -------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        wrong = list(self._refused_at_start.values()) + problems(PARAMETERS, p, RANGES)
        if not wrong and not p["robot"]:
            wrong.append("robot is empty: give the robot's mapping YAML")
        if not wrong:
            try:  # checked here with a stand-in body: the real one comes on robot_description
                from ..core.skeleton import Skeleton

                load_retarget(p["robot"], p["robot_urdf"], Skeleton.canonical(1.75))
                self._urdf_text = robot_urdf_text(p["robot"], p["robot_urdf"])
            except RobotFileError as err:
                wrong.append(str(err))
        if wrong:
            self.get_logger().error(f"configure failed: {'; '.join(wrong)}")
            return TransitionCallbackReturn.FAILURE
        self.params = p
        from tf2_msgs.msg import TFMessage  # here, not at import: the stand-in exists only after setup

        self.pub_joints = self.create_lifecycle_publisher(JointState, "robot/joint_states", QoSProfile(depth=10))
        self.pub_tf = self.create_lifecycle_publisher(TFMessage, "/tf", QoSProfile(depth=100))
        self.pub_diag = self.create_lifecycle_publisher(DiagnosticArray, "/diagnostics", QoSProfile(depth=10))
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_description = self.create_publisher(String, "robot/robot_description", latched)
        self.pub_description.publish(String(data=self._urdf_text))
        self.subs = [
            # deep: /tf also carries the trackers and this node's own base, three messages a frame
            self.create_subscription(TFMessage, "/tf", self._on_tf, QoSProfile(depth=200), raw=True),
            self.create_subscription(JointState, "joint_states", self._on_body, 50),
            self.create_subscription(FootContacts, "foot_contacts", self._on_contacts, 50),
            self.create_subscription(EstimateStatus, "estimate_status", self._on_status, 50),
            self.create_subscription(String, "robot_description", self._on_description, latched),
        ]
        self.get_logger().info(f"configured: the body as {p['robot']} (waiting for the body's robot_description)")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.retarget is not None:
            self.retarget.reset()
        self.diag_timer = self.create_timer(1.0, self._publish_diagnostics)
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.diag_timer is not None:
            self.destroy_timer(self.diag_timer)
            self.diag_timer = None
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def _release(self) -> None:
        if self.diag_timer is not None:
            self.destroy_timer(self.diag_timer)
        for pub in (self.pub_joints, self.pub_tf, self.pub_diag):
            if pub is not None:
                self.destroy_lifecycle_publisher(pub)
        if self.pub_description is not None:
            self.destroy_publisher(self.pub_description)
        for sub in self.subs:
            self.destroy_subscription(sub)
        self.subs, self.retarget, self.links, self.limiter, self.diag_timer = [], None, None, None, None
        self.pub_joints = self.pub_tf = self.pub_diag = self.pub_description = None
        self._waiting: dict[int, JointState] = {}  # body JointStates by stamp (ns), until their root comes
        self._roots: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # the body's roots by stamp (ns), lately
        self._contacts: tuple[int, np.ndarray] = (-1, np.zeros(2, bool))  # the newest foot contacts
        self._invalid: set[int] = set()  # stamps (ns) of body estimates marked invalid (held) lately
        self._dropped = DroppedInputs(self.get_logger().warning)
        self._published = 0
        self._overlapping = 0  # published poses where two of the robot's links overlap (robot/collision.py)

    # -- work --------------------------------------------------------------------------------
    def _drop(self, reason: str) -> None:
        self._dropped.drop(reason)

    @_guarded("robot_description")
    def _on_description(self, msg: String) -> None:
        try:
            skeleton = body_skeleton(msg.data)
            self.retarget = load_retarget(self.params["robot"], self.params["robot_urdf"], skeleton)
            self.links = RobotLinks(self.retarget, self.params["fixed_frame"], self.params["frame_prefix"])
            if self.limiter is None:  # (a new body keeps the robot where its commands left it)
                self.limiter = limiter_for(self.retarget)
        except RobotFileError as err:  # (a body URDF from the network is input like any other)
            self._drop(f"robot_description: {err}")
            return
        self.get_logger().info(f"retargeting a {skeleton.height():.2f} m body at scale {self.retarget.scale:.3f}")

    @_guarded("foot_contacts")
    def _on_contacts(self, msg: FootContacts) -> None:
        contact = {c.name: bool(c.in_contact) for c in msg.contacts}
        self._contacts = (
            _nanoseconds(msg.header.stamp),
            np.array([contact.get("left_foot", False), contact.get("right_foot", False)]),
        )

    @_guarded("estimate_status")
    def _on_status(self, msg: EstimateStatus) -> None:
        if not msg.valid:  # a held body (too little tracker input): the robot holds too
            self._invalid.add(_nanoseconds(msg.header.stamp))
            while len(self._invalid) > 2 * KEPT:
                self._invalid.discard(min(self._invalid))

    @_guarded("/tf")
    def _on_tf(self, data: bytes) -> None:
        """Every root of the body on /tf, kept by stamp: its JointState may come before or after
        it, and other roots after it (each topic is delivered in order, not the two together)."""
        try:
            rows = read_tf(data)
        except MalformedMessage:
            self._drop("/tf: not a TFMessage")
            return
        root = self.params["input_prefix"] + "pelvis"
        for parent, child, stamp, values in rows:
            if child != root or parent != self.params["fixed_frame"]:
                continue
            value = np.asarray(values, float)
            if not (np.all(np.isfinite(value)) and 0.5 < np.linalg.norm(value[3:]) < 2.0):
                self._drop("/tf: a root that is not a finite pose")
                continue
            self._roots[round(stamp * 1e9)] = (value[:3], value[3:])
            while len(self._roots) > 2 * KEPT:
                self._roots.pop(min(self._roots))
        self._match()

    @_guarded("joint_states")
    def _on_body(self, msg: JointState) -> None:
        self._waiting[_nanoseconds(msg.header.stamp)] = msg
        while len(self._waiting) > KEPT:
            self._waiting.pop(min(self._waiting))
            self._drop("no root on /tf at the JointState's stamp")
        self._match()

    def _match(self) -> None:
        """Retarget the newest waiting JointState whose root has come (by stamp); those before
        it are dropped, counted: a node that fell behind (a starved machine) answers the body
        as it is now, not a backlog of where it was (each solve only adds to the delay)."""
        ready = [(stamp, root) for stamp in sorted(self._waiting) if (root := self._root_at(stamp)) is not None]
        if not ready:
            return
        newest, root = ready[-1]
        for stamp in [k for k in self._waiting if k < newest]:
            del self._waiting[stamp]
            self._drop("joint_states: a newer body was ready first (the node fell behind)")
        self._publish(self._waiting.pop(newest), *root)

    def _root_at(self, stamp: int) -> tuple[np.ndarray, np.ndarray] | None:
        root = self._roots.get(stamp)
        if root is None:  # (the cache keeps seconds: a nanosecond of rounding either way)
            root = next((r for k, r in self._roots.items() if abs(k - stamp) <= SAME), None)
        return root

    def _publish(self, msg: JointState, translation, rotation) -> None:
        if self.retarget is None or self.pub_joints is None or self.pub_tf is None:
            self._drop("no body robot_description yet")
            return
        try:
            body = pose_from_joint_state(msg.name, msg.position, translation, rotation, to_seconds(msg.header.stamp))
        except ValueError as err:
            self._drop(f"joint_states: {err}")
            return
        body.valid = _nanoseconds(msg.header.stamp) not in self._invalid  # (its status comes before its root)
        stamp_ns, contact = self._contacts
        if stamp_ns >= 0:  # the newest: the estimator sends them with the JointState (a frame late at worst)
            body.contact = contact.copy()
        over = self.retarget.over_budget
        robot = self.retarget.step(body, self.params["solve_budget"])
        if self.retarget.over_budget > over:
            self._drop("the solve ran past solve_budget: the last robot pose held")
        assert self.limiter is not None  # made with the retarget
        command, velocity = self.limiter(body.stamp, robot.positions, robot.fresh)
        base = published_precision(np.concatenate([robot.base_position, robot.base_quat]))[None, None]
        refused = _unpublishable(command, base[0, 0], self.retarget.lower, self.retarget.upper)
        if refused:
            self._drop(f"not published: {refused}")
            return
        turn = quat_to_matrix(base[0, 0, 3:])
        links = self.retarget.link_transforms(command, base[0, 0, :3], turn)
        self._overlapping += bool(self.retarget.collision.distances(links).min(initial=np.inf) < 0.0)
        joints = cdr.joint_state_messages([body.stamp], self.retarget.names, command[None], velocity[None])
        self.pub_joints.publish(joints[0])
        if self.params["publish_link_tf"] and self.links is not None:
            table = self.links.link_table(command[None], base[0], links[None])
        else:  # robot_state_publisher places the links from robot/joint_states
            child = self.params["frame_prefix"] + self.retarget.mapping.base
            table = TransformTable((self.params["fixed_frame"],), (child,), base)
        self.pub_tf.publish(cdr.tf_messages([body.stamp], table.parents, table.children, table.values)[0])
        self._published += 1

    def _publish_diagnostics(self) -> None:
        if self.pub_diag is None:
            return
        window = self.params["warn_window"]
        recent = self._dropped.recent(window)  # the counts stay; the warning passes
        status = DiagnosticStatus(
            name=f"{self.get_name()}: retargeting",
            hardware_id="sparse_body",
            level=DiagnosticStatus.WARN if recent else DiagnosticStatus.OK,
            message=f"inputs dropped in the last {window:g} s" if recent else "ok",
            values=[
                KeyValue(key="published", value=str(self._published)),
                KeyValue(key="published with two robot links overlapping", value=str(self._overlapping)),
                KeyValue(
                    key="commands held to a velocity or acceleration limit",
                    value=str(self.limiter.limited if self.limiter is not None else 0),
                ),
                KeyValue(
                    key="poses solved afresh after a limb missed its goal",
                    value=str(self.retarget.restarts if self.retarget is not None else 0),
                ),
            ]
            + [KeyValue(key=k, value=v) for k, v in self._dropped.values("dropped: ").items()],
        )
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(array)


def _unpublishable(positions: np.ndarray, base: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> str:
    """Why a robot pose must not be published (empty: it may): every command finite, within
    the URDF's limits, the base within MAX_BASE of the origin with a unit turn."""
    if not (np.all(np.isfinite(positions)) and np.all(np.isfinite(base))):
        return "a non-finite robot pose"
    if np.any(positions < lower) or np.any(positions > upper):
        return "a joint outside the URDF's limits"
    if np.abs(base[:3]).max() > MAX_BASE or not 0.99 < np.linalg.norm(base[3:]) < 1.01:
        return f"a robot base more than {MAX_BASE:g} m away or turned by no unit quaternion"
    return ""


def _nanoseconds(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def main(args=None) -> None:
    init(args)  # from here a signal ends the node, also while it starts
    start_and_spin(RetargetNode)


if __name__ == "__main__":
    main()
