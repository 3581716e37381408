"""The CMU index, the committed split and the parse cache (needs ../shared/mocap)."""

import time

import numpy as np
import pytest

from sparse_body.data.catalog import SELECTION, SPLITS, compute_split, load_clip, load_split, split_clips

pytestmark = pytest.mark.mocap


def test_index_lists_every_clip_with_its_file(clip_index):
    assert len(clip_index) == 313
    formats = {c.format for c in clip_index.values()}
    assert formats == {"asf/amc", "bvh-mb2", "bvh-daz", "bvh-max"}
    assert all(c.path.is_file() for c in clip_index.values())
    assert all(c.skeleton_path.is_file() for c in clip_index.values() if c.format == "asf/amc")


def test_committed_split_is_the_computed_one_and_keeps_people_apart(clip_index):
    split = load_split()
    assert split == compute_split(list(clip_index.values()))
    seen = [c for s in SPLITS for c in split[s]]
    assert sorted(seen) == sorted(clip_index) and len(set(seen)) == len(seen)
    subjects = {s: {clip_index[c].subject for c in split[s]} for s in SPLITS}
    assert not subjects["train"] & (subjects["test"] | subjects["validation"])
    assert not subjects["test"] & subjects["validation"]
    assert len(subjects["test"]) >= 3 and len(subjects["validation"]) >= 3  # several people, not one
    total = sum(c.seconds for c in clip_index.values())
    for part in ("test", "validation"):
        share = sum(clip_index[c].seconds for c in split[part]) / total
        assert 0.10 <= share <= 0.15, (part, share)


def test_the_selection_holds_every_kind_of_motion_the_validation_people_bring_and_training_lacks(mocap_root):
    train = {c.kind for c in split_clips(mocap_root, "train")}
    validation = split_clips(mocap_root, "validation")
    selection = split_clips(mocap_root, SELECTION)
    assert {c.kind for c in selection} == {"dance", "acrobatics", "balance"}  # cartwheels, ropes, one leg
    assert not {c.kind for c in selection} & train
    assert {c.clip_id for c in selection} == {c.clip_id for c in validation if c.kind not in train}
    assert sum(c.seconds for c in selection) > 4 * 60  # enough to choose on: 36 clips, 5 minutes
    # "other" is split by what its clips show: ladders and a motorcycle trained, cartwheels not
    assert "climbing" in train and {"acrobatics", "balance"} <= {c.kind for c in validation}


def test_second_load_comes_from_the_cache(clip_index, tmp_path, monkeypatch):
    monkeypatch.setenv("SPARSE_BODY_CACHE", str(tmp_path))
    clip = clip_index["02_05"]
    start = time.perf_counter()
    first = load_clip(clip)
    parse = time.perf_counter() - start
    start = time.perf_counter()
    second = load_clip(clip)
    cached = time.perf_counter() - start
    assert len(list(tmp_path.rglob("*.npz"))) == 1
    assert first.fps == second.fps == 60.0 and len(first) == len(second)
    # bit-identical: evaluations must not depend on whether the cache was warm
    np.testing.assert_array_equal(second.local_quats, first.local_quats)
    np.testing.assert_array_equal(second.root_positions, first.root_positions)
    np.testing.assert_array_equal(second.skeleton.offsets, first.skeleton.offsets)
    assert cached < parse / 3


def test_eval_on_the_selection_meets_each_clip_with_its_validation_draws(mocap_root, tmp_path, capsys):
    import json

    from sparse_body.cli import main

    def run(split, limit, out):
        with pytest.raises(SystemExit) as ended:
            main(
                ["eval", "--estimator", "ik", "--sensors", "four_point", "--no-compare", "--quiet"]
                + ["--split", split, "--limit", str(limit), "--output", str(out)]
            )
        assert ended.value.code == 0, capsys.readouterr().err
        return json.loads(out.read_text())[0]

    validation = run("validation", 2, tmp_path / "v.json")  # 05_01, a walk; 05_02, a dance
    selection = run(SELECTION, 1, tmp_path / "s.json")  # the walk is not in it
    assert [c["clip"] for c in selection["clips"]] == ["05_02"]
    assert selection["settings"]["contact_labels"] == 2  # which definition its skate and contacts used
    same = next(c for c in validation["clips"] if c["clip"] == "05_02")
    assert same["category"] == selection["clips"][0]["category"] == "dance"
    assert same["Lower PE [cm]"] == selection["clips"][0]["Lower PE [cm]"]  # the same field draws
