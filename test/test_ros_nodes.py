"""The estimator and tracker bridge nodes as real processes over real rclpy and Fast DDS."""

import subprocess
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (run the setup command)")
pytest.importorskip("tf2_msgs.msg", reason="tf2_msgs is not available (run the setup command)")

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from lifecycle_msgs.msg import State, Transition  # noqa: E402
from lifecycle_msgs.srv import ChangeState, GetState  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from ros_helpers import (  # noqa: E402
    STARTUP_LIMIT,
    Listener,
    diagnostic_values,
    during_playback,
    replay_bag,
    stamp_key,
    start_estimator,
    start_node,
    stop,
)
from sensor_msgs.msg import JointState  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402

from sparse_body.apps.offline import make_bag  # noqa: E402
from sparse_body.core.kinematics import forward_kinematics  # noqa: E402
from sparse_body.core.rotations import euler_to_matrix, quat_to_matrix  # noqa: E402
from sparse_body.core.sensors import load_sensor_config  # noqa: E402
from sparse_body.core.skeleton import Skeleton  # noqa: E402
from sparse_body.data.synthetic import synthetic_walk  # noqa: E402
from sparse_body.io.output import joint_state_names  # noqa: E402
from sparse_body.msg import EstimateStatus  # noqa: E402

pytestmark = pytest.mark.ros
ESTIMATOR = "sparse_body.ros.estimator_node"
BRIDGE = "sparse_body.ros.tracker_bridge_node"


RESEND_AFTER = 20.0  # s without an answer before the request goes again


def _call(node, client, request, timeout=STARTUP_LIMIT):
    """The first answer to REQUEST. A request unanswered for RESEND_AFTER goes again and the
    earlier ones stay pending: a clean CI run once waited 300 s for a ChangeState that was
    never answered. Every request these tests send may arrive twice: a repeated lifecycle
    transition is refused without a change, a repeated GetState or SetParameters changes nothing."""
    deadline = time.monotonic() + timeout
    assert client.wait_for_service(timeout_sec=timeout), f"no service {client.srv_name}"
    futures = []
    while (left := deadline - time.monotonic()) > 0:
        futures.append(client.call_async(request))
        wait_until = time.monotonic() + min(RESEND_AFTER, left)
        while time.monotonic() < wait_until and not any(f.done() for f in futures):
            rclpy.spin_once(node, timeout_sec=0.1)
        if done := [f for f in futures if f.done()]:
            return done[0].result()
    raise AssertionError(f"{client.srv_name} did not answer {len(futures)} requests in {timeout:.0f} s")


def _lifecycle(node, name: str):
    """(transition(id) -> success, state() -> id) of the lifecycle node NAME, by its services."""
    change = node.create_client(ChangeState, f"/{name}/change_state")
    get = node.create_client(GetState, f"/{name}/get_state")

    def transition(tid):
        return _call(node, change, ChangeState.Request(transition=Transition(id=tid))).success

    def state():
        return _call(node, get, GetState.Request()).current_state.id

    return transition, state


def test_lifecycle_transitions_gate_the_outputs(ros_env, tmp_path):
    proc = start_estimator({"sensors": "three_point", "estimator": "reference"}, tmp_path, ros_env)
    listener = Listener(rclpy, {"joint_states": JointState})
    try:
        node = listener.node
        transition, state = _lifecycle(node, "sparse_body_estimator")
        assert state() == State.PRIMARY_STATE_UNCONFIGURED
        assert transition(Transition.TRANSITION_CONFIGURE) and state() == State.PRIMARY_STATE_INACTIVE
        listener.spin_for(1.0)
        assert listener.received["joint_states"] == []  # inactive: nothing published
        assert transition(Transition.TRANSITION_ACTIVATE) and state() == State.PRIMARY_STATE_ACTIVE
        assert listener.spin_until(lambda: len(listener.received["joint_states"]) >= 10, STARTUP_LIMIT)
        # With no trackers at all the node still publishes: finite, held poses.
        assert all(np.all(np.isfinite(m.position)) for m in listener.received["joint_states"])
        assert transition(Transition.TRANSITION_DEACTIVATE)
        listener.spin_for(0.5)
        count = len(listener.received["joint_states"])
        listener.spin_for(1.0)
        assert len(listener.received["joint_states"]) == count  # deactivated: stopped
        assert transition(Transition.TRANSITION_CLEANUP) and state() == State.PRIMARY_STATE_UNCONFIGURED
        # Reconfigure with a bad parameter: configure fails, the node stays up and unconfigured.
        from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
        from rcl_interfaces.srv import SetParameters

        setp = node.create_client(SetParameters, "/sparse_body_estimator/set_parameters")
        bad = Parameter(
            name="sensors", value=ParameterValue(type=ParameterType.PARAMETER_STRING, string_value="seven_point")
        )
        _call(node, setp, SetParameters.Request(parameters=[bad]))
        assert not transition(Transition.TRANSITION_CONFIGURE)
        assert state() == State.PRIMARY_STATE_UNCONFIGURED and proc.poll() is None
    finally:
        listener.destroy()
        stop(proc)
    assert "no sensor configuration 'seven_point'" in (tmp_path / "sparse_body_estimator.log").read_text()


def _motion(request):
    """A real CMU clip when ../shared/mocap is there, else the synthetic walk."""
    from sparse_body.data.catalog import find_mocap_root, load_clip, read_index

    root = find_mocap_root()
    if root is None:
        return synthetic_walk(6.0)
    clip = {c.clip_id: c for c in read_index(root)}["02_01"]
    return load_clip(clip).slice(0, 360)


