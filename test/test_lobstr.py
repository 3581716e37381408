"""LoBSTr: features, the network's streaming export, contact IK, and the estimator on real clips."""

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import shipped_model

from sparse_body.core.contact_hold import ContactHold, release_weight
from sparse_body.core.contacts import FOOT_JOINTS
from sparse_body.core.kinematics import forward_kinematics
from sparse_body.core.resources import models_dir
from sparse_body.core.rotations import axis_angle_to_matrix, quat_to_matrix, yaw_matrix
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.core.skeleton import Skeleton, standing_pose
from sparse_body.data.catalog import load_clip
from sparse_body.data.virtual_trackers import TrackerNoise, synthesize_trackers
from sparse_body.estimators.onnx_model import ModelMissing
from sparse_body.methods.factory import create_estimator
from sparse_body.methods.lobstr.features import (
    INPUT_JOINTS,
    apply_legs,
    apply_upper,
    features,
    leg_targets,
    sequence_features,
    upper_targets,
)


@pytest.fixture(scope="module")
def clip(train_clip_index):
    return load_clip(train_clip_index["02_05"]).slice(0, 300)


@pytest.fixture(scope="module")
def lobstr_model():
    """The shipped model and its training report."""
    return shipped_model("lobstr")


def test_features_do_not_depend_on_where_the_person_stands_or_faces(clip):
    pos, rot = clip.positions[:, INPUT_JOINTS], clip.global_rotations[:, INPUT_JOINTS]
    turn = yaw_matrix(1.1)
    moved_pos = np.einsum("ij,tkj->tki", turn, pos) + [3.0, -2.0, 0.0]
    moved_rot = turn @ rot
    a, b = sequence_features(pos, rot), sequence_features(moved_pos, moved_rot)
    assert a.shape == (len(clip), 37)
    np.testing.assert_allclose(a, b, atol=1e-9)
    # ...but lifting the person changes the reference height, and only that
    lifted = sequence_features(pos + [0, 0, 0.5], rot)
    np.testing.assert_allclose(lifted[:, :36], a[:, :36], atol=1e-9)
    np.testing.assert_allclose(lifted[:, 36] - a[:, 36], 0.5)
    # the first frame has no velocity: identity rotations, zero translations
    assert np.allclose(a[0, 0:3], 0) and np.allclose(a[0, 3:9], [1, 0, 0, 0, 1, 0])
    # the learned upper body's inputs: the same 37, then the pose, which does not depend on
    # where the person stands or faces either, but does on where the hands are
    c, d = sequence_features(pos, rot, pose=True), sequence_features(moved_pos, moved_rot, pose=True)
    assert c.shape == (len(clip), 70)
    np.testing.assert_allclose(c[:, :37], a, atol=1e-12)
    np.testing.assert_allclose(c, d, atol=1e-9)
    raised = pos.copy()
    raised[:, 2, 2] += 0.3  # the left hand 30 cm higher
    e = sequence_features(raised, rot, pose=True)
    np.testing.assert_allclose(
        e[:, 37 + 9 : 37 + 18] - c[:, 37 + 9 : 37 + 18],
        np.tile([0, 0, 0.3, 0, 0, 0, 0, 0, 0], (len(clip), 1)),
        atol=1e-9,
    )


def test_one_frame_s_compiled_features_equal_the_sequence_s(clip):
    """A streaming step's features (compiled) and a sequence's (numpy, what training sees)
    agree within 1e-12, with and without the pose, at any floor."""
    pos, rot = clip.positions[:, INPUT_JOINTS], clip.global_rotations[:, INPUT_JOINTS]
    for pose in (False, True):
        for floor in (0.0, 0.07):
            sequence = sequence_features(pos, rot, floor, pose=pose)
            for t in range(1, len(clip), 7):
                one = features(pos[t], rot[t], pos[t - 1], rot[t - 1], floor, pose=pose)
                np.testing.assert_allclose(one, sequence[t], rtol=0, atol=1e-12)


