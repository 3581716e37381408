"""Tracker bags in, estimate bags out, without ROS (real rosbag2 MCAP files via rosbags)."""

import numpy as np
import pytest

from sparse_body.apps.offline import make_bag, process_bag
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import synthesize_trackers
from sparse_body.io.bagio import (
    CONTACTS_TOPIC,
    JOINT_STATES_TOPIC,
    STATUS_TOPIC,
    TF_TOPIC,
    BagError,
    read_topic,
    read_tracker_stream,
    write_tracker_bag,
)
from sparse_body.io.output import joint_state_names


def test_make_bag_round_trips_the_trackers(tmp_path):
    motion = synthetic_walk(2.0)
    config = load_sensor_config("six_point")
    assert make_bag(motion, config, tmp_path / "trackers") == len(motion)
    stream = read_tracker_stream(tmp_path / "trackers", config)
    truth = synthesize_trackers(motion, config)
    assert len(stream) == len(motion) and stream.valid.all()
    np.testing.assert_allclose(stream.positions, truth.positions, atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(stream.orientations * truth.orientations, -1)), 1.0, atol=1e-9)
    np.testing.assert_allclose(stream.times - stream.times[0], np.arange(len(motion)) / 60.0, atol=1e-6)


def test_process_writes_one_estimate_per_frame(tmp_path):
    motion = synthetic_walk(2.0)
    config = load_sensor_config("six_point")
    make_bag(motion, config, tmp_path / "in")
    poses = process_bag(
        tmp_path / "in", tmp_path / "out", "ik", config, motion.skeleton, progress=False, keep_poses=True
    ).poses
    states = read_topic(tmp_path / "out", JOINT_STATES_TOPIC)
    assert len(states) == len(poses) == len(motion)
    assert list(states[0].name) == joint_state_names() and len(states[0].name) == 63
    assert all(np.all(np.isfinite(s.position)) for s in states)
    assert len(read_topic(tmp_path / "out", CONTACTS_TOPIC)) == len(motion)
    assert all(s.valid for s in read_topic(tmp_path / "out", STATUS_TOPIC))
    tfs = read_topic(tmp_path / "out", TF_TOPIC)
    assert len(tfs) == len(motion)
    children = {t.child_frame_id for t in tfs[0].transforms}
    assert {"pelvis", "left_wrist", "head"} <= children and {s.frame_id for s in config.sites} <= children
    # The IK baseline puts the wrists where the controllers say.
    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.rotations import quat_to_matrix

    local = quat_to_matrix(np.stack([p.local_quats for p in poses]))
    _, pos = forward_kinematics(local, np.stack([p.root_position for p in poses]), motion.skeleton.offsets)
    err = np.linalg.norm(pos[:, J["left_wrist"]] - motion.positions[:, J["left_wrist"]], axis=-1)
    assert err.mean() < 0.01


@pytest.mark.parametrize("smooth", [False, True], ids=["live filter", "smoothed"])
def test_bad_tracker_samples_keep_one_finite_output_per_frame(tmp_path, smooth):
    motion = synthetic_walk(3.0)
    config = load_sensor_config("four_point")
    stream = synthesize_trackers(motion, config)
    stream.positions[20:25, 0] = np.nan  # NaN headset poses
    stream.orientations[30, 1] = 0.0  # a zero quaternion
    stream.valid[40:80, 3] = False  # the pelvis tracker stops for 2/3 s
    stream.valid[90, :] = False  # a frame with no tracker at all
    stream.valid[140:160, [0, 3]] = False  # headset and pelvis both gone
    stream.times[100], stream.times[101] = stream.times[101], stream.times[100]  # out of order
    stream.times[120:] -= 2.0  # the clock jumps back (a bag loop)
    write_tracker_bag(tmp_path / "bad", stream, config)
    back = read_tracker_stream(tmp_path / "bad", config)
    # Frame 90 carried no transform at all, so it is no input frame; every other one is.
    assert len(back) == len(motion) - 1
    poses = process_bag(
        tmp_path / "bad",
        tmp_path / "out",
        "ik",
        config,
        motion.skeleton,
        progress=False,
        smooth=smooth,
        keep_poses=True,
    ).poses
    assert len(poses) == len(back)
    assert all(p.is_finite() for p in poses)
    valid = np.array([p.valid for p in poses])
    pelvis = back.sites.index("pelvis")
    assert not back.valid[50:78, pelvis].any()  # stale after 0.1 s
    assert valid[50:78].all()  # ...and the root then hangs from the headset
    assert not valid[145:158].any()  # no headset, no pelvis: held and marked invalid
    assert valid[:20].all() and valid[-20:].all()
    statuses = read_topic(tmp_path / "out", STATUS_TOPIC)
    assert [s.valid for s in statuses] == list(valid)
    assert all(np.all(np.isfinite(s.position)) for s in read_topic(tmp_path / "out", JOINT_STATES_TOPIC))


