"""The retarget node as a real process over real rclpy and DDS: the body's JointState, root
and contacts in, the robot's JointState and base out; hostile input from the network (a
JointState that is not the body's, non-finite values, a body URDF that is none, a root far
away) is counted and dropped, and never stops the node nor yields a non-finite or
out-of-limit joint; a bad robot file fails configure with its reason."""

import subprocess
import sys

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (run the setup command)")
pytest.importorskip("tf2_msgs.msg", reason="tf2_msgs is not available (run the setup command)")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import TransformStamped  # noqa: E402
from lifecycle_msgs.msg import State, Transition  # noqa: E402
from lifecycle_msgs.srv import ChangeState, GetState  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from ros_helpers import STARTUP_LIMIT, Listener, start_node, stop  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from test_ros_nodes import _call  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402

from sparse_body.core.rotations import matrix_to_quat  # noqa: E402
from sparse_body.core.sensors import load_sensor_config  # noqa: E402
from sparse_body.data.synthetic import synthetic_walk  # noqa: E402
from sparse_body.evaluation import estimate_motion  # noqa: E402
from sparse_body.io.output import joint_angles, joint_state_names  # noqa: E402
from sparse_body.io.urdf import body_urdf  # noqa: E402
from sparse_body.msg import FootContact, FootContacts  # noqa: E402
from sparse_body.robot.example import write_robot  # noqa: E402
from sparse_body.robot.urdf_model import load_urdf  # noqa: E402
from sparse_body.ros.messages import to_time  # noqa: E402

pytestmark = pytest.mark.ros
NODE = "sparse_body.ros.retarget_node"


def _root(stamp, position, quat) -> TFMessage:
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id, t.header.stamp = "world", "pelvis", to_time(stamp)
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = map(float, position)
    t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w = map(float, quat)
    return TFMessage(transforms=[t])


def test_hostile_input_is_counted_and_the_robot_stays_finite_and_within_its_limits(ros_env, tmp_path):
    walk = estimate_motion(synthetic_walk(4.0), "ik", load_sensor_config("six_point"))
    robot = write_robot(tmp_path / "robot")
    lower, upper = load_urdf(tmp_path / "robot" / "test_humanoid.urdf").limits()
    node = start_node(NODE, {"robot": str(robot), "autostart": True}, "sparse_body_retarget", tmp_path, ros_env)
    listener = Listener(rclpy, {"robot/joint_states": JointState, "/diagnostics": DiagnosticArray})
    pub_urdf, pub_joints, pub_tf = _body_publishers(listener)
    pub_contacts = listener.node.create_publisher(FootContacts, "foot_contacts", 10)
    names, angles = joint_state_names(), joint_angles(matrix_to_quat(walk.local_rotations))
    good = 0
    try:
        pub_urdf.publish(String(data=body_urdf(walk.view.skeleton)))
        assert listener.spin_until(lambda: node.poll() is not None or _subscribed(listener), STARTUP_LIMIT)
        for i in range(len(walk.positions)):
            stamp = listener.node.get_clock().now().nanoseconds * 1e-9
            position, quat = walk.positions[i, 0], matrix_to_quat(walk.local_rotations[i, 0])
            msg = JointState(name=names, position=list(map(float, angles[i])))
            msg.header.stamp = to_time(stamp)
            if i % 20 == 5:  # a JointState that is not the body's
                msg = JointState(name=["elbow"], position=[1.0])
                msg.header.stamp = to_time(stamp)
            elif i % 20 == 10:  # non-finite angles
                msg.position = [float("nan")] * len(names)
            elif i % 20 == 15:  # a root a kilometre away: bounded, finite, within limits
                position = position + [1000.0, 0.0, 0.0]
            else:
                good += 1
            if i == 100:  # a body URDF that is none: dropped, the body had before kept
                pub_urdf.publish(String(data="<robot name='x'><link"))
            contacts = FootContacts(
                contacts=[
                    FootContact(name=n, in_contact=bool(c))
                    for n, c in zip(("left_foot", "right_foot"), walk.contacts[i], strict=True)
                ]
            )
            contacts.header.stamp = msg.header.stamp
            pub_contacts.publish(contacts)
            pub_joints.publish(msg)
            pub_tf.publish(_root(stamp, position, quat))
            listener.spin_for(1.0 / 60)
        listener.spin_for(1.5)
        alive = node.poll() is None
    finally:
        listener.destroy()
        stop(node)
    log = _ran_cleanly(alive, tmp_path)
    states = listener.received["robot/joint_states"]
    assert len(states) >= 0.8 * good, (len(states), good, log)
    q = np.array([m.position for m in states])
    assert np.all(np.isfinite(q)) and np.all((q >= lower) & (q <= upper))
    values = {kv.key: kv.value for d in listener.received["/diagnostics"] for s in d.status for kv in s.values}
    assert int(values["dropped: joint_states: JointState lacks 63 of the body's joints, e.g. 'left_hip_rz'"]) > 0
    assert any(k.startswith("dropped: joint_states: JointState or root pose holds non-finite") for k in values)
    assert any(k.startswith("dropped: robot_description:") for k in values)
    assert 0 <= int(values["published with two robot links overlapping"]) <= int(values["published"])


