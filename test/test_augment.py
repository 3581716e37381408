"""Training augmentation (train/augment.py) on a real clip: what each kind does to the body."""

import json

import numpy as np
import pytest

from sparse_body.core.contacts import estimate_floor
from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.data.catalog import load_clip
from sparse_body.train.augment import (
    KINDS,
    MIRROR,
    SEGMENTS,
    SPLICED,
    Augmentation,
    augmented,
    mirrored,
    played_at,
    random_variant,
    spliced,
    variants,
    with_proportions,
)


@pytest.fixture(scope="module")
def walk(clip_index):
    return load_clip(clip_index["02_01"])


@pytest.fixture(scope="module")
def box(clip_index):
    return load_clip(clip_index["02_05"])


def test_the_mirror_image_is_the_reflected_motion_with_sides_swapped(walk):
    mirror = mirrored(walk)
    np.testing.assert_allclose(mirror.positions, walk.positions[:, MIRROR] * [1, -1, 1], atol=1e-9)
    # the person's left hand now does (reflected) what the right hand did
    np.testing.assert_allclose(
        mirror.positions[:, J["left_wrist"], 1], -walk.positions[:, J["right_wrist"], 1], atol=1e-9
    )
    np.testing.assert_allclose(mirrored(mirror).positions, walk.positions, atol=1e-9)
    assert not np.allclose(mirror.positions, walk.positions, atol=0.01)  # a walk is not symmetric


def test_speed_shortens_the_motion_and_keeps_its_path(walk):
    fast = played_at(walk, 1.25)
    assert fast.fps == walk.fps
    assert abs(fast.duration - walk.duration / 1.25) < 1.5 / walk.fps
    np.testing.assert_allclose(fast.positions[0], walk.positions[0], atol=1e-9)
    np.testing.assert_allclose(
        fast.positions[-1], walk.positions[min(round((len(fast) - 1) * 1.25), len(walk) - 1)], atol=0.02
    )
    speed = np.linalg.norm(np.diff(walk.root_positions[:, :2], axis=0), axis=1).mean()
    fast_speed = np.linalg.norm(np.diff(fast.root_positions[:, :2], axis=0), axis=1).mean()
    assert fast_speed == pytest.approx(1.25 * speed, rel=0.02)


def test_proportions_change_segment_lengths_and_keep_the_feet_on_the_floor(walk):
    body = with_proportions(walk, {"thigh": 1.08, "forearm": 0.92})
    lengths = np.linalg.norm(body.skeleton.offsets, axis=1) / np.maximum(
        np.linalg.norm(walk.skeleton.offsets, axis=1), 1e-12
    )
    assert lengths[J["left_knee"]] == pytest.approx(1.08) and lengths[J["right_knee"]] == pytest.approx(1.08)
    assert lengths[J["left_wrist"]] == pytest.approx(0.92)
    assert lengths[J["left_elbow"]] == pytest.approx(1.0)
    np.testing.assert_allclose(body.local_quats, walk.local_quats)
    legs = body.skeleton.leg_length() / walk.skeleton.leg_length()
    assert legs > 1.02
    pelvis_height = walk.root_positions[:, 2] - estimate_floor(walk.positions)
    new_height = body.root_positions[:, 2] - estimate_floor(body.positions)
    assert np.median(new_height / pelvis_height) == pytest.approx(legs, rel=0.02)


def test_a_splice_puts_the_donors_arms_and_head_on_the_clips_legs_and_spine(walk, box):
    both = spliced(walk, box)
    T = min(len(walk), len(box))
    assert len(both) == T and both.skeleton is walk.skeleton
    legs = [J[n] for n in ("pelvis", "spine3", "left_knee", "right_ankle", "left_foot")]
    # the legs, the pelvis path and the spine are the clip's: the feet stand where they stood
    np.testing.assert_allclose(both.positions[:, legs], walk.positions[:T, legs], atol=1e-9)
    np.testing.assert_allclose(both.local_quats[:, SPLICED], box.local_quats[:T, SPLICED])
    assert {J["head"], J["left_wrist"], J["right_collar"]} <= set(SPLICED) and J["spine3"] not in SPLICED
    # the hands move as the boxer's arms do, on the walker's torso
    hand = both.positions[:, J["right_wrist"]] - both.positions[:, J["spine3"]]
    walker_hand = walk.positions[:T, J["right_wrist"]] - walk.positions[:T, J["spine3"]]
    assert np.abs(hand - walker_hand).max() > 0.2