@pytest.mark.parametrize("lag", [0.0, 0.05])
def test_replayed_bag_gives_one_valid_estimate_per_tracker_frame_with_small_end_effector_error(
    ros_env, tmp_path, request, lag
):
    """With filter_lag, each estimate is of an earlier tracker frame and stamped with its stamp:
    the end effectors are checked against the trackers of that stamp (50 ms of a walk's hand
    and foot motion, several centimetres, would fail the 2 cm bound)."""
    motion = _motion(request)
    config = load_sensor_config("six_point")
    height = motion.skeleton.height()
    parameters = {"estimator": "ik", "height": height, "filter_lag": lag}
    listener = replay_bag(rclpy, ros_env, tmp_path, motion, config, parameters)
    states = listener.received["joint_states"]
    assert states and list(states[0].name) == joint_state_names()
    assert all(np.all(np.isfinite(m.position)) for m in states)
    # Driven by the input: while the bag plays, every estimate is stamped with a tracker
    # sample's stamp, and each tracker frame gets at most one (bursts are coalesced).
    # (The node's own clock stamps only what it holds for want of any tracker input: a tick
    # just before the first sample is taken in.)
    no_input = {
        stamp_key(s.header.stamp)
        for s in listener.received["estimate_status"]
        if s.message.startswith("held: no tracker input")
    }
    played = [m for m in during_playback(listener, "joint_states") if stamp_key(m.header.stamp) not in no_input]
    keys = [stamp_key(m.header.stamp) for m in played]
    tracker = set(listener.tracker_stamps)
    # Every valid estimate is of a tracker frame. (A pose held while a filter lag fills, after
    # the start or a restart, is stamped its frame's stamp less the lag: with the bag restamped
    # at playback, not a tracker stamp. A float round trip inside the node may move a stamp
    # across a 10 us rounding edge.)
    valid = {stamp_key(s.header.stamp) for s in listener.received["estimate_status"] if s.valid}
    estimated = [k for k in keys if k in valid]
    assert len(estimated) >= 0.9 * len(keys)
    # A listener starved by a loaded machine loses some of the bridge's /tf messages (it kept
    # 100): an estimate of a frame it lost lies in a gap of what it saw. Every other estimate
    # must be stamped with a tracker frame it saw (a busy machine failed the plain check).
    seen = np.array(sorted(tracker))
    assert len(seen) >= 0.5 * len(motion), f"the listener saw {len(seen)} of {len(motion)} tracker frames"
    gap = 1.5e5 / motion.fps  # 1.5 frames, in stamp_key's 10 us

    def of_a_tracker_frame(k: int) -> bool:
        if {k - 1, k, k + 1} & tracker:
            return True
        i = int(np.searchsorted(seen, k))
        if 0 < i < len(seen):
            return seen[i] - seen[i - 1] > gap  # a frame the listener lost lies between these
        return len(seen) < len(motion)  # before or after all it saw, when it lost some

    assert all(of_a_tracker_frame(k) for k in estimated), [k for k in estimated if not of_a_tracker_frame(k)]
    assert len(keys) == len(set(keys))
    statuses = during_playback(listener, "estimate_status")
    assert sum(s.valid for s in statuses) >= 0.95 * len(statuses), {s.message for s in statuses if not s.valid}
    values = diagnostic_values(listener, "estimator")
    assert int(values["estimates driven by input"]) >= 10, values  # the trackers drove estimates
    # its own link TF came back on /tf and was known by its bytes, not read
    assert int(values["own /tf messages skipped"]) >= 10, values
    contacts = listener.received["foot_contacts"]
    assert contacts and [c.name for c in contacts[-1].contacts] == ["left_foot", "right_foot"]
    urdf = listener.received["robot_description"][0].data
    assert all(f'joint name="{n}"' in urdf for n in joint_state_names())
    # every link of the URDF has a transform on /tf: RViz finds each one it draws
    import xml.etree.ElementTree as ET

    links = {link.get("name") for link in ET.fromstring(urdf).iter("link")}
    on_tf = {tf.child_frame_id for m in listener.received["/tf"] for tf in m.transforms}
    assert len(links) == 64 and not links - on_tf, sorted(links - on_tf)[:5]

    errors = _end_effector_errors(listener, config, Skeleton.canonical(height))
    assert np.mean(errors) < 0.02, f"mean end-effector error {np.mean(errors) * 100:.2f} cm"


def test_predict_ahead_publishes_the_body_stamped_that_far_past_its_trackers(ros_env, tmp_path):
    # 105 ms: not a whole number of 60 Hz frames, so a forecast stamp is never a tracker's
    ahead = 0.105
    motion, config = synthetic_walk(4.0), load_sensor_config("six_point")
    listener = replay_bag(rclpy, ros_env, tmp_path, motion, config, {"estimator": "ik", "predict_ahead": ahead})
    valid = [s for s in listener.received["estimate_status"] if s.valid]
    assert len(valid) >= 0.5 * len(motion), f"{len(valid)} valid estimates of {len(motion)} frames"
    tracker, shift = set(listener.tracker_stamps), round(ahead * 1e5)
    keys = [stamp_key(s.header.stamp) for s in valid]
    ahead_of_a_frame = [k for k in keys if {k - shift - 1, k - shift, k - shift + 1} & tracker]
    assert len(ahead_of_a_frame) >= 0.9 * len(keys), sorted(set(keys) - set(ahead_of_a_frame))[:5]
    # none at a tracker stamp without being ahead of one (a pose not forecast): the bridge stamps
    # with the wall clock, so on a starved machine a forecast stamp can meet a later tracker's
    # stamp by chance (once in a burner run), and that one is ahead of its own frame too
    ahead = set(ahead_of_a_frame)
    assert not [k for k in keys if k in tracker and k not in ahead]
    states = listener.received["joint_states"]
    assert all(np.all(np.isfinite(m.position)) for m in states)


def test_a_step_over_its_budget_gives_the_fallbacks_pose_flagged_and_counted(ros_env, tmp_path):
    """DragPoser with a budget no step can keep (a microsecond): the frames are ik's, valid,
    said so on estimate_status and counted on /diagnostics, and none is lost; without a
    fallback every step is waited for and is DragPoser's own."""
    config = load_sensor_config("four_point")
    motion = synthetic_walk(3.0)
    parameters = {"estimator": "dragposer", "step_budget": 1e-6}
    (tmp_path / "over").mkdir()
    (tmp_path / "waited").mkdir()
    listener = replay_bag(rclpy, ros_env, tmp_path / "over", motion, config, parameters)
    statuses = during_playback(listener, "estimate_status")
    over = [s for s in statuses if s.valid and s.message.startswith("over budget: ik's pose")]
    assert len(over) >= 0.5 * len(statuses) and len(statuses) >= 30, {s.message for s in statuses}
    assert "dragposer took over 0.0 ms" in over[0].message
    assert sum(s.valid for s in statuses) >= 0.95 * len(statuses), {s.message for s in statuses}
    assert all(np.all(np.isfinite(m.position)) for m in listener.received["joint_states"])
    values = diagnostic_values(listener, "estimator")
    assert int(values["estimates by budget_fallback (step over budget)"]) >= 10, values
    assert float(values["over budget [%]"]) >= 50.0, values

    parameters["budget_fallback"] = ""
    listener = replay_bag(rclpy, ros_env, tmp_path / "waited", motion, config, parameters)
    statuses = during_playback(listener, "estimate_status")
    assert sum(s.valid for s in statuses) >= 0.95 * len(statuses) and len(statuses) >= 30
    assert not any(s.message.startswith("over budget") for s in statuses)
    assert diagnostic_values(listener, "estimator")["estimates by budget_fallback (step over budget)"] == "0"


def _end_effector_errors(listener, config, skeleton) -> list[float]:
    """FK of each valid estimate (JointState and root TF) on skeleton against the joints the
    trackers of the same stamp place: hands and feet, metres."""
    states = listener.received["joint_states"]
    tracker_tf, root_tf = {}, {}
    for msg in listener.received["/tf"]:
        for tf in msg.transforms:
            key = stamp_key(tf.header.stamp)
            t, q = tf.transform.translation, tf.transform.rotation
            pose = (np.array([t.x, t.y, t.z]), np.array([q.x, q.y, q.z, q.w]))
            if tf.child_frame_id == "pelvis":
                root_tf[key] = pose
            elif tf.child_frame_id in {s.frame_id for s in config.sites}:
                tracker_tf.setdefault(key, {})[tf.child_frame_id] = pose
    errors = []
    for msg, status in zip(states, listener.received["estimate_status"], strict=False):
        key = stamp_key(msg.header.stamp)
        if not status.valid or key not in tracker_tf or key not in root_tf or len(tracker_tf[key]) < 6:
            continue
        local = np.tile(np.eye(3), (22, 1, 1))
        local[1:] = euler_to_matrix(np.array(msg.position).reshape(21, 3), "ZYX")
        local[0] = quat_to_matrix(root_tf[key][1])
        _, pos = forward_kinematics(local, root_tf[key][0], skeleton.offsets)
        for site in ("left_hand", "right_hand", "left_foot", "right_foot"):
            spec = config.site(site)
            target, _ = spec.joint_pose(*tracker_tf[key][spec.frame_id])
            errors.append(np.linalg.norm(pos[spec.joint_index] - target))
    assert len(errors) >= 4 * 25, (
        f"too few estimates matched their tracker frames: {len(states)} JointStates, "
        f"{sum(s.valid for s in listener.received['estimate_status'])} valid, "
        f"{len(tracker_tf)} tracker stamps, {len(root_tf)} root stamps, "
        f"{len(set(tracker_tf) & set(root_tf))} in both"
    )
    return errors