def _ran_cleanly(alive: bool, tmp_path) -> str:
    """The retarget node's log, once it is known the node stayed up and raised nothing."""
    log = (tmp_path / "sparse_body_retarget.log").read_text()
    assert alive and "Traceback" not in log, log
    return log


def _subscribed(listener) -> bool:
    return listener.node.count_subscribers("joint_states") > 0


@pytest.mark.parametrize(
    ("robot", "reason"),
    [
        ("", "robot is empty"),
        ("no_such_robot", "no robot mapping 'no_such_robot'"),
        ("/nowhere/r.yaml", "cannot be read"),
    ],
)
def test_a_bad_robot_file_refuses_configure_with_the_reason_and_the_node_stays_up(ros_env, tmp_path, robot, reason):
    with open(tmp_path / "bad.log", "w") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", NODE, "--ros-args", "-p", f"robot:={robot!r}" if robot else "robot:=''"],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=ros_env,
        )
    listener = Listener(rclpy, {})
    try:
        change = listener.node.create_client(ChangeState, "/sparse_body_retarget/change_state")
        get = listener.node.create_client(GetState, "/sparse_body_retarget/get_state")
        configure = ChangeState.Request(transition=Transition(id=Transition.TRANSITION_CONFIGURE))
        assert not _call(listener.node, change, configure).success
        assert _call(listener.node, get, GetState.Request()).current_state.id == State.PRIMARY_STATE_UNCONFIGURED
        assert proc.poll() is None
    finally:
        listener.destroy()
        stop(proc)
    text = (tmp_path / "bad.log").read_text()
    assert "configure failed: " in text and reason in text and "Traceback" not in text, text


def _joint_state(stamp, names, positions) -> JointState:
    msg = JointState(name=list(names), position=[float(v) for v in positions])
    msg.header.stamp = to_time(stamp)
    return msg


