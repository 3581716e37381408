"""Bags that draw themselves (issue 34): a processed bag carries the body's URDF, every link
of it on /tf, and the trackers, so Foxglove's 3D panel or RViz shows the body as it moves."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader

from sparse_body.apps.offline import make_bag, process_bag
from sparse_body.core.rotations import quat_to_matrix
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import NUM_JOINTS
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.io.bagio import DESCRIPTION_TOPIC, JOINT_STATES_TOPIC, TF_TOPIC, read_topic
from sparse_body.io.output import joint_state_names


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _tf_poses(message, fixed: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every frame's (rotation, position) in the fixed frame by walking up its parents, as a
    viewer's TF buffer does; a frame whose chain does not reach the fixed frame is absent."""
    parent = {t.child_frame_id: t for t in message.transforms}
    poses = {fixed: (np.eye(3), np.zeros(3))}

    def pose(frame: str, depth: int = 0):
        if frame in poses:
            return poses[frame]
        t = parent.get(frame)
        if t is None or depth > 200:
            return None
        up = pose(t.header.frame_id, depth + 1)
        if up is None:
            return None
        q, v = t.transform.rotation, t.transform.translation
        rot = quat_to_matrix(np.array([q.x, q.y, q.z, q.w]))
        poses[frame] = (up[0] @ rot, up[0] @ np.array([v.x, v.y, v.z]) + up[1])
        return poses[frame]

    for frame in parent:
        pose(frame)
    return poses