def _urdf_offsets(urdf: str) -> dict[str, np.ndarray]:
    """Each joint's rest offset from the URDF: the origin of the first of its three revolute joints."""
    import re

    offsets = {}
    for name, xyz in re.findall(
        r'<joint name="([^"]+)_r[xyz]" type="continuous">\s*<parent link="[^"]+"/>'
        r'<child link="[^"]+"/>\s*<origin xyz="([^"]+)"',
        urdf,
    ):
        offsets.setdefault(name, np.array([float(v) for v in xyz.split()]))
    return offsets


def test_a_calibration_file_gives_the_body_the_node_estimates_and_publishes(ros_env, tmp_path, request):
    """The calibration's fitted body (here: from a T-pose of the clip's own subject) replaces
    the height-scaled canonical one: in the URDF, and in the JointState that puts the hands
    and feet on their trackers with that body."""
    from sparse_body.core.calibration import Calibration
    from sparse_body.core.skeleton import JOINT_INDEX as J
    from sparse_body.data.field_protocol import FIELD, calibrate_from_tpose, tpose_motion
    from sparse_body.data.motion import Motion
    from sparse_body.data.virtual_trackers import NO_NOISE, synthesize_trackers

    motion = _motion(request)
    offsets = motion.skeleton.offsets.copy()  # longer forearms and shins than any canonical body has
    offsets[[J["left_wrist"], J["right_wrist"], J["left_ankle"], J["right_ankle"]]] *= 1.15
    motion = Motion(motion.name, motion.fps, Skeleton(offsets), motion.local_quats, motion.root_positions)
    config = load_sensor_config("six_point")
    rng = np.random.default_rng(0)
    calibration = calibrate_from_tpose(synthesize_trackers(tpose_motion(motion, FIELD, rng), config, NO_NOISE), config)
    calibration.save(tmp_path / "calibration.yaml")
    body = Calibration.load(tmp_path / "calibration.yaml").body()  # as saved (rounded to 0.01 mm)
    canonical = Skeleton.canonical(calibration.height)
    assert np.abs(body.offsets - canonical.offsets).max() > 0.01  # a body the height alone does not give
    listener = replay_bag(
        rclpy, ros_env, tmp_path, motion, config, {"estimator": "ik", "calibration": str(tmp_path / "calibration.yaml")}
    )
    published = _urdf_offsets(listener.received["robot_description"][0].data)
    assert len(published) >= 20
    for name, offset in published.items():
        j = Skeleton.names.index(name)
        np.testing.assert_allclose(offset, body.offsets[j], atol=2e-6, err_msg=name)
    errors = _end_effector_errors(listener, config, body)
    assert np.mean(errors) < 0.01, f"mean end-effector error {np.mean(errors) * 100:.2f} cm with the calibrated body"
    assert "the body of" in (tmp_path / "sparse_body_estimator.log").read_text()


def test_bad_tracker_input_is_reported_and_never_gives_non_finite_output(ros_env, tmp_path):
    """NaN poses, a tracker that stops, one never seen, out-of-order stamps, a clock jump back,
    bytes that are no TFMessage."""
    from geometry_msgs.msg import TransformStamped
    from rclpy.serialization import serialize_message

    from sparse_body.data.virtual_trackers import synthesize_trackers
    from sparse_body.ros.messages import to_time

    config = load_sensor_config("four_point")
    motion = synthetic_walk(8.0)
    stream = synthesize_trackers(motion, config)
    est = start_estimator({"sensors": "four_point", "estimator": "ik", "autostart": True}, tmp_path, ros_env)
    listener = Listener(
        rclpy, {"joint_states": JointState, "estimate_status": EstimateStatus, "/diagnostics": DiagnosticArray}
    )
    pub = listener.node.create_publisher(TFMessage, "/tf", 100)
    try:
        assert listener.spin_until(lambda: listener.received["joint_states"], STARTUP_LIMIT), "estimator did not start"
        start = time.monotonic()
        for i in range(len(motion)):
            t = time.monotonic() - start
            now = listener.node.get_clock().now().nanoseconds * 1e-9
            stamp = now - 5.0 if t > 6.0 else now  # from 6 s on: the clock jumps back 5 s
            msgs = []
            for s, site in enumerate(config.sites):
                pos, rot = stream.positions[i, s].copy(), stream.orientations[i, s]
                if site.site == "right_hand":
                    continue  # never seen at all
                if site.site == "head" and 1.0 < t < 1.5:
                    pos[:] = np.nan  # NaN poses
                if site.site == "pelvis" and 2.0 < t < 4.0:
                    continue  # stops for 2 s
                if site.site == "head" and 3.0 < t < 4.0:
                    continue  # ...and the headset too for 1 s
                site_stamp = stamp - 0.3 if (site.site == "left_hand" and 4.5 < t < 5.0) else stamp  # out of order
                m = TransformStamped()
                m.header.frame_id, m.child_frame_id, m.header.stamp = "world", site.frame_id, to_time(site_stamp)
                m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = map(float, pos)
                (m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z, m.transform.rotation.w) = map(
                    float, rot
                )
                msgs.append(m)
            if 5.2 < t < 5.4:  # a headset whose clock runs 9 s ahead: refused, never an estimate's stamp
                msgs[0].header.stamp = to_time(stamp + 9.0)
            pub.publish(TFMessage(transforms=msgs))
            if i % 45 == 0:  # values whose square overflows a float: on another frame, then on the headset
                hostile = [TransformStamped(), msgs[0]] if msgs else [TransformStamped()]
                hostile[0].header.frame_id, hostile[0].child_frame_id = "world", "someone_elses_frame"
                hostile[0].header.stamp = to_time(stamp)
                hostile[0].transform.rotation.x = 2e154
                pub.publish(TFMessage(transforms=hostile[:1]))
                if len(hostile) > 1:
                    hostile[1].transform.rotation.w = 1e300
                    pub.publish(TFMessage(transforms=hostile[1:]))
            if i % 30 == 0:  # bytes that are no TFMessage: a count that lies, a message cut short
                pub.publish(
                    b"\x00\x01\x00\x00\xff\xff\xff\x7f"
                    if i % 60
                    else serialize_message(TFMessage(transforms=msgs))[:-9]
                )
            listener.spin_for(1.0 / 60)
            if t > 7.5:
                break
        listener.spin_for(1.5)
        alive = est.poll() is None
    finally:
        listener.destroy()
        stop(est)
    assert alive, (tmp_path / "sparse_body_estimator.log").read_text()
    states = listener.received["joint_states"]
    assert len(states) > 60 and all(np.all(np.isfinite(m.position)) for m in states)
    latest = max(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in states)
    assert latest < time.time() + 0.5, "an estimate stamped in the future"
    statuses = listener.received["estimate_status"]
    invalid = [s for s in statuses if not s.valid]
    assert invalid and any("head" in s.message and "pelvis" in s.message for s in invalid)
    assert sum(s.valid for s in statuses) > len(statuses) / 2
    values = {}
    messages = []
    for d in listener.received["/diagnostics"]:
        for st in d.status:
            messages.append(st.message)
            values.update({kv.key: kv.value for kv in st.values})
            # the level is a byte: OK only while estimating, WARN with stale trackers
            expected = b"\x00" if st.message == "estimating" else b"\x01" if "stale" in st.message else b"\x02"
            assert st.level == expected, (st.level, st.message)
    assert int(values["rejected samples: non-finite or absurd value"]) > 0
    assert int(values["rejected samples: stamp ahead of the clock"]) > 0
    assert int(values["rejected samples: out of order"]) > 0
    assert int(values["rejected samples: malformed message"]) > 0
    assert int(values["clock jumps back"]) >= 1
    assert values["right_hand age [s]"] == "never seen"
    assert any("stale or missing trackers" in m and "pelvis" in m for m in messages)