def test_applying_an_output_is_numpy_s_sixd_and_the_hips_turned_from_the_reference_frame(rng):
    """apply_legs / apply_upper (compiled) against the numpy expression they replaced."""
    from scipy.spatial.transform import Rotation

    from sparse_body.core.rotations import heading, sixd_to_matrix, yaw_matrix
    from sparse_body.methods.lobstr.features import HIPS, LEG_JOINTS, UPPER_JOINTS

    local = Rotation.random(22, random_state=5).as_matrix()
    legs6, upper6 = rng.normal(size=48), rng.normal(size=78)
    legs = sixd_to_matrix(legs6.reshape(1, 8, 6))[0]  # numpy's batched path
    expected = local.copy()
    expected[list(LEG_JOINTS)] = legs
    expected[list(HIPS)] = local[0].T @ yaw_matrix(heading(local[0])) @ legs[:2]
    np.testing.assert_allclose(apply_legs(local, legs6), expected, rtol=0, atol=1e-12)
    expected = local.copy()
    expected[list(UPPER_JOINTS)] = sixd_to_matrix(upper6.reshape(1, -1, 6))[0]
    np.testing.assert_allclose(apply_upper(local, upper6), expected, rtol=0, atol=1e-12)


def test_leg_targets_round_trip_through_apply_legs(clip):
    glob, local = clip.global_rotations, clip.local_rotations
    targets = leg_targets(glob, local)
    upper = upper_targets(local)
    for t in (0, 150, len(clip) - 1):
        np.testing.assert_allclose(apply_legs(local[t], targets[t]), local[t], atol=1e-9)
        np.testing.assert_allclose(apply_upper(local[t], upper[t]), local[t], atol=1e-9)
        assert not np.allclose(apply_upper(local[t], upper[t + 1 - 2 * (t > 0)]), local[t], atol=1e-3)


@pytest.mark.train
@pytest.mark.parametrize("learned_upper", [False, True])
def test_streaming_onnx_equals_the_recurrent_net_over_the_window(tmp_path, clip, learned_upper):
    """The runtime carries the GRU state; running the exported step frame by frame must give
    what the training graph gives for the whole window at once."""
    import onnxruntime as ort
    import torch

    from sparse_body.train.lobstr.model import LobstrConfig, LobstrNet
    from sparse_body.train.lobstr.train import export_onnx

    torch.manual_seed(0)
    config = LobstrConfig(hidden=32, latent=16, learned_upper=learned_upper)
    net = LobstrNet(config).eval()
    x = sequence_features(
        clip.positions[:90, INPUT_JOINTS], clip.global_rotations[:90, INPUT_JOINTS], pose=learned_upper
    )
    x = x.astype(np.float32)
    net.mean.copy_(torch.from_numpy(x.mean(0)))
    net.std.copy_(torch.from_numpy(x.std(0) + 1e-3))
    export_onnx(net, tmp_path / "net.onnx", {"method": "lobstr", "config": config.to_dict()})
    session = ort.InferenceSession(str(tmp_path / "net.onnx"), providers=["CPUExecutionProvider"])
    state = np.zeros((1, 1, config.hidden), np.float32)
    streamed_legs, streamed_prob = [], []
    for t in range(len(x)):
        legs, prob, state = session.run(None, {"features": x[t : t + 1], "state": state})
        streamed_legs.append(legs[0])
        streamed_prob.append(prob[0])
    with torch.no_grad():
        legs, logits, _ = net(torch.from_numpy(x[None]))
    np.testing.assert_allclose(np.stack(streamed_legs), legs[0].numpy(), atol=1e-4)
    np.testing.assert_allclose(np.stack(streamed_prob), torch.softmax(logits[0], -1)[..., 1].numpy(), atol=1e-4)
    assert np.abs(np.diff(np.stack(streamed_legs), axis=0)).max() > 1e-3  # the state did carry something


def test_onnx_metadata_carries_the_configuration(lobstr_model):
    import onnxruntime as ort

    path, report = lobstr_model
    meta = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]).get_modelmeta().custom_metadata_map
    assert json.loads(meta["method"]) == "lobstr"
    assert json.loads(meta["config"]) == report["config"]