def test_unreadable_bags_name_the_path(tmp_path):
    config = load_sensor_config("three_point")
    with pytest.raises(BagError, match="no such bag"):
        read_tracker_stream(tmp_path / "absent", config)
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "metadata.yaml").write_text("not: a bag\n")
    with pytest.raises(BagError, match=r"junk: cannot be read as a rosbag2"):
        read_tracker_stream(tmp_path / "junk", config)
    make_bag(synthetic_walk(0.5), load_sensor_config("six_point").subset(["pelvis"]), tmp_path / "other")
    with pytest.raises(BagError, match="no transforms of the tracker frames"):
        read_tracker_stream(tmp_path / "other", config)


def test_frames_whose_samples_were_all_refused_are_invalid_and_counted(tmp_path):
    motion = synthetic_walk(2.0)
    config = load_sensor_config("four_point")
    stream = synthesize_trackers(motion, config)
    stream.positions[50, :] = np.nan  # every tracker of frame 50: NaN
    stream.orientations[60, :] = 0.0  # every tracker of frame 60: a zero quaternion
    write_tracker_bag(tmp_path / "bad", stream, config)
    refused = {}
    poses = process_bag(
        tmp_path / "bad",
        tmp_path / "out",
        "ik",
        config,
        motion.skeleton,
        progress=False,
        refused=refused,
        keep_poses=True,
    ).poses
    assert len(poses) == len(motion)
    assert not poses[50].valid and not poses[60].valid and poses[49].valid and poses[61].valid
    assert refused == {"non-finite or absurd value": 4, "degenerate quaternion": 4}
    stamps = [p.stamp for p in poses]
    assert len(set(stamps)) == len(stamps)  # each frame keeps its own stamp