def test_an_ordinary_but_unusable_joint_state_stops_neither_the_constraint_nor_the_retarget_node(ros_env, tmp_path):
    """Every JointState the message type allows and that is no body pose (names and no
    positions, too few positions, a name twice, non-finite values) and roots far away or at
    1e200 m are dropped and counted by both nodes that read the body's JointState; neither
    dies, and the robot's base on /tf stays finite and bounded."""
    from sparse_body.robot.retarget import MAX_BASE

    walk = estimate_motion(synthetic_walk(2.0), "ik", load_sensor_config("six_point"))
    robot = write_robot(tmp_path / "robot")
    retarget, refiner = _both_readers({"robot": str(robot), "autostart": True, "warn_window": 1.0}, tmp_path, ros_env)
    listener = Listener(
        rclpy, {"robot/joint_states": JointState, "/diagnostics": DiagnosticArray, "/tf": TFMessage}, qos={"/tf": 500}
    )
    pub_urdf, pub_joints, pub_tf = _body_publishers(listener)
    names = joint_state_names()
    angles = joint_angles(matrix_to_quat(walk.local_rotations))
    unusable = [
        (names, []),  # the message type allows it: names and no positions
        (names, angles[0][:10]),
        (names[:-1] + names[:1], angles[0]),  # a joint named twice, another missing
        (names, [float("inf")] * len(names)),
    ]
    try:
        pub_urdf.publish(String(data=body_urdf(walk.view.skeleton)))
        subscribed = lambda: listener.node.count_subscribers("joint_states") >= 2  # noqa: E731
        assert listener.spin_until(lambda: node_gone(retarget, refiner) or subscribed(), STARTUP_LIMIT)
        for i in range(len(walk.positions)):
            stamp = listener.node.get_clock().now().nanoseconds * 1e-9
            position, quat = walk.positions[i, 0], matrix_to_quat(walk.local_rotations[i, 0])
            kind = i % 8
            if kind < len(unusable):
                msg = _joint_state(stamp, *unusable[kind])
            else:
                msg = _joint_state(stamp, names, angles[i])
                if kind == 5:
                    position = position + [1e200, 0.0, 0.0]
                elif kind == 6:
                    position = position + [1e20, 0.0, 0.0]
            pub_tf.publish(_root(stamp, position, quat))
            pub_joints.publish(msg)
            listener.spin_for(1.0 / 60)
        listener.spin_for(3.5)  # quiet: the retarget node's warning passes (warn_window), its counts stay
        alive = {name: p.poll() is None for name, p in (("retarget", retarget), ("constraint", refiner))}
    finally:
        listener.destroy()
        stop(retarget, refiner)
    logs = {name: (tmp_path / f"{name}.log").read_text() for name in ("sparse_body_retarget", "sparse_body_constraint")}
    assert all(alive.values()), (alive, logs)
    for log in logs.values():
        assert "Traceback" not in log and "process has died" not in log, log
    assert listener.received["robot/joint_states"], logs["sparse_body_retarget"]
    bases = [
        t.transform.translation
        for m in listener.received["/tf"]
        for t in m.transforms
        if t.child_frame_id == "robot/pelvis"
    ]
    assert bases and all(np.isfinite([b.x, b.y, b.z]).all() and abs(b.x) <= MAX_BASE for b in bases)
    keys = {kv.key for d in listener.received["/diagnostics"] for s in d.status for kv in s.values}
    for prefix in ("dropped: joint_states: ", "dropped input: "):  # the retarget node's, the constraint node's
        assert any(k.startswith(prefix) and "63 names and 0 positions" in k for k in keys), (prefix, keys)
        assert any(k.startswith(prefix) and "names a joint twice" in k for k in keys), (prefix, keys)
    assert any("dropped: joint_states: the body's root is more than" in k for k in keys), keys
    levels = [s.level for d in listener.received["/diagnostics"] for s in d.status if "retargeting" in s.name]
    assert DiagnosticStatus.WARN in levels and levels[-1] == DiagnosticStatus.OK, levels


def _body_publishers(listener):
    """What an estimator publishes of the body, from the listener's node: its URDF (latched),
    its JointState and /tf."""
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    return (
        listener.node.create_publisher(String, "robot_description", latched),
        listener.node.create_publisher(JointState, "joint_states", 10),
        listener.node.create_publisher(TFMessage, "/tf", 10),
    )