def test_estimator_gives_one_finite_pose_per_frame_and_survives_bad_samples(lobstr_model, clip):
    path, _ = lobstr_model
    config = load_sensor_config("four_point")
    stream = synthesize_trackers(clip, config, TrackerNoise(drop_probability=0.05), seed=3)
    stream.positions[100:110, 1] = np.nan  # a headset reporting NaN
    stream.orientations[200, 0] = [0, 0, 0, 0]  # a degenerate pelvis quaternion
    # a missing tracker missing (not carried with the others): its frames have no new pose
    missing = {"filter_carry_lost": 0.0, "filter_reacquire_speed": 0.0}
    est = create_estimator("lobstr", config, clip.skeleton, model_path=str(path), **missing)
    poses = est.process(stream)
    assert len(poses) == len(stream)
    assert all(p.is_finite() for p in poses)
    assert all(np.all(np.isfinite(p.contact_probability)) for p in poses if p.valid)
    bad = ~stream.valid.all(axis=1) | np.isnan(stream.positions).any(axis=(1, 2))
    bad[200] = True
    valid = np.array([p.valid for p in poses])
    assert not valid[bad].any() and valid[~bad].all()
    # by default a missing tracker is carried with the head: frames missing another tracker
    # have a valid pose, but for some right after the head itself came back (each carried
    # tracker keeps the anchor it was lost with)
    carried = create_estimator("lobstr", config, clip.skeleton, model_path=str(path)).process(stream)
    head = stream.sites.index("head")
    head_usable = stream.valid[:, head] & np.isfinite(stream.positions[:, head]).all(axis=1)
    head_usable[200] &= head != 0  # the degenerate quaternion is site 0's
    valid = np.array([p.valid for p in carried])
    assert all(p.is_finite() for p in carried)
    others_lost = bad & head_usable
    assert valid[others_lost].sum() >= 0.8 * others_lost.sum() > 10, (valid[others_lost].sum(), others_lost.sum())
    # the upper body follows the hands exactly (IK); the legs are the network's
    local = quat_to_matrix(poses[50].local_quats)
    _, pos = forward_kinematics(local, poses[50].root_position, clip.skeleton.offsets)
    np.testing.assert_allclose(pos[J["left_wrist"]], clip.positions[50, J["left_wrist"]], atol=0.01)


def test_learned_upper_body_is_the_networks_put_on_the_trackers_and_false_is_the_papers_ik(lobstr_model, clip):
    """The network's upper body, turned onto the headset and hands (learned_upper, the
    default with a model trained with it); learned_upper=false is the paper's: the IK's."""
    from sparse_body.core.skeleton import UPPER_BODY

    path, report = lobstr_model
    assert report["config"]["learned_upper"]
    config = load_sensor_config("four_point")
    stream = synthesize_trackers(clip, config, TrackerNoise(), seed=1)
    learned = create_estimator("lobstr", config, clip.skeleton, model_path=str(path)).process(stream)
    paper = create_estimator("lobstr", config, clip.skeleton, model_path=str(path), learned_upper=False).process(stream)
    ik = create_estimator("ik", config, clip.skeleton).process(stream)
    upper = [J[n] for n in UPPER_BODY]
    differ = 0
    for a, b, c in zip(learned, paper, ik, strict=True):
        pa, pb, pc = (quat_to_matrix(p.local_quats)[upper] for p in (a, b, c))
        np.testing.assert_allclose(pb, pc, atol=1e-9)
        differ += not np.allclose(pa, pc, atol=1e-3)
    assert differ > 0.9 * len(learned)
    # the head and hands sit on their trackers within the IK's soft reach (a frame whose
    # predicted torso leaves a hand out of reach is the IK's)
    misses = []
    for t, pose in enumerate(learned):
        _, pos = forward_kinematics(quat_to_matrix(pose.local_quats), pose.root_position, clip.skeleton.offsets)
        misses.append(
            max(np.linalg.norm(pos[J[j]] - clip.positions[t, J[j]]) for j in ("head", "left_wrist", "right_wrist"))
        )
    paper_misses = []
    for t, pose in enumerate(paper):
        _, pos = forward_kinematics(quat_to_matrix(pose.local_quats), pose.root_position, clip.skeleton.offsets)
        paper_misses.append(
            max(np.linalg.norm(pos[J[j]] - clip.positions[t, J[j]]) for j in ("head", "left_wrist", "right_wrist"))
        )
    assert np.median(misses) < 0.01 and np.mean(np.array(misses) > 0.02) < 0.2
    assert np.mean(paper_misses) < 0.01


