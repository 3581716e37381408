"""DTP: features, the ONNX export against torch, the estimator on real clips with occluded and
missing feet, the lookahead variant offline, and the occlusion protocol every estimator is
measured under."""

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from conftest import shipped_model

from sparse_body.core.resources import models_dir
from sparse_body.core.rotations import yaw_matrix
from sparse_body.core.sensors import load_sensor_config
from sparse_body.data.catalog import load_clip
from sparse_body.data.field_protocol import FIELD_EXACT, Protocol, user_view
from sparse_body.data.virtual_trackers import NO_NOISE, VR_NOISE, synthesize_trackers
from sparse_body.methods.dtp.features import INPUT_JOINTS, leaf_features, window_features
from sparse_body.methods.factory import create_estimator

SIX = load_sensor_config("six_point")


@pytest.fixture(scope="module")
def clip(train_clip_index):
    return load_clip(train_clip_index["02_05"]).slice(0, 240)


@pytest.fixture(scope="module")
def dtp_models():
    """The shipped online model (its stage before fine-tuning beside it) and lookahead model,
    with their training reports."""
    (online, online_report), (lookahead, lookahead_report) = shipped_model("dtp"), shipped_model("dtp_lookahead")
    paths = {"online": online, "online.pretrained": online.with_suffix(".pretrained.onnx"), "lookahead": lookahead}
    return paths, {"online": online_report, "lookahead": lookahead_report}


def _features(motion, current=-1):
    pos, rot = motion.positions[:, INPUT_JOINTS], motion.global_rotations[:, INPUT_JOINTS]
    leaves = leaf_features(pos[:, 0], rot[:, 0], pos[:, 1:], rot[:, 1:])
    return window_features(pos[:, 0], rot[:, 0], leaves, current)


def test_window_features_do_not_depend_on_where_the_person_stands_or_faces(clip):
    window = clip.slice(100, 121)
    turn = yaw_matrix(np.array(1.2))
    moved = replace(window, root_positions=window.root_positions @ turn.T + [3.0, -2.0, 0.0])
    quats = moved.local_quats.copy()
    from scipy.spatial.transform import Rotation

    quats[:, 0] = (Rotation.from_matrix(turn) * Rotation.from_quat(quats[:, 0])).as_quat()
    moved = replace(moved, local_quats=quats)
    np.testing.assert_allclose(_features(moved), _features(window), atol=1e-9)
    # ... but they do see the person move: the pelvis of earlier frames is not at the origin
    assert np.abs(_features(window)[0, :2]).max() > 0.01


@pytest.mark.train
def test_onnx_gives_the_torch_models_output_on_the_same_window(tmp_path, clip):
    """Any window length up to the trained one, online and with future frames; a token never
    sees further ahead than `future` frames."""
    import onnxruntime as ort
    import torch

    from sparse_body.train.dtp.model import DtpConfig, DtpNet
    from sparse_body.train.dtp.train import export_onnx

    x = _features(clip.slice(0, 26), current=20).astype(np.float32)
    for future in (0, 5):
        torch.manual_seed(0)
        config = DtpConfig(d_model=32, heads=4, layers=2, feedforward=64, future=future)
        net = DtpNet(config).eval()
        with torch.no_grad():
            net.position.normal_(0.0, 0.1)
        net.mean.copy_(torch.from_numpy(x.mean(0)))
        net.std.copy_(torch.from_numpy(x.std(0) + 1e-3))
        path = tmp_path / f"dtp{future}.onnx"
        export_onnx(net, path, {"method": "dtp", "config": config.to_dict()})
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        for n in (1, 7, config.window):
            onnx_out = session.run(None, {"window": x[None, :n]})[0][0]
            with torch.no_grad():
                torch_out = net(torch.from_numpy(x[None, :n]))[0].numpy()
            np.testing.assert_allclose(onnx_out, torch_out, atol=1e-4)
        window = x[: config.window]
        changed = window.copy()
        changed[15:] += 1.0
        out = session.run(None, {"window": changed[None]})[0][0]
        base = session.run(None, {"window": window[None]})[0][0]
        np.testing.assert_allclose(out[: 15 - future], base[: 15 - future], atol=1e-5)
        assert np.abs(out[15 - future :] - base[15 - future :]).max() > 1e-3


