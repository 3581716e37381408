"""`sparse-body import-mocap`: a user's own download (CMU's ASF/AMC as it unpacks) becomes a
folder that eval, train and make-bag --clip take with --mocap, without copying or changing a
file, and with a subject-disjoint split of its own."""

import shutil

import pytest
import yaml

from sparse_body.cli import EXIT_INPUT, EXIT_OUTPUT, main
from sparse_body.data.catalog import read_index, split_clips


def run_cli(capsys, *argv):
    with pytest.raises(SystemExit) as ended:
        main([str(a) for a in argv])
    out = capsys.readouterr()
    return ended.value.code, out.out, out.err


def test_a_cmu_download_becomes_a_motion_folder(mocap_root, tmp_path, capsys):
    subjects = mocap_root / "asfamc" / "subjects"
    if not (subjects / "02").is_dir():
        pytest.skip("the CMU ASF/AMC subjects are not in the indexed motion capture")
    download = tmp_path / "allasfamc" / "all_asfamc" / "subjects"  # as CMU's zip unpacks
    for subject in ("02", "05", "06", "07", "08", "09", "10", "12"):
        if (subjects / subject).is_dir():
            shutil.copytree(subjects / subject, download / subject)
    (download / "notes.bvh").write_text("not a motion file")  # left out, with the reason
    before = {p: p.stat().st_mtime_ns for p in download.rglob("*")}
    code, out, err = run_cli(capsys, "import-mocap", tmp_path / "allasfamc", "--out", tmp_path / "mine", "--quiet")
    assert code == 0, err
    assert "left out" in err and "notes.bvh" in err
    assert {p: p.stat().st_mtime_ns for p in download.rglob("*")} == before  # nothing changed
    clips = read_index(tmp_path / "mine")
    assert clips and all(c.clip_id.count("_") == 1 and c.path.is_file() for c in clips)
    assert {c.clip_id for c in clips} >= {"02_01", "05_01"}
    split = yaml.safe_load((tmp_path / "mine" / "split.yaml").read_text())
    parts = {part: {c.split("_")[0] for c in ids} for part, ids in split.items()}
    assert sorted(c for ids in split.values() for c in ids) == sorted(c.clip_id for c in clips)
    assert not parts["train"] & (parts["test"] | parts["validation"])  # subject-disjoint
    # the folder serves make-bag --clip and eval --mocap like the shared one
    code, out, err = run_cli(
        capsys, "make-bag", tmp_path / "bag", "--clip", "02_01", "--seconds", "1", "--mocap", tmp_path / "mine"
    )
    assert code == 0, err
    train = split_clips(tmp_path / "mine", "train", limit=1)
    assert len(train) == 1
    code, out, err = run_cli(
        capsys,
        "eval",
        "--estimator",
        "ik",
        "--sensors",
        "six_point",
        "--split",
        "train",
        "--limit",
        "1",
        "--mocap",
        tmp_path / "mine",
        "--quiet",
        "--no-compare",
        "--output",
        tmp_path / "r.json",
    )
    assert code == 0, err
    assert train[0].clip_id in (tmp_path / "r.json").read_text()


def test_import_refuses_to_write_into_a_used_folder_and_names_unreadable_files(tmp_path, capsys):
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "a.bvh").write_text("HIERARCHY\nROOT hip\n{\n")
    (tmp_path / "used").mkdir()
    (tmp_path / "used" / "keep.txt").write_text("mine")
    code, _, err = run_cli(capsys, "import-mocap", tmp_path / "src", "--out", tmp_path / "used", "--quiet")
    assert code == EXIT_OUTPUT and "not an empty folder" in err
    assert sorted(p.name for p in (tmp_path / "used").iterdir()) == ["keep.txt"]
    code, _, err = run_cli(capsys, "import-mocap", tmp_path / "src", "--out", tmp_path / "new", "--quiet")
    assert code == EXIT_INPUT and "no readable motion file" in err and "a.bvh" in err
    assert not (tmp_path / "new").exists()
    code, _, err = run_cli(capsys, "import-mocap", tmp_path / "absent", "--out", tmp_path / "new", "--quiet")
    assert code == EXIT_INPUT and "no such file or folder" in err