def test_estimator_refuses_a_missing_or_foreign_model(tmp_path, clip, lobstr_model):
    config = load_sensor_config("four_point")
    with pytest.raises(ModelMissing, match="train one"):
        create_estimator("lobstr", config, clip.skeleton, model_path=str(tmp_path / "none.onnx"))
    (tmp_path / "junk.onnx").write_bytes(b"not a model")
    with pytest.raises(ValueError, match="junk.onnx"):
        create_estimator("lobstr", config, clip.skeleton, model_path=str(tmp_path / "junk.onnx"))
    with pytest.raises(ValueError, match="needs trackers on pelvis"):
        create_estimator("lobstr", load_sensor_config("three_point"), clip.skeleton, model_path=str(lobstr_model[0]))
    for bad in (-0.01, 0.05, float("nan")):  # a tolerance the fallback's 2 cm would override
        with pytest.raises(ValueError, match="spine_tolerance"):
            create_estimator("lobstr", config, clip.skeleton, model_path=str(lobstr_model[0]), spine_tolerance=bad)
    # metadata that claims LoBSTr over a graph with other inputs: refused when loaded, not at every step
    import onnx
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        [helper.make_node("Identity", ["x"], ["y"])],
        "other",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 5])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 5])],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    helper.set_model_props(model, {"method": '"lobstr"', "config": '{"hidden": 8, "fps": 60}'})
    onnx.save(model, tmp_path / "claims_lobstr.onnx")
    with pytest.raises(ValueError, match=r"claims_lobstr\.onnx: a lobstr model needs an input 'features'"):
        create_estimator("lobstr", config, clip.skeleton, model_path=str(tmp_path / "claims_lobstr.onnx"))
    # DragPoser pointed at the LoBSTr file: refused, not silently the shipped models beside it
    with pytest.raises(ValueError, match="not a DragPoser model"):
        create_estimator("dragposer", config, clip.skeleton, model_path=str(lobstr_model[0]))


def test_an_ensemble_steps_each_network_with_its_own_state_and_averages_their_outputs(tmp_path, clip, lobstr_model):
    """Two networks on the same features: each keeps its own GRU state (the mean of the two
    runs apart, frame after frame), and a second model trained otherwise is refused in a line."""
    import onnx
    from onnx import numpy_helper

    from sparse_body.methods.lobstr.estimator import LobstrEnsemble, LobstrModel

    model = onnx.load(str(lobstr_model[0]))  # another network: the shipped one, its weights moved
    for init in model.graph.initializer:
        if init.data_type == onnx.TensorProto.FLOAT and len(init.dims) == 2:
            w = numpy_helper.to_array(init)
            init.CopyFrom(numpy_helper.from_array(w * 0.9 + 0.01, init.name))
    onnx.save(model, tmp_path / "other.onnx")
    first, other = LobstrModel(lobstr_model[0]), LobstrModel(tmp_path / "other.onnx")
    x = sequence_features(clip.positions[:60, INPUT_JOINTS], clip.global_rotations[:60, INPUT_JOINTS], pose=True)
    both, alone = LobstrEnsemble([first, other]), [first, other]
    states = [both.initial_state(), *(a.initial_state() for a in alone)]
    for t in range(len(x)):
        (pose, prob, states[0]), *apart = [e.step(x[t], s) for e, s in zip([both, *alone], states, strict=True)]
        states[1:] = [a[2] for a in apart]
        np.testing.assert_allclose(pose, (apart[0][0] + apart[1][0]) / 2, atol=1e-6)
        np.testing.assert_allclose(prob, (apart[0][1] + apart[1][1]) / 2, atol=1e-6)
    assert np.abs(apart[0][0] - apart[1][0]).max() > 1e-3  # (the two do differ)
    # one model trained at another rate: its outputs mean other things, so it is refused
    props = {p.key: p.value for p in model.metadata_props}
    config = json.loads(props["config"])
    onnx.helper.set_model_props(model, {**props, "config": json.dumps({**config, "fps": 30.0})})
    onnx.save(model, tmp_path / "at_30.onnx")
    with pytest.raises(ValueError, match=r"at_30\.onnx: not averaged with .*lobstr\.onnx"):
        create_estimator(
            "lobstr",
            load_sensor_config("four_point"),
            clip.skeleton,
            model_path=str(lobstr_model[0]),
            ensemble_path=str(tmp_path / "at_30.onnx"),
        )