def test_onnx_metadata_carries_the_configuration_and_both_stages_are_kept(dtp_models):
    import onnxruntime as ort

    models, reports = dtp_models
    meta = ort.InferenceSession(str(models["online"]), providers=["CPUExecutionProvider"]).get_modelmeta()
    assert json.loads(meta.custom_metadata_map["method"]) == "dtp"
    assert json.loads(meta.custom_metadata_map["config"]) == reports["online"]["config"]
    assert json.loads(meta.custom_metadata_map["stage"]) == "finetune"
    pretrained = ort.InferenceSession(str(models["online.pretrained"]), providers=["CPUExecutionProvider"])
    assert json.loads(pretrained.get_modelmeta().custom_metadata_map["stage"]) == "pretrain"
    assert set(reports["online"]["stages"]) == {"pretrain", "finetune"}


def test_missing_feet_read_as_occluded_and_the_body_goes_on(dtp_models, clip):
    models, _ = dtp_models
    stream = synthesize_trackers(clip, SIX, VR_NOISE, seed=3)
    foot, head = stream.sites.index("left_foot"), stream.sites.index("head")
    stream.valid[50:110, foot] = False  # a foot tracker gone for a second
    stream.positions[50:110, foot] = np.nan
    stream.orientations[130:140, stream.sites.index("right_foot")] = np.nan  # and one giving NaN
    stream.positions[160:165, head] = np.nan  # the headset gone: no pose
    est = create_estimator("dtp", SIX, clip.skeleton, model_path=str(models["online"]), filter=False)
    poses = est.process(stream)
    assert len(poses) == len(stream) and all(p.is_finite() for p in poses)
    valid = np.array([p.valid for p in poses])
    assert valid[:160].all() and not valid[160:165].any() and valid[165:].all()
    # the pelvis is the tracker's; the polish puts the hands on theirs, not the missing foot on the origin
    np.testing.assert_allclose(poses[80].root_position, clip.positions[80, 0], atol=0.01)
    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.rotations import quat_to_matrix
    from sparse_body.core.skeleton import JOINT_INDEX as J

    raw = create_estimator(
        "dtp", SIX, clip.skeleton, model_path=str(models["online"]), filter=False, polish=False
    ).process(stream)

    def joints(pose):
        return forward_kinematics(quat_to_matrix(pose.local_quats), pose.root_position, clip.skeleton.offsets)[1]

    wrists = [J["left_wrist"], J["right_wrist"]]
    for t in (30, 80, 200):
        polished = np.linalg.norm(joints(poses[t])[wrists] - clip.positions[t, wrists], axis=-1)
        network = np.linalg.norm(joints(raw[t])[wrists] - clip.positions[t, wrists], axis=-1)
        assert np.all(polished < 0.5 * network), (t, polished, network)
    assert np.linalg.norm(joints(poses[80])[J["left_ankle"]]) > 0.3


def test_a_gap_starts_the_window_over(dtp_models, clip):
    models, _ = dtp_models
    stream = synthesize_trackers(clip, SIX, seed=1)
    est = create_estimator("dtp", SIX, clip.skeleton, model_path=str(models["online"]), filter=False)
    est.reset()
    for t in range(100):
        est.step(stream.frame(t))
    late = stream.frame(150)
    late = replace(late, stamp=late.stamp + 5.0)  # seconds later: nothing before it counts
    after_gap = est.step(late)
    fresh = create_estimator("dtp", SIX, clip.skeleton, model_path=str(models["online"]), filter=False)
    fresh.reset()
    np.testing.assert_allclose(after_gap.local_quats, fresh.step(late).local_quats, atol=1e-6)