def test_plain_process_takes_the_shipped_parameter_file(ros_env, tmp_path):
    """What the launch file gives the node, by hand: --params-file config/estimator.yaml -p ..."""
    import subprocess
    import sys

    from sparse_body.core.resources import config_dir

    with open(tmp_path / "plain.log", "w") as log:  # the child holds its own copy
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                ESTIMATOR,
                "--ros-args",
                "--params-file",
                str(config_dir() / "estimator.yaml"),
                "-p",
                "autostart:=true",
                "-p",
                "sensors:=three_point",
                "-p",
                "estimator:=reference",
            ],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=ros_env,
        )
    listener = Listener(rclpy, {"joint_states": JointState})
    try:
        assert listener.spin_until(lambda: len(listener.received["joint_states"]) >= 5, STARTUP_LIMIT)
    finally:
        listener.destroy()
        stop(proc)
    assert "configured: reference on three_point" in (tmp_path / "plain.log").read_text()


def test_a_qos_override_changes_only_the_publisher_it_names(ros_env, tmp_path):
    from rclpy.qos import ReliabilityPolicy

    proc = start_node(
        ESTIMATOR,
        {
            "sensors": "three_point",
            "estimator": "reference",
            "autostart": True,
            "qos_overrides": {"/joint_states": {"publisher": {"reliability": "best_effort"}}},
        },
        "sparse_body_estimator",
        tmp_path,
        ros_env,
    )
    listener = Listener(rclpy, {"joint_states": JointState})
    try:
        node = listener.node

        def reliability(topic):
            infos = node.get_publishers_info_by_topic(topic)
            return infos[0].qos_profile.reliability if infos else None

        assert listener.spin_until(lambda: reliability("/estimate_status") is not None, STARTUP_LIMIT), (
            tmp_path / "sparse_body_estimator.log"
        ).read_text()
        assert reliability("/joint_states") == ReliabilityPolicy.BEST_EFFORT
        assert reliability("/foot_contacts") == ReliabilityPolicy.RELIABLE
        assert reliability("/estimate_status") == ReliabilityPolicy.RELIABLE
    finally:
        listener.destroy()
        stop(proc)


def test_the_tf_reader_ignores_the_frames_its_node_publishes(ros_env):
    from geometry_msgs.msg import TransformStamped
    from rclpy.serialization import serialize_message

    from sparse_body.ros.tf_input import TfReader

    node = rclpy.create_node("tf_reader_test")
    moved = []
    try:
        reader = TfReader(node, {"hmd"}, ignore_frames={"pelvis", "head", "hmd"}, on_tracker=lambda: moved.append(1))
        msg = TFMessage()
        for child in ("pelvis", "head", "hmd"):
            tf = TransformStamped()
            tf.header.frame_id, tf.child_frame_id = "world", child
            tf.header.stamp = node.get_clock().now().to_msg()
            tf.transform.rotation.w = 1.0
            msg.transforms.append(tf)
        reader._on_tf(serialize_message(msg), False)  # the reader subscribes raw: bytes
        assert reader.lookup("world", "hmd") is not None  # a tracker frame is never ignored
        assert reader.lookup("world", "pelvis") is None and reader.lookup("world", "head") is None
        assert moved == [1]
        msg.transforms[2].header.stamp.sec = 5  # judged by the node's clock: refused, counted
        reader._on_tf(serialize_message(msg), False)
        assert moved == [1] and reader.rejected["stamp far from the clock"] == 1
        reader._on_tf(serialize_message(msg)[:-3], False)  # cut short: counted, nothing else
        assert moved == [1] and reader.rejected["malformed message"] == 1
        reader.destroy()
    finally:
        node.destroy_node()


def test_held_for_no_input_says_when_trackers_arrive_but_are_refused(ros_env):
    """A tracker stamped far from the node's clock (a bag played with its own stamps, a peer's
    wrong clock) is refused: the held estimate says so, instead of only "no input yet"."""
    from geometry_msgs.msg import TransformStamped
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message

    from sparse_body.ros.estimator_node import EstimatorNode

    node = EstimatorNode(
        parameter_overrides=[Parameter("estimator", value="ik"), Parameter("sensors", value="four_point")]
    )
    try:
        node.trigger_configure()
        assert node.tf_in is not None
        assert node._held_reason(None, True, np.inf) == "held: no tracker input yet"
        tf = TransformStamped()
        tf.header.frame_id, tf.child_frame_id = "world", node._frames[0]
        tf.header.stamp.sec = 5  # the node's clock is now: decades away
        tf.transform.rotation.w = 1.0
        node.tf_in._on_tf(serialize_message(TFMessage(transforms=[tf])), False)
        reason = node._held_reason(None, True, np.inf)
        assert reason == "held: no tracker input yet (/tf samples refused: stamp far from the clock 1)", reason
        assert node._held_reason(None, True, 2.0) == "held: no tracker input for 2.0 s"
    finally:
        node.destroy_node()


def _position_noise(estimator):
    return estimator.input_filter.config.position_noise


def _floor_height(estimator):
    return estimator.options.floor_height


@pytest.mark.parametrize(
    "spec,parameters,read,expected",
    [
        ("ik:filter_position_noise=0.02", {}, _position_noise, 0.02),  # ran with 0.001: configure set it again
        ("ik", {"filter_position_noise": 0.03}, _position_noise, 0.03),
        ("ik:filter_position_noise=0.02", {"filter_position_noise": 0.03}, _position_noise, 0.03),  # a set one wins
        ("ik:floor_height=0.2", {}, _floor_height, 0.2),
        ("ik", {"ik.floor_height": 0.3}, _floor_height, 0.3),  # a method's option as the parameter NAME.<field>
        ("ik:floor_height=0.2", {"ik.floor_height": 0.3}, _floor_height, 0.3),  # a set one wins, as the filter's
        ("ik", {"lobstr.floor_height": 0.3}, _floor_height, 0.0),  # another method's: not this estimator's
    ],
)
def test_options_come_from_the_spec_string_then_the_parameters_set(ros_env, spec, parameters, read, expected):
    from rclpy.parameter import Parameter

    from sparse_body.ros.estimator_node import EstimatorNode

    node = EstimatorNode(
        parameter_overrides=[
            Parameter("estimator", value=spec),
            *(Parameter(k, value=v) for k, v in parameters.items()),
        ]
    )
    try:
        node.trigger_configure()
        assert node.estimator is not None
        assert read(node.estimator) == expected
        assert node.estimator.input_filter.config.rotation_noise == 0.33  # the others keep their defaults
    finally:
        node.destroy_node()