def test_splices_take_donors_from_other_clips_and_need_one(walk, box):
    rng = np.random.default_rng(3)
    out = augmented([walk, box], Augmentation(("splice",), 6), rng)
    assert len(out) == 14 and out[0] is walk and out[7] is box
    names = [m.name for m in out]
    assert any(n.startswith("02_01/arms:02_05") for n in names) and any(n.startswith("02_05/arms:02_01") for n in names)
    for name in names:  # "<clip>[/mirror]/arms:<donor>[...]": never the clip's own arms
        if "arms:" in name:
            assert name.split("arms:")[1].split("/")[0] != name.split("/")[0]
    with pytest.raises(ValueError, match="splice augmentation needs at least two"):
        [random_variant(walk, Augmentation(("splice",)), rng, []) for _ in range(20)]
    # without splice, the draws are variants' own, clip by clip
    plain = Augmentation(("mirror", "speed"), 3)
    a = augmented([walk, box], plain, np.random.default_rng(9))
    r = np.random.default_rng(9)
    b = variants(walk, plain, r) + variants(box, plain, r)
    assert [len(m) for m in a] == [len(m) for m in b]


def test_the_spliced_share_is_what_the_spec_says(walk, box):
    def spliced_share(spec: str) -> float:
        rng = np.random.default_rng(11)
        copies = [random_variant(walk, Augmentation.parse(spec), rng, [box]) for _ in range(60)]
        return sum("arms:" in m.name for m in copies) / len(copies)

    assert spliced_share("splice=1") == 1.0 and spliced_share("splice=0") == 0.0
    assert 0.3 < spliced_share("splice") < 0.7  # half, as before the share could be said
    assert Augmentation.parse("mirror,splice=0.8").spec == "mirror,splice=0.8"
    assert Augmentation.parse("mirror,splice=0.5").spec == "mirror,splice"  # the default, said as before
    assert Augmentation.parse("mirror,splice=0.8").without("mirror").spec == "splice=0.8"  # as the ablation runs it
    assert Augmentation.parse("tilt=0.5,mirror").spec == "mirror,tilt=0.5"
    for bad, why in (
        ("splice=1.5", "from 0 to 1"),
        ("splice=many", "from 0 to 1"),
        ("tilt=-1", "from 0 to 1"),
        ("speed=2", "takes no value"),
    ):
        with pytest.raises(ValueError, match=why):
            Augmentation.parse(bad)


def test_variants_start_with_the_clip_and_its_mirror_image_and_stay_in_range(walk, box):
    rng = np.random.default_rng(5)
    out = variants(walk, Augmentation(KINDS, 4), rng, [box])
    assert len(out) == 5 and out[0] is walk
    np.testing.assert_allclose(out[1].positions, mirrored(walk).positions)
    for v in [random_variant(walk, Augmentation(("speed", "proportions")), rng) for _ in range(8)]:
        assert walk.duration / 1.26 <= v.duration <= walk.duration / 0.79
        ratio = np.linalg.norm(v.skeleton.offsets, axis=1)[1:] / np.linalg.norm(walk.skeleton.offsets, axis=1)[1:]
        ratio = ratio[np.isfinite(ratio)]
        assert np.all((ratio > 0.89) & (ratio < 1.11))
        assert np.all(np.isfinite(v.positions))
    assert variants(walk, Augmentation.parse("none"), rng) == [walk]


def test_augmentation_names_parse_and_unknown_ones_are_refused():
    assert Augmentation.parse("all").kinds == KINDS
    assert Augmentation.parse("speed, mirror").kinds == ("mirror", "speed")
    assert Augmentation.parse("none").variants == 0 and Augmentation.parse("none").spec == "none"
    with pytest.raises(ValueError, match="unknown augmentation heading.*mirror"):
        Augmentation.parse("mirror,heading")
    assert set(SEGMENTS) >= {"thigh", "shin", "upper_arm", "forearm", "torso"}