def test_lookahead_sees_the_frames_after_each_one_offline(dtp_models, clip):
    models, reports = dtp_models
    future = reports["lookahead"]["config"]["future"]
    stream = synthesize_trackers(clip.slice(0, 60), SIX, seed=2)
    est = create_estimator("dtp", SIX, clip.skeleton, model_path=str(models["lookahead"]), filter=False)
    offline = est.process(stream)
    assert len(offline) == len(stream) and all(p.valid and p.is_finite() for p in offline)
    changed = synthesize_trackers(clip.slice(0, 60), SIX, seed=2)
    changed.positions[40:, :, 0] += 0.3  # everything from frame 40 on moves
    again = est.process(changed)
    same = [np.allclose(a.local_quats, b.local_quats, atol=1e-6) for a, b in zip(offline, again, strict=True)]
    assert all(same[: 40 - future]) and not any(same[40 - future : 40])
    # live, step() cannot see the future: it differs from the offline pose
    est.reset()
    live = [est.step(f) for f in stream]
    assert not np.allclose(live[30].local_quats, offline[30].local_quats, atol=1e-6)


def test_lookahead_offline_eases_a_returning_hand_as_a_live_step_does(dtp_models, clip):
    """Offline, the lookahead model's frames are sampled ahead of its poses; each pose is made
    once the frames after it are sampled, so a returning hand starts from where the last pose
    had it (filter_reacquire_speed) instead of snapping from wherever the method guessed."""
    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.rotations import quat_to_matrix
    from sparse_body.core.skeleton import JOINT_INDEX

    models, _ = dtp_models
    stream = synthesize_trackers(clip.slice(0, 120), SIX, seed=2)
    hand = stream.sites.index("left_hand")
    stream.valid[40:70, hand] = False
    stream.positions[40:, hand] += [0.0, 0.3, 0.0]  # it comes back 30 cm from where it was lost
    wrist = JOINT_INDEX["left_wrist"]

    def largest_step_after_return(**options) -> float:
        est = create_estimator("dtp", SIX, clip.skeleton, model_path=str(models["lookahead"]), **options)
        poses = est.process(stream)
        joints = [
            forward_kinematics(quat_to_matrix(p.local_quats), p.root_position, clip.skeleton.offsets)[1] for p in poses
        ]
        return max(np.linalg.norm(joints[t][wrist] - joints[t - 1][wrist]) for t in range(70, 80))

    eased, snapped = largest_step_after_return(), largest_step_after_return(filter_reacquire_speed=0.0)
    assert snapped > 0.15 and eased < 0.1, (eased, snapped)


def test_occlusion_protocol_occludes_the_share_asked_one_or_both_feet_both_ways(clip_index):
    noise = NO_NOISE.occluding(20)
    assert noise.occluded_percent == pytest.approx(20.0)
    motion = load_clip(clip_index["16_17"])
    clean = synthesize_trackers(motion, SIX)
    left, right = SIX.site_names.index("left_foot"), SIX.site_names.index("right_foot")
    others = [s for s in range(len(SIX.sites)) if s not in (left, right)]
    seen = {"both": 0, "left": 0, "right": 0, "origin": 0, "bounded": 0}
    for seed in range(5):
        stream = synthesize_trackers(motion, SIX, noise, seed=seed)
        off = {s: np.linalg.norm(stream.positions[:, s] - clean.positions[:, s], axis=-1) > 1e-9 for s in (left, right)}
        assert 0.05 < (off[left] | off[right]).mean() < 0.4
        at_origin = np.all(stream.positions[:, [left, right]] == 0.0, axis=-1).any(-1)
        seen["both"] += (off[left] & off[right]).sum()
        seen["left"] += (off[left] & ~off[right]).sum()
        seen["right"] += (off[right] & ~off[left]).sum()
        seen["origin"] += at_origin.sum()
        seen["bounded"] += ((off[left] | off[right]) & ~at_origin).sum()
        np.testing.assert_array_equal(stream.positions[:, others], clean.positions[:, others])
        assert stream.valid.all()  # an occluded tracker lies; it does not fall silent
    assert all(n > 0 for n in seen.values()), seen
    # the T-pose calibration is taken with the feet in view: the same body with or without occlusion
    occluded = Protocol.named(occluded_percent=20)
    assert "feet occluded in 20 % of frames" in occluded.label
    assert user_view(motion, SIX, occluded, seed=4).skeleton.offsets == pytest.approx(
        user_view(motion, SIX, FIELD_EXACT, seed=4).skeleton.offsets
    )
    with pytest.raises(ValueError, match="occluded share"):
        VR_NOISE.occluding(100)