def test_outputs_are_never_half_written_nor_silently_replaced(tmp_path, monkeypatch):
    from sparse_body.cli import main

    motion = synthetic_walk(1.0)
    config = load_sensor_config("three_point")
    make_bag(motion, config, tmp_path / "in")
    with pytest.raises(BagError, match=r"in: already exists .*--overwrite"):
        make_bag(motion, config, tmp_path / "in")
    make_bag(motion, config, tmp_path / "in", overwrite=True)
    process_bag(tmp_path / "in", tmp_path / "out", "ik", config, motion.skeleton, progress=False)
    # an existing output is refused before the reading and the estimation start
    monkeypatch.setattr("sparse_body.apps.offline.create_estimator", lambda *a, **k: pytest.fail("estimated first"))
    monkeypatch.setattr("sparse_body.apps.pipeline.tracker_chunks", lambda *a, **k: pytest.fail("read first"))
    for parallel in (False, True):
        with pytest.raises(BagError, match=r"out: already exists"):
            process_bag(
                tmp_path / "in", tmp_path / "out", "ik", config, motion.skeleton, progress=False, parallel=parallel
            )
    monkeypatch.undo()

    # Ctrl-C while writing, in this process or in the writer's: nothing is left behind, and
    # the command exits 130 with one line
    from sparse_body.io.estimate_bag import EstimateBagWriter

    def interrupted(self, poses, trackers):
        raise KeyboardInterrupt

    monkeypatch.setattr(EstimateBagWriter, "write", interrupted)
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(SystemExit) as ended:
        main(["process", str(tmp_path / "in"), str(tmp_path / "new"), "--sensors", "three_point", "--quiet"])
    assert ended.value.code == 130
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    with pytest.raises(KeyboardInterrupt):  # (raised in the forked writer, said here)
        process_bag(tmp_path / "in", tmp_path / "new", "ik", config, motion.skeleton, progress=False, parallel=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_empty_bags_are_refused(tmp_path, capsys):
    from rosbags.rosbag2 import StoragePlugin, Writer

    from sparse_body.cli import main
    from sparse_body.core.types import TrackerStream
    from sparse_body.io.bagio import TF_TYPE, typestore

    config = load_sensor_config("three_point")
    with pytest.raises(SystemExit) as ended:  # wrote a 0-frame bag before
        main(["make-bag", str(tmp_path / "nothing")])
    assert ended.value.code == 1 and "make-bag needs a motion" in capsys.readouterr().err
    assert not (tmp_path / "nothing").exists()
    empty = TrackerStream(
        config.site_names, np.zeros(0), np.zeros((0, 3, 3)), np.zeros((0, 3, 4)), np.zeros((0, 3), bool)
    )
    with pytest.raises(BagError, match="no frames"):
        write_tracker_bag(tmp_path / "empty", empty, config)
    with Writer(tmp_path / "silent", version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        writer.add_connection(TF_TOPIC, TF_TYPE, typestore=typestore())  # a /tf topic, no message
    from sparse_body.io.bagio import read_tf_messages

    with pytest.raises(BagError, match=r"silent: no /tf messages"):  # the bridge's loop spun a core
        read_tf_messages(tmp_path / "silent")


def test_stamps_that_round_up_carry_into_the_seconds_on_both_paths():
    from sparse_body.io.bagio import _time, typestore
    from sparse_body.io.output import stamp_parts

    assert stamp_parts(5.9999999999) == (6, 0)  # the bag path wrapped to (5, 0)
    assert stamp_parts(1_700_000_000.25) == (1_700_000_000, 250_000_000)
    t = _time(typestore(), 5.9999999999)
    assert (t.sec, t.nanosec) == (6, 0)
    pytest.importorskip("rclpy", reason="rclpy is not installed")
    from sparse_body.ros.messages import to_time

    assert (to_time(5.9999999999).sec, to_time(5.9999999999).nanosec) == (6, 0)


def test_cli_refuses_bad_arguments_and_lists_what_is_there(tmp_path, capsys):
    from sparse_body.cli import main

    for argv, said in [
        (["eval", "--estimator", "ik", "--limit", "0"], "must be at least 1"),
        (["eval", "--estimator", "ik", "--limit", "-1"], "must be at least 1"),
        (["eval", "--estimator", "ik", "--faulty", "150"], "must be from 0 to 100 %"),
    ]:
        with pytest.raises(SystemExit):
            main(argv)
        assert said in capsys.readouterr().err
    motion = synthetic_walk(1.0)
    make_bag(motion, load_sensor_config("three_point"), tmp_path / "three")
    with pytest.raises(SystemExit) as ended:
        main(
            [
                "process",
                str(tmp_path / "three"),
                str(tmp_path / "o"),
                "--estimator",
                "ik:bogus=1",
                "--sensors",
                "three_point",
                "--quiet",
            ]
        )
    assert ended.value.code == 1
    assert "estimator 'ik' has no option 'bogus'; its options are floor_height" in capsys.readouterr().err
    # a configuration whose trackers never appear: process refuses it in one line, before any work
    with pytest.raises(SystemExit) as ended:
        main(["process", str(tmp_path / "three"), str(tmp_path / "six"), "--sensors", "six_point", "--quiet"])
    err = capsys.readouterr().err
    assert ended.value.code == 1 and err.count("\n") == 1, err
    assert "six_point's tracker frames left_foot_tracker, pelvis_tracker, right_foot_tracker never appear" in err
    assert not (tmp_path / "six").exists()
    # process_bag itself says which never had a usable pose (no Python warning)
    processed = process_bag(
        tmp_path / "three", tmp_path / "six", "ik", load_sensor_config("six_point"), motion.skeleton, progress=False
    )
    assert processed.never_usable == ("pelvis", "left_foot", "right_foot")
    with pytest.raises(SystemExit):
        main(["process", "--help"])
    help_text = capsys.readouterr().out
    assert "(default: auto)" in help_text and "six_point" in help_text and "lobstr" in help_text


def test_setup_py_defers_to_pyproject():
    """ROS Python tooling still looks for a setup.py; it must give pyproject.toml's metadata."""
    import subprocess
    import sys
    from pathlib import Path

    import tomllib

    root = Path(__file__).resolve().parents[1]
    project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    out = subprocess.run(
        [sys.executable, "setup.py", "--name", "--version"], cwd=root, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[-2:] == [project["name"], project["version"]]


def test_pyproject_depends_on_what_requirements_txt_lists():
    """`pip install .` and `make demo` (requirements.txt) give the same runtime: numba, the
    viewer's and the live view's packages were missing from pyproject's list."""
    import re
    from pathlib import Path

    import tomllib

    root = Path(__file__).resolve().parents[1]
    lines = (root / "requirements.txt").read_text().splitlines()
    listed = sorted(line.split("#")[0].strip() for line in lines if line.split("#")[0].strip())
    declared = tomllib.loads((root / "pyproject.toml").read_text())["project"]["dependencies"]
    assert sorted(declared) == listed
    assert all(re.match(r"^[a-z0-9-]+>=", d) for d in declared)


def test_the_demo_draws_the_skull_above_the_head_joint_and_its_output_is_not_committed():
    from pathlib import Path

    from sparse_body.apps.demo import HEAD, head_tops
    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.skeleton import Skeleton, standing_pose

    glob, pos = forward_kinematics(standing_pose()[None], np.zeros((1, 3)), Skeleton.canonical().offsets)
    top = head_tops(pos, glob, 0.1)
    np.testing.assert_allclose(top[0] - pos[0, HEAD], [0.0, 0.0, 0.1], atol=1e-12)
    root = Path(__file__).resolve().parents[1]
    assert "/sparse_body_demo/" in (root / ".gitignore").read_text().split()
    makefile = (root / "Makefile").read_text()
    for target in ("test: setup-test", "test-train: setup-train"):
        recipe = makefile.split(f"\n{target}\n")[1].splitlines()[0]
        assert "pytest" in recipe and "-rs" in recipe  # make test says what it skipped and why


def test_process_takes_the_body_of_a_calibration_file(tmp_path, capsys):
    """`process --calibration`: the fitted body puts the wrists on the controllers, where the
    canonical body of the same height misses; a broken file is named."""
    from sparse_body.cli import main
    from sparse_body.core.calibration import Calibration
    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.rotations import euler_to_matrix, quat_to_matrix
    from sparse_body.core.skeleton import Skeleton
    from sparse_body.data.motion import Motion

    walk = synthetic_walk(2.0)
    offsets = walk.skeleton.offsets.copy()
    offsets[[J["left_elbow"], J["right_elbow"], J["left_knee"], J["right_knee"]]] *= 1.1  # not the canonical build
    motion = Motion(walk.name, walk.fps, Skeleton(offsets), walk.local_quats, walk.root_positions)
    config = load_sensor_config("six_point")
    make_bag(motion, config, tmp_path / "in")
    Calibration(motion.skeleton.height(), 0.0, {}, motion.skeleton).save(tmp_path / "cal.yaml")
    errors = {}
    for name, args in (
        ("calibrated", ["--calibration", str(tmp_path / "cal.yaml")]),
        ("height", ["--height", str(motion.skeleton.height())]),
    ):
        with pytest.raises(SystemExit) as ended:
            main(["process", str(tmp_path / "in"), str(tmp_path / name), "--quiet", *args])
        assert ended.value.code == 0
        body = (
            Calibration.load(tmp_path / "cal.yaml").body()
            if name == "calibrated"
            else Skeleton.canonical(motion.skeleton.height())
        )
        states, tfs = read_topic(tmp_path / name, JOINT_STATES_TOPIC), read_topic(tmp_path / name, TF_TOPIC)
        assert len(states) == len(motion)
        local = np.tile(np.eye(3), (len(states), 22, 1, 1))
        local[:, 1:] = euler_to_matrix(np.array([s.position for s in states]).reshape(-1, 21, 3), "ZYX")
        root = [next(t for t in m.transforms if t.child_frame_id == "pelvis").transform for m in tfs]
        local[:, 0] = quat_to_matrix(np.array([[r.rotation.x, r.rotation.y, r.rotation.z, r.rotation.w] for r in root]))
        _, pos = forward_kinematics(
            local, np.array([[r.translation.x, r.translation.y, r.translation.z] for r in root]), body.offsets
        )
        errors[name] = np.linalg.norm(pos[:, J["left_wrist"]] - motion.positions[:, J["left_wrist"]], axis=-1).mean()
    assert errors["calibrated"] < 0.01 and errors["calibrated"] < errors["height"]
    (tmp_path / "broken.yaml").write_text("height: 1.7\nskeleton: {pelvis: [0, 0, 0]}\n")
    with pytest.raises(SystemExit) as ended:
        main(
            [
                "process",
                str(tmp_path / "in"),
                str(tmp_path / "x"),
                "--quiet",
                "--calibration",
                str(tmp_path / "broken.yaml"),
            ]
        )
    assert ended.value.code == 1 and "broken.yaml: 'skeleton' must give" in capsys.readouterr().err


@pytest.mark.parametrize("sensors", ["three_point", "four_point", "six_point", "four_point_foot_imus"])
def test_without_sensors_process_reads_the_bag_as_the_configuration_whose_trackers_it_holds(tmp_path, capsys, sensors):
    """A four-point bag with no --sensors was read as six_point: a raw Python warning, exit 0
    and straight, still legs."""
    from sparse_body.cli import main

    make_bag(synthetic_walk(1.0), load_sensor_config(sensors), tmp_path / "trackers")
    with pytest.raises(SystemExit) as ended:
        main(["process", str(tmp_path / "trackers"), str(tmp_path / "body"), "--quiet"])
    out = capsys.readouterr()
    assert ended.value.code == 0, out.err
    assert f"reading it as {sensors} (--sensors to choose)" in out.out and "Warning" not in out.err
    from sparse_body.io.bagio import read_topic

    assert read_topic(tmp_path / "body", "/joint_states")