@pytest.mark.parametrize("signal_names", [["SIGINT"], ["SIGTERM"], ["SIGINT", "SIGINT"]])
def test_every_node_ends_cleanly_on_a_signal_while_data_flows(ros_env, tmp_path, signal_names):
    """SIGINT twice is a terminal's Ctrl-C under `ros2 launch`: every process of the launch gets
    it, and launch then sends its own; the second once came while the node was exiting, after
    Python had put the default handler back, and killed it (-2)."""
    import signal
    import time

    config = load_sensor_config("four_point")
    make_bag(synthetic_walk(4.0), config, tmp_path / "trackers")
    est = start_estimator({"sensors": "four_point", "estimator": "ik", "autostart": True}, tmp_path, ros_env)
    refiner = start_node(
        "sparse_body.ros.constraint_node",
        {"sensors": "four_point", "autostart": True},
        "sparse_body_constraint",
        tmp_path,
        ros_env,
        remaps={"input/joint_states": "/joint_states"},
    )
    bridge = start_node(
        BRIDGE,
        {"bag": str(tmp_path / "trackers"), "loop": True, "min_subscribers": 2},
        "sparse_body_tracker_bridge",
        tmp_path,
        ros_env,
    )
    procs = {"sparse_body_estimator": est, "sparse_body_constraint": refiner, "sparse_body_tracker_bridge": bridge}
    listener = Listener(
        rclpy,
        {"estimate_status": EstimateStatus, "refined/estimate_status": EstimateStatus},
        qos={"estimate_status": 1000, "refined/estimate_status": 1000},
    )
    try:
        # valid estimates: the trackers' data flows (held poses flow before the bridge is even
        # up; on a loaded machine its imports once took over 90 s, and a signal then tests nothing)
        flowing = listener.spin_until(
            lambda: (
                sum(s.valid for s in listener.received["estimate_status"]) >= 30
                and sum(s.valid for s in listener.received["refined/estimate_status"]) >= 5
            ),
            STARTUP_LIMIT,
        )
        assert flowing, "no valid estimates within STARTUP_LIMIT"
        for k, signal_name in enumerate(signal_names):
            time.sleep(0.5 * k)
            for p in procs.values():
                if p.poll() is None:
                    p.send_signal(getattr(signal, signal_name))
        codes = {}
        for name, p in procs.items():
            try:
                codes[name] = p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                codes[name] = "still running"
    finally:
        listener.destroy()
        stop(*procs.values())
    logs = {name: (tmp_path / f"{name}.log").read_text() for name in procs}
    for name in procs:
        assert codes[name] == 0, (name, codes[name], logs[name][-2000:])
        assert "Traceback" not in logs[name], (name, logs[name][-2000:])


@pytest.mark.parametrize("height", [-1.0, float("nan"), float("inf"), 100.0, "tall"])
def test_a_bad_height_refuses_configure_with_the_reason_and_the_node_stays_up(ros_env, tmp_path, height):
    import sys

    # given on the command line, as `ros2 run ... -p height:=...` gives it (it ended the process before)
    with open(tmp_path / "bad_height.log", "w") as log:  # the child holds its own copy
        value = height if isinstance(height, str) else repr(height).replace("nan", ".nan").replace("inf", ".inf")
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                ESTIMATOR,
                "--ros-args",
                "-p",
                "sensors:=three_point",
                "-p",
                "estimator:=reference",
                "-p",
                f"height:={value}",
            ],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=ros_env,
        )
    listener = Listener(rclpy, {})
    try:
        node = listener.node
        change = node.create_client(ChangeState, "/sparse_body_estimator/change_state")
        get = node.create_client(GetState, "/sparse_body_estimator/get_state")
        assert not _call(
            node,
            change,
            ChangeState.Request(transition=Transition(id=Transition.TRANSITION_CONFIGURE)),
            timeout=STARTUP_LIMIT,
        ).success
        assert _call(node, get, GetState.Request()).current_state.id == State.PRIMARY_STATE_UNCONFIGURED
        assert proc.poll() is None
    except AssertionError as err:  # what the node said, which the failure alone does not tell
        raise AssertionError(f"{err}\nthe node's log:\n{(tmp_path / 'bad_height.log').read_text()}") from None
    finally:
        listener.destroy()
        stop(proc)
    text = (tmp_path / "bad_height.log").read_text()
    assert "configure failed: height must be" in text and "Traceback" not in text, text


def test_parameters_set_while_configured_apply_live_or_are_refused_with_the_reason(ros_env, tmp_path):
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    proc = start_estimator({"sensors": "three_point", "estimator": "reference", "autostart": True}, tmp_path, ros_env)
    listener = Listener(rclpy, {"joint_states": JointState})
    try:
        node = listener.node
        assert listener.spin_until(lambda: listener.received["joint_states"], STARTUP_LIMIT)
        setp = node.create_client(SetParameters, "/sparse_body_estimator/set_parameters")

        def set_one(name, **value):
            kind = ParameterType.PARAMETER_STRING if "string_value" in value else ParameterType.PARAMETER_DOUBLE
            param = Parameter(name=name, value=ParameterValue(type=kind, **value))
            return _call(node, setp, SetParameters.Request(parameters=[param])).results[0]

        bogus = set_one("estimator", string_value="bogus")
        assert not bogus.successful and "unknown estimator 'bogus'" in bogus.reason
        later = set_one("sensors", string_value="six_point")
        assert not later.successful and "takes effect at configure" in later.reason
        live = set_one("stale_timeout", double_value=0.3)
        assert live.successful
        negative = set_one("stale_timeout", double_value=-1.0)  # refused by rclpy, from the declared range
        assert not negative.successful and "out of range" in negative.reason and "Min: 0.001" in negative.reason
        from rcl_interfaces.srv import DescribeParameters

        describe = node.create_client(DescribeParameters, "/sparse_body_estimator/describe_parameters")
        names = ["height", "predict_ahead", "foxglove_port", "estimator", "dragposer.iterations", "filter_jump"]
        names += ["lobstr.contact_threshold"]
        described = _call(node, describe, DescribeParameters.Request(names=names)).descriptors
        ranges = {
            d.name: [(r.from_value, r.to_value) for r in (*d.floating_point_range, *d.integer_range)] for d in described
        }
        assert ranges == {
            "height": [(0.5, 2.5)],
            "predict_ahead": [(0.0, 0.2)],
            "foxglove_port": [(0, 65535)],
            "estimator": [],
            "dragposer.iterations": [(1, 100)],  # each method's options, from its dataclass
            "filter_jump": [(0.0, 100.0)],  # the filter's, from FilterConfig
            "lobstr.contact_threshold": [(0.0, 1.0)],
        }
        help_text = {d.name: d.description for d in described}
        assert help_text["dragposer.iterations"] == "search steps a frame at most (steps)"
        zero = _call(
            node,
            setp,
            SetParameters.Request(
                parameters=[
                    Parameter(
                        name="dragposer.iterations",
                        value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=0),
                    )
                ]
            ),
        ).results[0]
        assert not zero.successful and "out of range" in zero.reason
    finally:
        listener.destroy()
        stop(proc)