def test_contact_hold_pins_the_toe_then_lets_go_slowly():
    skeleton = Skeleton.canonical()
    hold = ContactHold(skeleton, release_frames=10)
    local = standing_pose()
    local[J["left_knee"]] = local[J["right_knee"]] = axis_angle_to_matrix([0.0, 0.3, 0.0])  # knees a little bent
    root = np.array([0.0, 0.0, 0.95])
    _, pos = forward_kinematics(local, root, skeleton.offsets)
    anchor = pos[FOOT_JOINTS[0]].copy()
    toes = []
    for t in range(30):
        moved = root + [0.01 * t, 0.0, -0.004 * t]  # the pelvis walks on and sinks a little
        contact = np.array([t < 15, False])
        out = hold.apply(local, moved, contact)
        _, p = forward_kinematics(out, moved, skeleton.offsets)
        _, free = forward_kinematics(local, moved, skeleton.offsets)
        toes.append((p[FOOT_JOINTS[0]], free[FOOT_JOINTS[0]], p[FOOT_JOINTS[1]], free[FOOT_JOINTS[1]]))
    for t in range(15):  # held: the toe stays where contact began
        assert np.linalg.norm(toes[t][0] - anchor) < 0.005, t
    for t in range(30):  # the other foot, never in contact, is left alone
        np.testing.assert_allclose(toes[t][2], toes[t][3], atol=1e-9)
    # released over 10 frames: from the anchor to the network's toe, slow at both ends
    gaps = [np.linalg.norm(toes[t][0] - toes[t][1]) for t in range(15, 26)]
    assert gaps[0] > 0.1 and gaps[-1] < 1e-3
    assert all(a >= b - 1e-4 for a, b in zip(gaps, gaps[1:], strict=False))
    w = [release_weight(k, 10) for k in range(11)]
    assert w[0] == 0 and w[10] == 1 and w[1] < 0.1 and w[9] > 0.9 and np.allclose(w[5], 0.5)


def test_contact_hold_lets_go_of_a_point_out_of_reach():
    skeleton = Skeleton.canonical()
    hold = ContactHold(skeleton)
    local = standing_pose()
    root = np.array([0.0, 0.0, 0.9])
    hold.apply(local, root, np.array([True, True]))
    far = root + [1.5, 0.0, 0.0]  # the body jumped 1.5 m
    out = hold.apply(local, far, np.array([True, True]))
    _, p = forward_kinematics(out, far, skeleton.offsets)
    assert np.all(np.isfinite(out))
    assert np.linalg.norm(p[FOOT_JOINTS[0]][:2] - far[:2]) < 1.2  # not stretched back to the old point


@pytest.mark.train
def test_train_is_one_command(tmp_path, train_mocap):
    out = tmp_path / "m.onnx"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "sparse_body.cli",
            "train",
            "lobstr",
            "--config",
            "tiny",
            "--steps",
            "2",
            "--limit",
            "1",
            "--out",
            str(out),
            "--no-card",
            "--mocap",
            str(train_mocap),
        ],
        check=True,
        capture_output=True,
    )
    report = json.loads(out.with_suffix(".train.json").read_text())
    assert out.is_file() and report["steps"] == 2 and report["train_clips"] == 1