def _both_readers(retarget_params: dict, tmp_path, ros_env):
    """The two nodes that read the body's JointState: the retarget node (these parameters) and
    the constraint node on the estimator's joint_states."""
    retarget = start_node(NODE, retarget_params, "sparse_body_retarget", tmp_path, ros_env)
    refiner = start_node(
        "sparse_body.ros.constraint_node",
        {"sensors": "six_point", "autostart": True},
        "sparse_body_constraint",
        tmp_path,
        ros_env,
        remaps={"input/joint_states": "/joint_states"},
    )
    return retarget, refiner


def node_gone(*procs) -> bool:
    return any(p.poll() is not None for p in procs)


def test_generated_joint_states_stop_neither_node_nor_give_a_non_finite_robot(ros_env, tmp_path):
    """Hypothesis writes JointStates of any names (the body's among them, in any order, some
    twice or missing), any number of positions of any doubles, and body roots of any doubles,
    each between well-formed body estimates; both nodes that read the body's JointState (the
    retarget and the constraint node) stay up, and every robot joint is finite and in limits."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    walk = estimate_motion(synthetic_walk(2.0), "ik", load_sensor_config("six_point"))
    robot = write_robot(tmp_path / "robot")
    lower, upper = load_urdf(tmp_path / "robot" / "test_humanoid.urdf").limits()
    retarget, refiner = _both_readers({"robot": str(robot), "autostart": True}, tmp_path, ros_env)
    listener = Listener(rclpy, {"robot/joint_states": JointState}, qos={"robot/joint_states": 1000})
    pub_urdf, pub_joints, pub_tf = _body_publishers(listener)
    names = joint_state_names()
    angles = joint_angles(matrix_to_quat(walk.local_rotations))
    sent = [0]

    def send(names_sent, positions, root, quat) -> None:
        stamp = listener.node.get_clock().now().nanoseconds * 1e-9
        pub_tf.publish(_root(stamp, root, quat))
        pub_joints.publish(_joint_state(stamp, names_sent, positions))
        listener.spin_for(0.004)

    def good() -> None:
        i = sent[0] % len(angles)
        sent[0] += 1
        send(names, angles[i], walk.positions[i, 0], matrix_to_quat(walk.local_rotations[i, 0]))

    doubles = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True) | st.sampled_from(
        [1e308, -1e308, 1e200, 2e154, 5e-324, 0.0, 1.0]
    )
    name_lists = st.one_of(
        st.permutations(names),
        st.lists(st.sampled_from(names) | st.text(max_size=8), max_size=70),
    )

    @settings(max_examples=150, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(
        name_lists,
        st.lists(doubles, max_size=70) | st.lists(st.floats(-3.0, 3.0), min_size=63, max_size=63),
        st.lists(doubles, min_size=3, max_size=3),
        st.lists(doubles, min_size=4, max_size=4),
    )
    def generated(names_sent, positions, root, quat):
        send(names_sent, positions, root, quat)
        good()

    try:
        pub_urdf.publish(String(data=body_urdf(walk.view.skeleton)))
        subscribed = lambda: listener.node.count_subscribers("joint_states") >= 2  # noqa: E731
        assert listener.spin_until(lambda: node_gone(retarget, refiner) or subscribed(), STARTUP_LIMIT)
        for _ in range(30):
            good()
        generated()
        listener.spin_for(1.0)
        alive = {"retarget": retarget.poll() is None, "constraint": refiner.poll() is None}
    finally:
        listener.destroy()
        stop(retarget, refiner)
    logs = {name: (tmp_path / f"{name}.log").read_text() for name in ("sparse_body_retarget", "sparse_body_constraint")}
    assert all(alive.values()), (alive, logs)
    assert all("Traceback" not in log for log in logs.values()), logs
    q = np.array([m.position for m in listener.received["robot/joint_states"]])
    assert len(q) and np.all(np.isfinite(q)) and np.all((q >= lower) & (q <= upper))


def test_a_number_out_of_its_range_at_start_up_fails_configure_in_one_line(ros_env, tmp_path):
    """A parameter given out of its declared range at start-up (rclpy would end the process
    with a traceback) is kept out and said by configure; the process ends 1 under autostart."""
    robot = write_robot(tmp_path / "robot")
    done = subprocess.run(
        [sys.executable, "-m", NODE, "--ros-args", "-p", f"robot:={robot}", "-p", "solve_budget:=-1.0"]
        + ["-p", "autostart:=true"],
        capture_output=True,
        text=True,
        env=ros_env,
        timeout=STARTUP_LIMIT,
    )
    text = done.stdout + done.stderr
    assert done.returncode == 1 and "configure failed: solve_budget must be between 0.001 and 10" in text, text
    assert "Traceback" not in text, text


def test_the_bench_measures_trackers_to_robot_joints_through_both_nodes(tmp_path, monkeypatch):
    """Issue 74: the end-to-end robot figure in `sparse-body bench`: tracker poses on /tf, the
    estimator node and the retarget node as processes of their own, the robot's JointState
    received, each matched to the tracker sample it was made from (no timing is asserted)."""
    pytest.importorskip("rclpy", reason="rclpy is not installed (run the setup command)")
    from ros_helpers import isolated_domain

    from sparse_body.apps.bench import bench_latency
    from sparse_body.robot.example import write_robot

    domain = isolated_domain()
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)  # the bench sets it for itself: put back after
    measured = bench_latency("ik", "six_point", seconds=3.0, robot=(str(write_robot(tmp_path)), ""), domain=domain)
    assert measured is not None and 0.0 < measured[0] <= measured[1] < 1000.0


def test_a_node_behind_answers_the_newest_body_and_counts_those_before_it(ros_env, tmp_path):
    """Three body JointStates wait for their roots, which come in one /tf message (as to a node
    that fell behind: its queue holds them all): the robot answers the newest only, and the two
    before it are counted as dropped."""
    walk = estimate_motion(synthetic_walk(2.0), "ik", load_sensor_config("six_point"))
    robot = write_robot(tmp_path / "robot")
    node = start_node(NODE, {"robot": str(robot), "autostart": True}, "sparse_body_retarget", tmp_path, ros_env)
    listener = Listener(rclpy, {"robot/joint_states": JointState, "/diagnostics": DiagnosticArray})
    pub_urdf, pub_joints, pub_tf = _body_publishers(listener)
    names, angles = joint_state_names(), joint_angles(matrix_to_quat(walk.local_rotations))
    try:
        pub_urdf.publish(String(data=body_urdf(walk.view.skeleton)))
        assert listener.spin_until(lambda: node.poll() is not None or _subscribed(listener), STARTUP_LIMIT)
        listener.spin_for(1.0)  # (the body's URDF read)
        start = listener.node.get_clock().now().nanoseconds * 1e-9
        stamps = [start + k / 60 for k in range(3)]
        for k, stamp in enumerate(stamps):
            pub_joints.publish(_joint_state(stamp, names, angles[30 + k]))
        listener.spin_for(1.0)  # all three wait for their roots
        roots = TFMessage(
            transforms=[
                _root(stamp, walk.positions[30 + k, 0], matrix_to_quat(walk.local_rotations[30 + k, 0])).transforms[0]
                for k, stamp in enumerate(stamps)
            ]
        )
        pub_tf.publish(roots)
        assert listener.spin_until(lambda: bool(listener.received["robot/joint_states"]), 10.0)
        listener.spin_for(2.5)  # a diagnostics message after it
        alive = node.poll() is None
    finally:
        listener.destroy()
        stop(node)
    _ran_cleanly(alive, tmp_path)
    answered = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in listener.received["robot/joint_states"]]
    assert len(answered) == 1 and abs(answered[0] - stamps[-1]) < 1e-6, (answered, stamps)
    values = {kv.key: kv.value for d in listener.received["/diagnostics"] for s in d.status for kv in s.values}
    assert values.get("dropped: joint_states: a newer body was ready first (the node fell behind)") == "2", values