def test_trackers_on_a_static_chain_count_as_current(ros_env, tmp_path):
    """Frames published once on /tf_static (a fixed tracker, a mock-up) are never stale."""
    from geometry_msgs.msg import TransformStamped

    from sparse_body.data.virtual_trackers import synthesize_trackers

    config = load_sensor_config("three_point")
    stream = synthesize_trackers(synthetic_walk(1.0), config)
    proc = start_estimator({"sensors": "three_point", "estimator": "ik", "autostart": True}, tmp_path, ros_env)
    listener = Listener(rclpy, {"estimate_status": EstimateStatus})
    latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    pub = listener.node.create_publisher(TFMessage, "/tf_static", latched)
    msg = TFMessage()
    for s, site in enumerate(config.sites):
        tf = TransformStamped()
        tf.header.frame_id, tf.child_frame_id = "world", site.frame_id
        tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z = map(
            float, stream.positions[0, s]
        )
        (tf.transform.rotation.x, tf.transform.rotation.y, tf.transform.rotation.z, tf.transform.rotation.w) = map(
            float, stream.orientations[0, s]
        )
        msg.transforms.append(tf)
    pub.publish(msg)
    try:
        assert listener.spin_until(
            lambda: sum(s.valid for s in listener.received["estimate_status"]) >= 10, STARTUP_LIMIT
        ), {s.message for s in listener.received["estimate_status"]}
    finally:
        listener.destroy()
        stop(proc)


def test_the_estimator_parameter_names_every_estimator():
    from sparse_body.methods.factory import estimator_names
    from sparse_body.ros.estimator_node import PARAMETERS

    text = PARAMETERS["estimator"][1]
    assert all(name in text for name in estimator_names()), text


def test_a_node_stopped_longer_than_tracker_timeout_is_late_not_invalid_when_it_resumes(ros_env, tmp_path):
    """A starved CPU, taken to the extreme: the estimator process is stopped (SIGSTOP) for
    twice tracker_timeout while the trackers go on. On resuming it must not take the trackers
    for stopped (tracker_timeout is judged by when samples arrive, not by the node's lateness):
    every estimate after the pause is valid."""
    import os
    import signal

    config = load_sensor_config("six_point")
    make_bag(synthetic_walk(4.0), config, tmp_path / "trackers")
    est = start_estimator(
        {"sensors": "six_point", "estimator": "ik", "autostart": True, "tracker_timeout": 1.0}, tmp_path, ros_env
    )
    bridge = start_node(
        BRIDGE, {"bag": str(tmp_path / "trackers"), "loop": True}, "sparse_body_tracker_bridge", tmp_path, ros_env
    )
    listener = Listener(rclpy, {"estimate_status": EstimateStatus}, qos={"estimate_status": 1000})
    statuses = listener.received["estimate_status"]
    try:
        assert listener.spin_until(lambda: sum(s.valid for s in statuses) >= 30, STARTUP_LIMIT), (
            tmp_path / "sparse_body_estimator.log"
        ).read_text()
        os.kill(est.pid, signal.SIGSTOP)
        try:
            listener.spin_for(2.0)
        finally:
            os.kill(est.pid, signal.SIGCONT)
        before = len(statuses)
        listener.spin_until(lambda: len(statuses) >= before + 30, STARTUP_LIMIT)
    finally:
        listener.destroy()
        stop(est, bridge)
    after = statuses[before:]
    assert len(after) >= 30
    assert [s.message for s in after if not s.valid] == [], [s.message for s in statuses if not s.valid]


def test_the_bridge_is_a_lifecycle_node_whose_transitions_start_and_stop_the_samples(ros_env, tmp_path):
    """autostart:=false: the bridge waits unconfigured and publishes nothing; configure reads
    the bag, activate starts it playing on /tf, deactivate stops it, cleanup releases it; a
    configure that fails (no such bag) leaves it up and unconfigured. With autostart (the
    default) the same failure ends the process with exit code 1 and the reason in its log."""
    from tf2_msgs.msg import TFMessage

    config = load_sensor_config("six_point")
    make_bag(synthetic_walk(4.0), config, tmp_path / "trackers")
    params = {"bag": str(tmp_path / "trackers"), "loop": True, "autostart": False, "start_delay": 0.0}
    bridge = start_node(BRIDGE, params, "sparse_body_tracker_bridge", tmp_path, ros_env)
    listener = Listener(rclpy, {"/tf": TFMessage})
    tf = listener.received["/tf"]
    try:
        node = listener.node
        transition, state = _lifecycle(node, "sparse_body_tracker_bridge")
        assert state() == State.PRIMARY_STATE_UNCONFIGURED
        assert transition(Transition.TRANSITION_CONFIGURE) and state() == State.PRIMARY_STATE_INACTIVE
        listener.spin_for(1.0)
        assert tf == []  # configured, not active: nothing on /tf
        assert transition(Transition.TRANSITION_ACTIVATE)
        assert listener.spin_until(lambda: len(tf) >= 30, STARTUP_LIMIT)
        assert {t.child_frame_id for m in tf for t in m.transforms} == {s.frame_id for s in config.sites}
        assert transition(Transition.TRANSITION_DEACTIVATE)
        listener.spin_for(0.5)
        count = len(tf)
        listener.spin_for(1.0)
        assert len(tf) == count  # deactivated: stopped
        assert transition(Transition.TRANSITION_ACTIVATE)  # and it plays again
        assert listener.spin_until(lambda: len(tf) >= count + 30, STARTUP_LIMIT)
        assert transition(Transition.TRANSITION_DEACTIVATE) and transition(Transition.TRANSITION_CLEANUP)
        assert state() == State.PRIMARY_STATE_UNCONFIGURED

        from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
        from rcl_interfaces.srv import SetParameters

        setp = node.create_client(SetParameters, "/sparse_body_tracker_bridge/set_parameters")
        missing = str(tmp_path / "no_such_bag")
        value = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=missing)
        _call(node, setp, SetParameters.Request(parameters=[Parameter(name="bag", value=value)]))
        assert not transition(Transition.TRANSITION_CONFIGURE)
        assert state() == State.PRIMARY_STATE_UNCONFIGURED and bridge.poll() is None
    finally:
        listener.destroy()
        stop(bridge)
    assert "configure failed" in (tmp_path / "sparse_body_tracker_bridge.log").read_text()

    failing = tmp_path / "autostart"
    failing.mkdir()
    proc = start_node(BRIDGE, {"bag": missing}, "sparse_body_tracker_bridge", failing, ros_env)
    try:
        assert proc.wait(timeout=STARTUP_LIMIT) == 1
    finally:
        stop(proc)
    log = (failing / "sparse_body_tracker_bridge.log").read_text()
    assert "configure failed" in log and "no_such_bag" in log, log


def test_the_bridge_plays_only_once_the_nodes_it_waits_for_take_tf(ros_env, tmp_path):
    """wait_for_nodes: a /tf listener that is not the consumer (a test's, a viewer's) does not
    start the bag; the named node's /tf subscription does (the launch file names its estimator,
    which a busy machine once configured 2 s into the replay)."""
    from tf2_msgs.msg import TFMessage

    make_bag(synthetic_walk(4.0), load_sensor_config("six_point"), tmp_path / "trackers")
    params = {"bag": str(tmp_path / "trackers"), "wait_for_nodes": ["late_consumer"], "start_delay": 0.0}
    bridge = start_node(BRIDGE, params, "sparse_body_tracker_bridge", tmp_path, ros_env)
    listener = Listener(rclpy, {"/tf": TFMessage})
    tf = listener.received["/tf"]
    consumer = None
    try:
        assert listener.spin_until(lambda: listener.node.count_publishers("/tf") > 0, STARTUP_LIMIT)
        listener.spin_for(2.0)
        assert tf == []  # subscribed, but not the node it waits for
        consumer = rclpy.create_node("late_consumer")
        consumer.create_subscription(TFMessage, "/tf", lambda _: None, 10)
        assert listener.spin_until(lambda: len(tf) >= 30, STARTUP_LIMIT)
    finally:
        if consumer is not None:
            consumer.destroy_node()
        listener.destroy()
        stop(bridge)


