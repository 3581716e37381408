import json
import os
import subprocess
import sys

import numpy as np
import pytest

from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.types import TrackerFrame
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.data.virtual_trackers import synthesize_trackers
from sparse_body.evaluation import evaluate_motion
from sparse_body.methods.factory import create_estimator


def test_reference_estimator_places_the_body_under_the_headset():
    motion = synthetic_walk(3.0)
    config = load_sensor_config("three_point")
    estimator = create_estimator("reference", config, motion.skeleton)
    poses = estimator.process(synthesize_trackers(motion, config))
    assert len(poses) == len(motion) and all(p.valid and p.is_finite() for p in poses)
    metrics = evaluate_motion(motion, "reference", config)
    # Head and root follow the headset closely; the arms do not follow the controllers.
    assert metrics["Root PE [cm]"] < 5.0
    assert metrics["Hand PE [cm]"] > 3.0
    assert set(metrics) >= {"MPJPE [cm]", "MPJRE [deg]", "Jitter [100m/s3]", "Skate [cm/s]", "Contact acc [%]"}


def test_bad_tracker_samples_give_finite_invalid_poses():
    motion = synthetic_walk(1.0)
    config = load_sensor_config("three_point")
    estimator = create_estimator("reference", config, motion.skeleton)
    stream = synthesize_trackers(motion, config)
    first = estimator.step(stream.frame(0))
    nan_frame = TrackerFrame(0.1, config.site_names, np.full((3, 3), np.nan), np.full((3, 4), np.nan), np.ones(3, bool))
    held = estimator.step(nan_frame)
    assert not held.valid and held.is_finite()
    np.testing.assert_allclose(held.root_position, first.root_position)
    zero_quat = stream.frame(1)
    zero_quat.orientations = np.zeros((3, 4))
    assert not estimator.step(zero_quat).valid
    estimator.reset()
    assert estimator.step(nan_frame).is_finite()


def test_unknown_estimator_and_missing_sites_are_clear_errors():
    config = load_sensor_config("three_point")
    with pytest.raises(
        ValueError,
        match="unknown estimator 'lobstr2'; available: auto, avatarjlm, blend, dragposer, dtp, ik, lobstr, reference, "
        "refined, upright",
    ):
        create_estimator("lobstr2", config, synthetic_walk(0.1).skeleton)
    hands = config.subset(["left_hand", "right_hand"])
    with pytest.raises(ValueError, match="needs a head or a pelvis tracker"):
        create_estimator("reference", hands, synthetic_walk(0.1).skeleton)


@pytest.mark.mocap
def test_eval_command_prints_the_table_and_writes_json(mocap_root, tmp_path):
    out = tmp_path / "eval.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "sparse_body.cli",
            "eval",
            "--estimator",
            "reference",
            "--sensors",
            "four_point",
            "--limit",
            "3",
            "--quiet",
            "--output",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "SPARSE_BODY_MOCAP": str(mocap_root)},
    )
    assert proc.returncode == 0, proc.stderr
    assert (
        "reference/four_point" in proc.stdout
        and "MPJPE [cm]" in proc.stdout
        and "3 clips of the test split" in proc.stdout
    )
    # the three clips are three kinds of motion: each kind's feet (skate, ground, contacts) has its table
    for metric in ("MPJPE [cm]", "Lower PE [cm]", "Skate [cm/s]", "Ground [cm]", "Contact acc [%]"):
        assert f"{metric} by motion" in proc.stdout, metric
    result = json.loads(out.read_text())[0]
    assert result["estimator"] == "reference" and len(result["clips"]) == 3
    assert 2.0 < result["summary"]["MPJPE [cm]"] < 40.0
    assert result["summary"]["Root PE [cm]"] < 10.0  # the pelvis tracker places the root


def test_eval_per_joint_rows_say_where_the_error_sits_and_average_to_the_totals(mocap_root, tmp_path):
    out = tmp_path / "eval.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "sparse_body.cli",
            "eval",
            "--estimator",
            "ik",
            "--sensors",
            "four_point",
            "--limit",
            "2",
            "--quiet",
            "--per-joint",
            "--output",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "SPARSE_BODY_MOCAP": str(mocap_root)},
    )
    assert proc.returncode == 0, proc.stderr
    assert "PE left_knee [cm]" in proc.stdout and "RE right_elbow [deg]" in proc.stdout
    summary = json.loads(out.read_text())[0]["summary"]
    from sparse_body.core.skeleton import JOINT_NAMES

    pe = [summary[f"PE {j} [cm]"] for j in JOINT_NAMES]
    re = [summary[f"RE {j} [deg]"] for j in JOINT_NAMES]
    assert np.isclose(np.mean(pe), summary["MPJPE [cm]"]) and np.isclose(np.mean(re), summary["MPJRE [deg]"])
    # four-point IK: the tracked wrists sit on their controllers, the untracked knees stand still
    assert summary["PE left_wrist [cm]"] < 1.0 < summary["PE left_knee [cm]"]