@pytest.mark.train
def test_noisy_copies_wear_their_trackers_off_the_same_way_through_a_clip(clip):
    from sparse_body.train.lobstr.train import clip_tensors

    # LoBSTr's own noise, then a 6-degree mounting turn and 2 cm mounting shift per site
    plain = clip_tensors(clip, 8, np.random.default_rng(0))
    worn = clip_tensors(clip, 8, np.random.default_rng(0), mounting=(6.0, 0.02))
    np.testing.assert_array_equal(plain.x[0], worn.x[0])  # the clean copy is the clip's
    np.testing.assert_array_equal(plain.legs, worn.legs)
    # per-frame noise averages out over a clip; a mounting error does not
    off_plain = np.abs((plain.x[1:] - plain.x[:1]).mean(axis=1)).mean()
    off_worn = np.abs((worn.x[1:] - worn.x[:1]).mean(axis=1)).mean()
    assert off_worn > 3 * off_plain


@pytest.mark.skipif(not (models_dir() / "lobstr.onnx").is_file(), reason="no shipped LoBSTr model")
def test_shipped_model_beats_the_ik_baseline_on_a_test_clip(clip_index):
    """The trained model on a held-out person's walk with a 90-degree turn: legs and contacts
    better than the IK baseline's standing legs. (On a boxing clip, 17_10, standing legs get
    as many contacts right as the model, 77 %: a boxer mostly stands.)"""
    from sparse_body.data.catalog import load_split
    from sparse_body.evaluation import evaluate_motion

    assert "16_17" in load_split()["test"]
    motion = load_clip(clip_index["16_17"])
    config = load_sensor_config("four_point")
    lobstr = evaluate_motion(motion, "lobstr", config)
    ik = evaluate_motion(motion, "ik", config)
    assert lobstr["Lower RE [deg]"] < ik["Lower RE [deg]"]
    assert lobstr["Contact acc [%]"] > ik["Contact acc [%]"] + 10.0
    assert lobstr["Toe PE [cm]"] < ik["Toe PE [cm]"]


def test_estimator_node_runs_lobstr_over_dds(lobstr_model, tmp_path, clip, ros_env):
    """estimator:=lobstr with the four-point configuration, fed by the tracker bridge."""
    import rclpy

    pytest.importorskip("tf2_msgs.msg")
    from ros_helpers import STARTUP_LIMIT, Listener, start_node, stop
    from sensor_msgs.msg import JointState

    from sparse_body.apps.offline import make_bag
    from sparse_body.msg import EstimateStatus, FootContacts

    env = ros_env
    config = load_sensor_config("four_point")
    make_bag(clip.slice(0, 180), config, tmp_path / "trackers")
    est = start_node(
        "sparse_body.ros.estimator_node",
        {
            "sensors": "four_point",
            "estimator": "lobstr",
            "model_path": str(lobstr_model[0]),
            "autostart": True,
            "height": clip.skeleton.height(),
        },
        "sparse_body_estimator",
        tmp_path,
        env,
    )
    listener = Listener(
        rclpy, {"joint_states": JointState, "foot_contacts": FootContacts, "estimate_status": EstimateStatus}
    )
    bridge = None
    try:
        assert listener.spin_until(lambda: listener.received["joint_states"], STARTUP_LIMIT), (
            tmp_path / "sparse_body_estimator.log"
        ).read_text()
        bridge = start_node(
            "sparse_body.ros.tracker_bridge_node",
            {"bag": str(tmp_path / "trackers"), "min_subscribers": 1, "start_delay": 0.5},
            "sparse_body_tracker_bridge",
            tmp_path,
            env,
        )
        # deadlines, not rates: a starved CPU is slower, not wrong
        listener.spin_until(lambda: sum(s.valid for s in listener.received["estimate_status"]) >= 30, STARTUP_LIMIT)
    finally:
        listener.destroy()
        stop(est, *([bridge] if bridge else []))
    valid = sum(s.valid for s in listener.received["estimate_status"])
    assert valid >= 30, (tmp_path / "sparse_body_estimator.log").read_text()
    assert all(np.all(np.isfinite(m.position)) for m in listener.received["joint_states"])
    probabilities = np.array([c.probability for m in listener.received["foot_contacts"] for c in m.contacts])
    known = probabilities[np.isfinite(probabilities)]  # NaN: no estimate yet
    assert len(known) >= 2 * 30 and np.all((known >= 0.0) & (known <= 1.0))