def test_the_train_commands_help_names_every_kind(capsys, monkeypatch):
    from sparse_body.cli import main

    monkeypatch.setenv("COLUMNS", "200")  # argparse would break a word longer than a narrow terminal
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert ",".join(KINDS) in text


@pytest.mark.train
def test_ablation_command_writes_each_runs_validation(tmp_path, train_mocap):
    from sparse_body.cli import main

    out = tmp_path / "lobstr.onnx"
    with pytest.raises(SystemExit) as done:
        main(
            [
                "train",
                "lobstr",
                "--config",
                "tiny",
                "--limit",
                "2",
                "--ablate-augment",
                "--augment",
                "mirror,speed",
                "--out",
                str(out),
                "--mocap",
                str(train_mocap),
            ]
        )
    assert done.value.code == 0
    report = json.loads((tmp_path / "lobstr.augment.json").read_text())
    assert [r["augment"] for r in report["runs"]] == ["none", "mirror,speed", "speed", "mirror"]
    for run in report["runs"]:
        assert run["steps"] == 3 and np.isfinite(run["validation"]["lower_rot_error_deg"])
    assert not out.exists()  # ablation runs train throwaway models
    from sparse_body.train.lobstr.card import LOBSTR_VALIDATION
    from sparse_body.train.model_card import augmentation_table

    table = augmentation_table(tmp_path / "lobstr.train.json", LOBSTR_VALIDATION)
    for spec in ("none", "mirror", "mirror,speed", "speed"):
        assert table.count(f"\n| {spec} |") == 1
    assert f"{report['runs'][0]['validation']['toe_error_cm']:.4g}" in table
    assert "missing" in augmentation_table(tmp_path / "other.train.json", LOBSTR_VALIDATION)


def test_a_tilted_variant_lies_off_its_feet_on_the_floor_and_keeps_its_limbs_motion(walk):
    """The tilt augmentation: the body turned off upright by the drawn angle, about an axis of
    the drawn direction, held where the clip starts, its lowest joint just over the floor, the
    limbs moving as in the clip (their local turns unchanged)."""
    from sparse_body.core.skeleton import JOINT_INDEX
    from sparse_body.data.floor import FLOOR_CLEARANCE
    from sparse_body.train.augment import TILT_RANGE, tilted

    for degrees, towards in ((90.0, 0.0), (45.0, 1.0), (100.0, 4.0)):
        laid = tilted(walk, degrees, towards)
        np.testing.assert_allclose(laid.local_quats[:, 1:], walk.local_quats[:, 1:])
        up = laid.positions[:, JOINT_INDEX["spine3"]] - laid.positions[:, JOINT_INDEX["pelvis"]]
        stood = walk.positions[:, JOINT_INDEX["spine3"]] - walk.positions[:, JOINT_INDEX["pelvis"]]
        tilt = np.degrees(np.arccos(up[:, 2] / np.linalg.norm(up, axis=1)))
        stood_tilt = np.degrees(np.arccos(stood[:, 2] / np.linalg.norm(stood, axis=1)))
        assert np.all(np.abs(tilt - degrees) <= stood_tilt + 1.0)  # the walk's own lean, at most
        np.testing.assert_allclose(laid.positions[..., 2].min(axis=1), FLOOR_CLEARANCE, atol=1e-9)
        assert np.ptp(laid.root_positions[:, :2], axis=0).max() == 0.0  # held where it starts
        assert laid.floor == 0.0
    rng = np.random.default_rng(3)
    share = Augmentation.parse("tilt=1")
    drawn = [random_variant(walk, share, rng) for _ in range(6)]
    assert all("/tilt" in v.name for v in drawn)
    assert all(TILT_RANGE[0] - 1 <= float(v.name.rsplit("tilt", 1)[1]) <= TILT_RANGE[1] + 1 for v in drawn)
    assert not any("/tilt" in random_variant(walk, Augmentation.parse("tilt=0"), rng).name for _ in range(6))