def test_eval_without_mocap_says_where_to_point(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "sparse_body.cli", "eval", "--estimator", "reference", "--mocap", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode != 0 and "no clips.tsv there" in proc.stderr


def test_wide_eval_tables_fit_a_terminal_with_their_columns_named_below():
    from sparse_body.core.results import EvalResult, format_table

    metrics = {"MPJPE [cm]": 4.4, "Contact acc [%]": 79.3, "End-effector PE [cm]": 0.1}
    results = [
        EvalResult(name, "four_point", "test", ["02_05"], [100], [metrics])
        for name in ("lobstr", "lobstr:contact_ik=false", "ik", "refined:base=lobstr,iterations=5")
    ]
    table = format_table(results, {"LoBSTr paper": {"Contact acc [%]": 85.77}})
    assert max(len(line) for line in table.splitlines()) <= 100, table
    assert "[2] lobstr:contact_ik=false/four_point" in table and "[5] LoBSTr paper" in table
    narrow = format_table(results[:1])
    assert "lobstr/four_point" in narrow.splitlines()[0]  # a narrow table keeps its names on top


def test_eval_takes_a_users_own_motion_files(tmp_path, mocap_root, capsys):
    import json

    from sparse_body.cli import main

    subject = mocap_root / "asfamc" / "subjects" / "02"
    if not subject.is_dir():
        pytest.skip("the CMU ASF/AMC subject 02 is not in the indexed motion capture")
    with pytest.raises(SystemExit) as ended:
        main(
            [
                "eval",
                "--estimator",
                "ik",
                "--sensors",
                "six_point",
                "--motion",
                str(subject),
                "--limit",
                "2",
                "--quiet",
                "--no-compare",
                "--output",
                str(tmp_path / "out.json"),
            ]
        )
    assert ended.value.code == 0
    assert "(2 clips of the motion files given" in capsys.readouterr().out
    result = json.loads((tmp_path / "out.json").read_text())[0]
    assert result["split"] == "files" and [c["clip"] for c in result["clips"]] == ["02_01.amc.gz", "02_02.amc.gz"]
    with pytest.raises(SystemExit) as ended:
        main(["eval", "--estimator", "ik", "--motion", str(tmp_path / "absent.bvh"), "--quiet"])
    assert ended.value.code == 1 and "no such file or folder" in capsys.readouterr().err


def test_intervals_drawn_by_person_are_wider_when_a_persons_clips_move_together():
    from sparse_body.core.results import EvalResult, clip_interval, format_table

    per_clip = [{"MPJPE [cm]": v} for v in (1.0, 1.0, 1.0, 3.0, 3.0, 3.0)]
    people = ["16", "16", "16", "43", "43", "43"]
    by_clip = clip_interval(per_clip, [100] * 6)["MPJPE [cm]"]
    by_person = clip_interval(per_clip, [100] * 6, units=people)["MPJPE [cm]"]
    assert by_person == [1.0, 3.0]  # two people: either one twice, or both
    assert 1.0 < by_clip[0] < 2.0 < by_clip[1] < 3.0
    assert clip_interval(per_clip, [100] * 6, units=["16"] * 6) == {}  # one person: no interval

    result = EvalResult("ik", "six_point", "test", [f"c{k}" for k in range(6)], [100] * 6, per_clip, subjects=people)
    data = result.to_json()
    assert data["interval_95_by_subject"]["MPJPE [cm]"] == by_person
    assert EvalResult.from_json(data).subjects == people
    assert "[1.00, 3.00] by person (2 people)" in format_table([result])


def test_intervals_beside_every_mean_and_each_person_s_own_figure():
    from sparse_body.core.results import EvalResult, clip_interval, format_groups, format_table

    per_clip = [{"MPJPE [cm]": v, "Jitter [100m/s3]": 10 * v} for v in (1.0, 1.2, 0.8, 3.0, 3.2, 2.8)]
    people = ["16", "16", "16", "43", "43", "43"]
    result = EvalResult("ik", "six_point", "test", [f"c{k}" for k in range(6)], [100] * 6, per_clip, subjects=people)
    table = format_table([result], intervals=True)
    for metric in ("MPJPE [cm]", "Jitter [100m/s3]"):
        lo, hi = clip_interval(per_clip, [100] * 6)[metric]
        plo, phi = clip_interval(per_clip, [100] * 6, units=people)[metric]
        row = next(line for line in table.splitlines() if line.startswith(metric))
        assert row.endswith(f"[{lo:.2f}, {hi:.2f}] [{plo:.2f}, {phi:.2f}]"), row
    assert format_table([result]).splitlines()[1].endswith(" 2.00")  # without: the means alone
    persons = format_groups([result], label="person", by="subject").splitlines()
    assert persons[0].startswith("MPJPE [cm] by person")
    assert persons[1].startswith("16 (3 clips)") and " 1.00 [" in persons[1]
    assert persons[2].startswith("43 (3 clips)") and " 3.00 [" in persons[2]


def test_each_kind_of_motion_has_its_figure_and_those_no_training_clip_has_are_marked():
    from sparse_body.core.results import EvalResult, format_groups

    per_clip = [{"MPJPE [cm]": v, "Lower PE [cm]": 2 * v} for v in (1.0, 1.2, 3.0, 3.2)]
    kinds = ["locomotion", "locomotion", "dance", "dance"]
    result = EvalResult("ik", "four_point", "validation", [f"c{k}" for k in range(4)], [100] * 4, per_clip)
    result.categories = kinds
    assert EvalResult.from_json(result.to_json()).categories == kinds
    rows = format_groups([result], "Lower PE [cm]", "motion", "category", {"dance": ", not in training"}).splitlines()
    assert rows[0].startswith("Lower PE [cm] by motion")
    assert rows[1].startswith("dance, not in training (2 clips)") and " 6.20 [" in rows[1]
    assert rows[2].startswith("locomotion (2 clips)") and " 2.20 [" in rows[2]


def test_untrained_categories_are_those_of_no_training_clip(mocap_root):
    from sparse_body.data.catalog import split_clips
    from sparse_body.evaluation import untrained_categories

    trained = {c.kind for c in split_clips(mocap_root, "train")}
    validation = [c.kind for c in split_clips(mocap_root, "validation")]
    notes = untrained_categories(mocap_root, validation)
    # CMU's split: dance, cartwheels and acrobatics, one-leg balances are only in validation
    assert set(notes) == set(validation) - trained == {"dance", "acrobatics", "balance"}
    assert not set(notes) & trained