def test_generated_tf_messages_never_stop_the_node_nor_give_a_non_finite_joint(ros_env, tmp_path):
    """Hypothesis writes /tf messages of any doubles (NaN, infinities, 1e308, 2e154, denormals),
    any frame names (ours among them) and any stamps; each goes to the live node between frames
    of well-formed trackers. The node stays up and every JointState it publishes is finite."""
    from geometry_msgs.msg import TransformStamped
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    from sparse_body.data.virtual_trackers import synthesize_trackers
    from sparse_body.ros.messages import to_time

    config = load_sensor_config("four_point")
    stream = synthesize_trackers(synthetic_walk(4.0), config)
    frames = [s.frame_id for s in config.sites]
    est = start_estimator({"sensors": "four_point", "estimator": "ik", "autostart": True}, tmp_path, ros_env)
    listener = Listener(rclpy, {"joint_states": JointState})
    pub = listener.node.create_publisher(TFMessage, "/tf", 100)
    sent = [0]

    def trackers_now() -> TFMessage:
        i = sent[0] % len(stream)
        stamp = to_time(listener.node.get_clock().now().nanoseconds * 1e-9)
        msgs = []
        for s, frame in enumerate(frames):
            m = TransformStamped()
            m.header.frame_id, m.child_frame_id, m.header.stamp = "world", frame, stamp
            t, q = m.transform.translation, m.transform.rotation
            t.x, t.y, t.z = map(float, stream.positions[i, s])
            q.x, q.y, q.z, q.w = map(float, stream.orientations[i, s])
            msgs.append(m)
        sent[0] += 1
        return TFMessage(transforms=msgs)

    doubles = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True) | st.sampled_from(
        [1e308, -1e308, 2e154, 5e-324, 0.0, 1.0]
    )
    names = st.sampled_from([*frames, "world", "sparse_body/pelvis", "pelvis"]) | st.text(
        st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=12
    )
    transform = st.tuples(
        names,
        names,
        st.integers(-(2**31), 2**31 - 1),
        st.integers(0, 2**32 - 1),
        st.lists(doubles, min_size=7, max_size=7),
    )

    @settings(max_examples=300, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(st.lists(transform, min_size=1, max_size=5))
    def send(transforms):
        msgs = []
        for parent, child, sec, nanosec, v in transforms:
            m = TransformStamped()
            m.header.frame_id, m.child_frame_id = parent, child
            m.header.stamp.sec, m.header.stamp.nanosec = sec, nanosec
            t, q = m.transform.translation, m.transform.rotation
            t.x, t.y, t.z, q.x, q.y, q.z, q.w = v
            msgs.append(m)
        pub.publish(TFMessage(transforms=msgs))
        pub.publish(trackers_now())
        listener.spin_for(0.005)

    try:
        end = time.monotonic() + STARTUP_LIMIT
        while not listener.received["joint_states"] and time.monotonic() < end:
            pub.publish(trackers_now())
            listener.spin_for(1.0 / 60)
        assert listener.received["joint_states"], "estimator did not start"
        send()
        for _ in range(30):  # then plain trackers: it still estimates
            pub.publish(trackers_now())
            listener.spin_for(1.0 / 60)
        alive = est.poll() is None
    finally:
        listener.destroy()
        stop(est)
    assert alive, (tmp_path / "sparse_body_estimator.log").read_text()[-3000:]
    states = listener.received["joint_states"]
    assert len(states) > 100 and all(np.all(np.isfinite(m.position)) for m in states)


@pytest.mark.parametrize("signal_name", ["SIGINT", "SIGTERM"])
def test_a_signal_during_a_cold_start_ends_the_node_at_once(ros_env, tmp_path, signal_name):
    """A start with no compiled kernels (a cache of its own, empty) compiles for most of a
    minute; a signal then ends the node within seconds with exit code 0 (issue 52: it waited
    for the compile, and `ros2 launch` escalated to SIGKILL)."""
    import signal

    env = {**ros_env, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "NUMBA_DEBUG_CACHE": "1", "PYTHONUNBUFFERED": "1"}
    node = start_estimator({"sensors": "four_point", "estimator": "dragposer", "autostart": True}, tmp_path, env)
    log = tmp_path / "sparse_body_estimator.log"
    try:
        deadline = time.monotonic() + STARTUP_LIMIT
        while "[cache] data saved" not in log.read_text() and node.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert "[cache] data saved" in log.read_text(), log.read_text()[-3000:]  # compiling: the start is under way
        assert "configured" not in log.read_text()
        sent = time.monotonic()
        node.send_signal(getattr(signal, signal_name))
        code = node.wait(timeout=60)
        took = time.monotonic() - sent
    finally:
        stop(node)
    text = log.read_text()
    assert code == 0, text[-3000:]
    assert "stopped while starting" in text and "Traceback" not in text, text[-3000:]
    print(f"{signal_name} during a cold start: ended {took:.2f} s after the signal")
    assert took < 5.0, f"{took:.1f} s from the signal to the end"


def test_a_stopped_start_stays_quiet_about_what_its_interrupt_left_half_built(ros_env, monkeypatch):
    """An interrupt inside numba's compile can leave an llvmlite object unbuilt, whose __del__
    then fails as it is collected: while stopping, that is not printed; anything else is."""
    import types

    import llvmlite.binding.ffi as ffi

    from sparse_body.ros import spin

    printed = []
    monkeypatch.setattr(spin.sys, "__unraisablehook__", printed.append)
    half_built = types.SimpleNamespace(object=ffi.ObjectRef.__del__, exc_value=AttributeError("_as_parameter_"))
    other = types.SimpleNamespace(object=print, exc_value=AttributeError("x"))
    monkeypatch.setattr(spin, "_STOP", types.SimpleNamespace(is_set=lambda: True))
    spin._quiet_dropped_interrupts(half_built)
    spin._quiet_dropped_interrupts(other)
    assert printed == [other]
    monkeypatch.setattr(spin, "_STOP", types.SimpleNamespace(is_set=lambda: False))
    spin._quiet_dropped_interrupts(half_built)  # not stopping: said
    assert printed == [other, half_built]


def test_a_parameter_over_the_spec_s_same_option_is_said_in_the_log(ros_env, capfd):
    """With the parameter predict_ahead 0.1 and `estimator:=ik:predict_ahead=0.2` the node
    logged 0.2 (its spec) while the parameter's 0.1 stamped the poses."""
    from rclpy.parameter import Parameter

    from sparse_body.ros.estimator_node import EstimatorNode

    node = EstimatorNode(
        parameter_overrides=[
            Parameter("estimator", value="ik:predict_ahead=0.2"),
            Parameter("predict_ahead", value=0.1),
        ]
    )
    try:
        node.trigger_configure()
        assert node.estimator is not None and node.estimator.ahead == 0.1
    finally:
        node.destroy_node()
    assert "the parameter sets predict_ahead to 0.1 over the estimator spec's 0.2" in capfd.readouterr().err


def test_the_bridge_s_diagnostics_and_waiting_end_quietly_when_a_stop_destroys_the_node(ros_env, tmp_path):
    """A terminal's Ctrl-C destroyed the bridge while its diagnostics timer ran in the
    executor's other thread: it raised, and rclpy printed "The following exception was never
    retrieved: cannot use Destroyable because destruction was requested"."""
    import threading

    from rclpy.parameter import Parameter

    from sparse_body.ros.tracker_bridge_node import TrackerBridge

    make_bag(synthetic_walk(1.0), load_sensor_config("six_point"), tmp_path / "trackers")
    node = TrackerBridge(parameter_overrides=[Parameter("bag", value=str(tmp_path / "trackers"))])
    node.trigger_configure()
    assert node.source is not None and node.pub_diag is not None
    publish, wait = node._publish_diagnostics, node._wait_for_subscribers
    pub = node.pub
    node.destroy_node()
    publish()  # the timer's callback after the stop began: ends without raising
    node.pub = pub  # a source thread that took the publisher before the stop
    node.params["wait_for_nodes"], node.params["min_subscribers"] = ["someone"], 1
    assert wait(threading.Event()) is False


TOY_SOURCE = """
import numpy as np


class Toy:
    def __init__(self, context):
        self.context = context

    def start(self):  # three samples of the head tracker at once
        frame = self.context.sensors.sites[0].frame_id
        site = self.context.sensors.sites[0].site
        self.context.send([(site, None, frame, self.context.now(), np.zeros(3), np.array([0.0, 0, 0, 1]))] * 3)

    def stop(self):
        pass

    close = stop

    def diagnostics(self):
        return "", {"toy": "yes"}


def make(context):
    context.log("a toy source")
    return Toy(context)
"""


def test_a_tracker_source_is_one_file_and_a_line_in_the_registry(ros_env, tmp_path, monkeypatch, capfd):
    """Issue 76: adding a source took three Python files and two configs (an `if kind == "vmc"`
    branch); now one module with a maker and its line in SOURCES."""
    from rclpy.parameter import Parameter

    from sparse_body.ros import tracker_sources
    from sparse_body.ros.tracker_bridge_node import TrackerBridge

    (tmp_path / "toy_source.py").write_text(TOY_SOURCE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(tracker_sources.SOURCES, "toy", "toy_source:make")
    node = TrackerBridge(parameter_overrides=[Parameter("source", value="toy")])
    try:
        node.trigger_configure()
        assert type(node.source).__name__ == "Toy"
        node.trigger_activate()
        assert node.published == 3  # through the bridge's own /tf publisher
    finally:
        node.destroy_node()
    unknown = TrackerBridge(parameter_overrides=[Parameter("source", value="carrier_pigeon")])
    try:
        unknown.trigger_configure()
        assert unknown.source is None  # configure failed, in one line naming the sources
    finally:
        unknown.destroy_node()
    said = capfd.readouterr().err
    assert "a toy source" in said and "must be one of bag, vmc, serial, toy, got 'carrier_pigeon'" in said, said


def test_a_body_lying_down_is_said_out_of_depth_on_estimate_status(ros_env, tmp_path):
    """The default four-point estimator (upright) stands a lying body up for its base and says
    so on estimate_status, valid, with the share of the tilt it took out; the joints stay finite."""
    from sparse_body.data.floor import lying

    config = load_sensor_config("four_point")
    motion = lying(synthetic_walk(3.0, speed=0.3), "lying on the front")  # short strides: the pelvis stays low
    listener = replay_bag(rclpy, ros_env, tmp_path, motion, config, {"estimator": "auto"})
    statuses = during_playback(listener, "estimate_status")
    deep = [s for s in statuses if s.valid and s.message.startswith("out of depth")]
    assert len(statuses) >= 30 and len(deep) >= 0.6 * len(statuses), {s.message for s in statuses}  # after its settling
    assert "degrees from upright; blend shown it stood up" in deep[-1].message, deep[-1].message
    assert max(float(s.message.split()[3].rstrip(":")) for s in deep) > 0.8, deep[-1].message
    assert all(np.all(np.isfinite(m.position)) for m in listener.received["joint_states"])


def _pelvis_height(batch) -> list[bytes]:
    """A toy output: std_msgs/Float64 of each pose's pelvis height (CDR: the header, a double)."""
    import struct

    return [b"\x00\x01\x00\x00" + struct.pack("<d", float(root[2])) for root in batch.poses.roots]


def test_an_output_topic_is_one_function_and_a_line_in_the_registry(ros_env, tmp_path, monkeypatch):
    """Issue 76: an output took five Python files and a fixed 3-tuple encoder; now a function of
    the pose batch and its line in POSE_OUTPUTS, and the live node, its Foxglove view and the
    estimate bag carry it, from the same bytes."""
    from rclpy.lifecycle import LifecycleNode
    from std_msgs.msg import Float64

    from sparse_body.core.skeleton import Skeleton
    from sparse_body.core.types import BodyPose, BodyPoses
    from sparse_body.io import pose_outputs
    from sparse_body.io.bagio import read_topic
    from sparse_body.io.estimate_bag import write_estimate_bag
    from sparse_body.ros.estimate_outputs import EstimateOutputs

    toy = pose_outputs.PoseOutput("/pelvis_height", "std_msgs/msg/Float64", _pelvis_height)
    monkeypatch.setattr(pose_outputs, "POSE_OUTPUTS", [*pose_outputs.POSE_OUTPUTS, toy])
    from sparse_body.io import estimate_bag
    from sparse_body.ros import estimate_outputs

    monkeypatch.setattr(estimate_bag, "POSE_OUTPUTS", pose_outputs.POSE_OUTPUTS)
    monkeypatch.setattr(estimate_outputs, "POSE_OUTPUTS", pose_outputs.POSE_OUTPUTS)
    skeleton = Skeleton.canonical()
    motion = synthetic_walk(1.0)
    poses = [
        BodyPose(i / motion.fps, motion.local_quats[i], motion.root_positions[i], np.zeros(2), np.zeros(2, bool))
        for i in range(len(motion))
    ]
    # the bag: the toy topic among the others, a message a pose
    bag = tmp_path / "body"
    write_estimate_bag(bag, poses, skeleton, topics=("/joint_states", "/pelvis_height"))
    heights = [msg.data for msg in read_topic(bag, "/pelvis_height")]
    assert np.allclose(heights, motion.root_positions[:, 2]) and len(read_topic(bag, "/joint_states")) == len(poses)
    # the node: a publisher of its type under the output namespace, publishing those bytes
    node = LifecycleNode("toy_outputs")
    received: list[float] = []
    node.create_subscription(Float64, "pelvis_height", lambda m: received.append(m.data), 10)
    try:
        node.trigger_configure()
        params = {"frame_prefix": "", "publish_link_tf": False, "foxglove_port": 0}
        outputs = EstimateOutputs(node, "", skeleton, "world", params)
        node.trigger_activate()
        executor = rclpy.executors.SingleThreadedExecutor()
        executor.add_node(node)
        deadline = time.monotonic() + STARTUP_LIMIT
        while not received and time.monotonic() < deadline:
            outputs.publish(poses[3], 1.0, "")
            executor.spin_once(timeout_sec=0.1)
        assert received and received[0] == pytest.approx(motion.root_positions[3, 2])
        outputs.destroy()
    finally:
        node.destroy_node()
    # the live view: a channel of its own (where foxglove-sdk is installed)
    pytest.importorskip("foxglove", reason="foxglove-sdk is not installed")
    from sparse_body.ros.live_view import LiveView

    view = LiveView("127.0.0.1", 0, "<robot name='body'/>")
    try:
        view.log(
            "/pelvis_height", _pelvis_height(pose_outputs.PoseBatch.of(BodyPoses.of([poses[3]]), skeleton, "w"))[0], 1.0
        )
    finally:
        view.close()