@pytest.mark.train
def test_train_dtp_is_one_command(tmp_path, train_mocap):
    out = tmp_path / "dtp.onnx"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "sparse_body.cli",
            "train",
            "dtp",
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
    assert out.is_file() and (tmp_path / "dtp.pretrained.onnx").is_file()
    assert report["stages"]["pretrain"]["steps"] == 2 and report["train_clips"] == 1


@pytest.mark.train
def test_resume_after_the_pre_training_goes_on_with_the_fine_tuning(tmp_path, train_mocap, monkeypatch):
    import sparse_body.train.dtp.train as dtp_train
    from sparse_body.train.dtp.model import DtpConfig
    from sparse_body.train.harness import TrainRun

    config = replace(DtpConfig.named("tiny"), finetune_steps=4)
    checkpoint, out, fit = tmp_path / "dtp.checkpoint.npz", tmp_path / "dtp.onnx", dtp_train.fit
    calls = []

    def interrupted_in_the_fine_tuning(*args, **kwargs):
        calls.append(kwargs["steps"])
        if len(calls) == 2:
            fit(*args, **{**kwargs, "steps": 2})
            raise KeyboardInterrupt
        return fit(*args, **kwargs)

    monkeypatch.setattr(dtp_train, "fit", interrupted_in_the_fine_tuning)
    with pytest.raises(KeyboardInterrupt):
        dtp_train.train(config, TrainRun(train_mocap, out, limit=1, checkpoint=checkpoint, log=lambda *_: None))
    assert (tmp_path / "dtp.pretrained.onnx").is_file() and not out.is_file()
    calls.clear()
    monkeypatch.setattr(dtp_train, "fit", fit)
    lines = []
    run = TrainRun(train_mocap, out, limit=1, checkpoint=checkpoint, resume=True, log=lines.append)
    report = dtp_train.train(config, run)
    assert any("pretrain: finished before" in line for line in lines)
    assert any("finetune: resumed" in line and "at step 2" in line for line in lines)
    assert report["stages"]["pretrain"]["steps"] == config.steps and report["stages"]["finetune"]["steps"] == 4
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dtp.onnx", "dtp.pretrained.onnx"]


@pytest.mark.skipif(
    not (models_dir() / "dtp.onnx").is_file() or not (models_dir() / "dtp.pretrained.onnx").is_file(),
    reason="no shipped DTP models",
)
def test_shipped_fine_tuning_pays_off_on_occluded_feet(clip_index):
    """A held-out person's walk with feet occluded in a fifth of the frames: the fine-tuned
    model places the body better than the one before fine-tuning."""
    from sparse_body.data.catalog import load_split
    from sparse_body.evaluation import evaluate_motion

    assert "16_17" in load_split()["test"]
    motion = load_clip(clip_index["16_17"])
    protocol = Protocol.named(occluded_percent=20)
    tuned = evaluate_motion(motion, "dtp", SIX, protocol)
    pretrained = evaluate_motion(motion, "dtp", SIX, protocol, model="pretrained")
    assert tuned["MPJPE [cm]"] < pretrained["MPJPE [cm]"]
    assert tuned["Lower PE [cm]"] < pretrained["Lower PE [cm]"]


def test_estimator_node_runs_dtp_over_dds(dtp_models, tmp_path, clip, ros_env):
    """estimator:=dtp with the six-point configuration, fed by the tracker bridge from a bag."""
    import rclpy

    pytest.importorskip("tf2_msgs.msg")
    from ros_helpers import after_first_valid, replay_bag

    models, _ = dtp_models
    listener = replay_bag(
        rclpy,
        ros_env,
        tmp_path,
        clip.slice(0, 180),
        SIX,
        {"estimator": "dtp", "model_path": str(models["online"]), "height": clip.skeleton.height()},
        until_valid=30,
    )
    statuses = after_first_valid(listener)  # the bag loops until 30 valid, however slow the machine
    valid = sum(s.valid for s in statuses)
    assert valid >= 0.9 * len(statuses) and valid >= 30, (tmp_path / "sparse_body_estimator.log").read_text()
    assert all(np.all(np.isfinite(m.position)) for m in listener.received["joint_states"])