def test_a_processed_bag_holds_the_urdf_its_links_on_tf_and_the_trackers(tmp_path):
    """By default /tf holds the links with a shape (robot_state_publisher computes the massless
    ones from /joint_states); with axis_links, every link of the URDF."""
    motion = synthetic_walk(1.5)
    config = load_sensor_config("six_point")
    make_bag(motion, config, tmp_path / "in")
    process_bag(tmp_path / "in", tmp_path / "small", "ik", config, motion.skeleton, progress=False)
    process_bag(tmp_path / "in", tmp_path / "out", "ik", config, motion.skeleton, progress=False, axis_links=True)
    (urdf,) = read_topic(tmp_path / "small", DESCRIPTION_TOPIC)
    shaped = [link.get("name") for link in ET.fromstring(urdf.data).iter("link") if link.find("visual") is not None]
    tfs = read_topic(tmp_path / "small", TF_TOPIC)
    for k in (0, len(tfs) - 1):
        poses = _tf_poses(tfs[k], config.fixed_frame)
        assert set(shaped) <= set(poses) and len(shaped) == NUM_JOINTS, shaped
        assert not [name for name in poses if name.endswith("_link")]  # no massless link

    with Reader(tmp_path / "out") as reader:
        (description,) = [c for c in reader.connections if c.topic == DESCRIPTION_TOPIC]
        # offered as transient local: `ros2 bag play` latches it for a late RViz
        assert [q.durability for q in description.ext.offered_qos_profiles] == [QosDurability.TRANSIENT_LOCAL]
        first = next(iter(reader.messages()))[0].topic
    assert first == DESCRIPTION_TOPIC  # before any /tf, as robot_state_publisher starts
    (urdf,) = read_topic(tmp_path / "out", DESCRIPTION_TOPIC)
    robot = ET.fromstring(urdf.data)
    joints = {j.get("name"): j for j in robot.iter("joint")}
    links = [link.get("name") for link in robot.iter("link")]
    assert sorted(joints) == sorted(joint_state_names())

    states = read_topic(tmp_path / "out", JOINT_STATES_TOPIC)
    tfs = read_topic(tmp_path / "out", TF_TOPIC)
    assert len(tfs) == len(states) == len(motion)
    for k in (0, len(tfs) // 2, len(tfs) - 1):
        poses = _tf_poses(tfs[k], config.fixed_frame)
        missing = [name for name in links if name not in poses]
        assert not missing, f"frame {k}: links without a TF chain to {config.fixed_frame}: {missing[:5]}"
        assert {s.frame_id for s in config.sites} <= set(poses)  # the trackers beside the body
        # robot_state_publisher's view (URDF joints driven by the JointState) equals the TF
        angle = dict(zip(states[k].name, states[k].position, strict=True))
        for name, joint in joints.items():
            parent, child = joint.find("parent").get("link"), joint.find("child").get("link")
            xyz = np.array(joint.find("origin").get("xyz").split(), float)
            axis = np.array(joint.find("axis").get("xyz").split(), float)
            rot, pos = poses[parent]
            want_rot = rot @ _axis_rotation(axis, angle[name])
            np.testing.assert_allclose(poses[child][0], want_rot, atol=1e-6, err_msg=name)
            np.testing.assert_allclose(poses[child][1], pos + rot @ xyz, atol=1e-6, err_msg=name)


def test_the_page_of_an_estimate_bag_shows_the_body_and_plays_in_a_real_browser(tmp_path):
    import shutil

    pytest.importorskip("plotly")
    playwright = pytest.importorskip(
        "playwright.sync_api", reason="playwright (requirements-test.txt) is not installed"
    )
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("no chromium here (Debian's package chromium; `make setup-dev` installs it where it can)")
    from PIL import Image

    from sparse_body.apps.viewer import bag_bodies, write_body_page
    from sparse_body.core.kinematics import forward_kinematics

    motion = synthetic_walk(3.0)
    config = load_sensor_config("six_point")
    make_bag(motion, config, tmp_path / "in")
    poses = process_bag(
        tmp_path / "in", tmp_path / "out", "ik", config, motion.skeleton, progress=False, keep_poses=True
    ).poses
    positions, trackers, fps, _ = bag_bodies(tmp_path / "out")
    _, want = forward_kinematics(
        quat_to_matrix(np.array([p.local_quats for p in poses])),
        np.array([p.root_position for p in poses]),
        motion.skeleton.offsets,
    )
    # the bag's body is the estimate, in the published numbers' float32 precision (0.06 um a metre)
    np.testing.assert_allclose(positions, want, atol=1e-6)
    assert fps == 60.0 and trackers.shape == (len(poses), len(config.sites), 3)
    page = write_body_page(tmp_path / "body.html", fps, estimate=positions, trackers=trackers, title="walk")
    assert '<script src="http' not in page.read_text()  # plotly.js is inside: no network needed

    blue = np.array([0x1F, 0x5F, 0xBF])

    def body_pixels(png) -> np.ndarray:
        image = np.asarray(Image.open(png).convert("RGB"), dtype=int)
        return np.all(np.abs(image - blue) < 40, axis=-1)  # the estimate's bones and joints

    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(
            executable_path=chromium, args=["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"]
        )
        try:
            view = browser.new_page(viewport={"width": 900, "height": 700})
            view.set_default_timeout(300_000)  # software WebGL on a busy machine: every step is slow
            view.route(
                "**/*", lambda route: route.continue_() if route.request.url.startswith("file:") else route.abort()
            )
            view.goto(page.as_uri())
            view.wait_for_selector("text=t = 0.00 s")
            view.wait_for_timeout(1000)
            view.screenshot(path=tmp_path / "start.png")
            view.get_by_text("play", exact=True).click()
            view.wait_for_function(  # the slider has moved on: the animation plays
                "() => ![...document.querySelectorAll('text')].some(t => t.textContent === 't = 0.00 s')"
            )
            view.get_by_text("pause", exact=True).click()
            view.wait_for_timeout(1000)
            view.screenshot(path=tmp_path / "played.png")
        finally:
            browser.close()
    start, played = body_pixels(tmp_path / "start.png"), body_pixels(tmp_path / "played.png")
    assert start.sum() > 100, "no body drawn"
    assert played.sum() > 100 and (start != played).sum() > 50, "the body did not move when played"
    # the camera follows and frames the body: it fills at least a third of the view's height
    # (the legend's blue line, at the left edge, is not the body)
    for name, pixels in (("start", start), ("played", played)):
        rows = np.flatnonzero(pixels[:, 150:].any(axis=1))
        assert rows.max() - rows.min() >= pixels.shape[0] / 3, f"{name}: the body is {rows.max() - rows.min()} px tall"


def test_a_live_view_that_is_not_there_is_a_one_line_error(capsys):
    import socket

    from sparse_body.cli import main

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    for extra, said in (([], "no live view there"), (["--seconds", "0"], "seconds must be between")):
        with pytest.raises(SystemExit) as ended:
            main(["view", f"ws://127.0.0.1:{port}", *extra])
        err = capsys.readouterr().err
        assert ended.value.code != 0 and said in err and len(err.strip().splitlines()) == 1, err


def test_a_live_view_that_closes_mid_recording_or_sends_unexpected_json_keeps_what_came(tmp_path, capsys):
    """A server (a real WebSocket one on this machine, speaking foxglove.websocket.v1 as
    foxglove_bridge does) that sends JSON of other shapes and text
    that is no JSON, then some bodies on /tf, then closes the connection: the page holds the
    bodies that came (ConnectionClosedError and a KeyError were tracebacks)."""
    import struct
    import threading

    from websockets.sync.server import serve

    from sparse_body.apps.live_record import LEGACY_SUBPROTOCOL, MESSAGE_DATA
    from sparse_body.cli import main
    from sparse_body.core.skeleton import NUM_JOINTS, Skeleton
    from sparse_body.io import cdr
    from sparse_body.io.output import body_table

    skeleton = Skeleton.canonical()
    quats = np.tile([0.0, 0.0, 0.0, 1.0], (30, NUM_JOINTS, 1))
    table = body_table(quats, np.tile([0.0, 0.0, 1.0], (30, 1)), skeleton, "world")
    bodies = cdr.tf_messages(1e9 + np.arange(30) / 60, table.parents, table.children, table.values)

    def handler(ws):
        for text in (
            "[1, 2]",
            '{"op": "advertise", "channels": "x"}',
            "not json",
            '{"op": "advertise", "channels": [{"topic": "/tf", "encoding": "cdr"}]}',
            '{"channels": [null]}',
        ):
            ws.send(text)
        ws.send('{"op": "advertise", "channels": [{"id": 7, "topic": "/tf", "encoding": "cdr"}]}')
        ws.recv(timeout=5)  # the subscription
        for body in bodies:
            ws.send(struct.pack("<BIQ", MESSAGE_DATA, 1, 0) + body)
        ws.socket.close()  # the node stops: no closing handshake

    # a server that speaks only the older protocol name (foxglove_bridge's): it was refused
    with serve(handler, "127.0.0.1", 0, subprotocols=[LEGACY_SUBPROTOCOL]) as server:
        threading.Thread(target=server.serve_forever, daemon=True).start()
        port = server.socket.getsockname()[1]
        with pytest.raises(SystemExit) as ended:
            main(["view", f"ws://127.0.0.1:{port}", "--seconds", "5", "-o", str(tmp_path / "live.html")])
        server.shutdown()
    captured = capsys.readouterr()
    assert ended.value.code == 0, captured.err
    assert "30 estimates" in captured.out and (tmp_path / "live.html").is_file()


def test_reading_a_long_bag_for_the_page_holds_bodies_not_messages(tmp_path):
    """bag_bodies reads /tf one message at a time: the rows of every message held at once cost
    42 kB a frame (a 5-minute bag took 982 MB), the bodies about a quarter of that."""
    import tracemalloc

    from sparse_body.apps.viewer import bag_bodies

    motion = synthetic_walk(10.0)
    config = load_sensor_config("six_point")
    make_bag(motion, config, tmp_path / "in")
    process_bag(tmp_path / "in", tmp_path / "out", "ik", config, motion.skeleton, progress=False)
    tracemalloc.start()
    try:
        positions, _, _, _ = bag_bodies(tmp_path / "out")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(positions) == 600 and peak / len(positions) < 20_000, f"{peak / len(positions):.0f} bytes a frame"


def test_the_urdf_draws_a_body_from_joint_to_joint_with_head_hands_and_feet():
    """RViz draws the URDF's visuals: each body link a capsule to each child joint, the ends of
    the body one along their bone (it drew 17 small spheres: no limbs, nothing at head, hands
    or feet). The massless links inside each joint lie on their body link and draw nothing."""
    from sparse_body.core.skeleton import JOINT_NAMES, PARENTS, Skeleton
    from sparse_body.io.urdf import body_urdf

    skeleton = Skeleton.canonical(1.6)
    robot = ET.fromstring(body_urdf(skeleton))
    links = {link.get("name"): link for link in robot.iter("link")}
    assert set(JOINT_NAMES) <= set(links)
    for j, name in enumerate(JOINT_NAMES):
        cylinders = links[name].findall("visual/geometry/cylinder")
        children = [c for c in range(len(JOINT_NAMES)) if PARENTS[c] == j and np.linalg.norm(skeleton.offsets[c]) > 0]
        assert len(cylinders) == max(len(children), 1), name  # a bone to each child, or the end's own
        for c, visual in zip(children, links[name].findall("visual")[1::2], strict=False):
            length = float(visual.find("geometry/cylinder").get("length"))
            assert length == pytest.approx(np.linalg.norm(skeleton.offsets[c]), abs=1e-4), (name, JOINT_NAMES[c])
    top = links["head"].findall("visual/origin")[-1]  # the skull's far sphere: above the head joint
    assert float(top.get("xyz").split()[2]) > 0.05
    others = [n for n in links if n not in JOINT_NAMES]
    assert len(others) == 42 and all(not links[n].findall("visual") for n in others)


def test_the_foxglove_layout_shows_what_the_package_publishes():
    """config/sparse_body.foxglove.json (Foxglove: Layouts > Import): every panel the layout
    places is configured, the 3D panel follows a link of the URDF in the fixed frame, and each
    topic and message field it names is one the node publishes."""
    import json
    import re

    from sparse_body.core.resources import config_dir
    from sparse_body.core.skeleton import Skeleton
    from sparse_body.io.bagio import CONTACTS_TOPIC, DESCRIPTION_TOPIC, STATUS_TOPIC, typestore
    from sparse_body.io.topics import ROBOT_DESCRIPTION_TOPIC
    from sparse_body.io.urdf import body_urdf

    layout = json.loads((config_dir() / "sparse_body.foxglove.json").read_text())

    def placed(node) -> list[str]:
        return [node] if isinstance(node, str) else placed(node["first"]) + placed(node["second"])

    assert set(placed(layout["layout"])) == set(layout["configById"])
    body = layout["configById"]["3D!body"]
    links = {link.get("name") for link in ET.fromstring(body_urdf(Skeleton.canonical())).iter("link")}
    assert body["followTf"] in links and body["layers"]["grid"]["frameId"] == "world"
    assert set(body["topics"]) == {DESCRIPTION_TOPIC, ROBOT_DESCRIPTION_TOPIC}  # the body, and a retargeted robot
    assert layout["configById"]["DiagnosticSummary!nodes"]["topicToRender"] == "/diagnostics"
    assert layout["configById"]["RawMessages!status"]["topicPath"] == STATUS_TOPIC
    store = typestore()
    fields = {name for name, _ in store.fielddefs["sparse_body/msg/FootContact"][1]}
    for path in layout["configById"]["Plot!contacts"]["paths"]:
        topic, field = re.fullmatch(r"(/\w+)\.contacts\[\d\]\.(\w+)", path["value"]).groups()
        assert topic == CONTACTS_TOPIC and field in fields


def test_the_page_of_a_five_minute_bag_peaks_under_300_mb_and_draws_one_frame_in_two(tmp_path):
    """`view` once peaked at 806 MB for a 300 s bag (5 s: 249 MB) making a 28 MB page: every
    frame read, then thousands of plotly objects. Now the frames the page draws are kept while
    reading and the page is written a frame at a time."""
    import subprocess
    import sys

    motion = synthetic_walk(300.0)
    config = load_sensor_config("six_point")
    make_bag(motion, config, tmp_path / "in")
    process_bag(tmp_path / "in", tmp_path / "out", "ik", config, motion.skeleton, progress=False)
    script = (
        "import sys; from sparse_body.cli import main\n"
        "try:\n    main(['view', sys.argv[1], '-o', sys.argv[2]])\nexcept SystemExit as end:\n    code = end.code\n"
        "print(next(l for l in open('/proc/self/status') if l.startswith('VmHWM')).split()[1]); sys.exit(code)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script, str(tmp_path / "out"), str(tmp_path / "page.html")],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    peak_mb = int(done.stdout.split()[-1]) / 1024
    assert peak_mb < 300, f"view peaked at {peak_mb:.0f} MB"
    head = (tmp_path / "page.html").read_text()[:6_000_000]
    assert "300.0 s at 60 Hz, one frame in 2 drawn" in head
