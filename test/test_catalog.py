"""The CMU index, the committed split and the parse cache (needs ../shared/mocap)."""

import time

import numpy as np
import pytest

from sparse_body.data.catalog import SPLITS, compute_split, load_clip, load_split

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
