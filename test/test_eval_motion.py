"""`sparse-body eval --motion` on another lab's ASF/AMC distribution, laid out as such
distributions are (test/generated_mocap.py): every actor's ASF beside the AMC files in a
folder per motion class, an upper-case .AMC, stray files. Skeleton matching, the AMC rate,
results written clip by clip and resumed, bad files skipped, seeds from identity, balanced
--limit, groups with intervals, one parse per file, output in a named results folder."""

import json
import os
import shutil

import generated_mocap as gen
import pytest

from sparse_body import evaluation
from sparse_body.cli import EXIT_INPUT, main
from sparse_body.data import catalog
from sparse_body.data.motion_inputs import balanced, find_inputs


@pytest.fixture(autouse=True)
def own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SPARSE_BODY_CACHE", str(tmp_path / "cache"))


def run_cli(capsys, *argv):
    with pytest.raises(SystemExit) as ended:
        main([str(a) for a in argv])
    out = capsys.readouterr()
    return ended.value.code, out.out, out.err


def eval_args(*extra):
    return ["eval", "--estimator", "ik", "--sensors", "six_point", "--no-compare", "--quiet", *extra]


def test_each_amc_gets_its_actors_asf_by_name_prefix(tmp_path):
    dist = gen.by_motion_class(tmp_path / "dist")
    inputs = find_inputs([dist])
    assert {i.path.name: i.skeleton.name for i in inputs} == {
        "actorA_run01.amc": "actorA.asf",
        "actorB_run01.amc": "actorB.asf",
        "actorA_walk01.amc": "actorA.asf",
        "actorA_walk02.amc": "actorA.asf",
        "actorB_walk01.AMC": "actorB.asf",
    }  # .DS_Store, notes.mat left out
    assert {i.how for i in inputs} == {"name prefix"}
    assert [i.group for i in inputs] == ["run", "run", "walk", "walk", "walk"]
    assert [i.group for i in find_inputs([dist], group_by="prefix")] == [
        "actorA",
        "actorB",
        "actorA",
        "actorA",
        "actorB",
    ]
    # CMU's own naming is a prefix too: 16.asf beside 16_05.amc, with another subject's ASF there
    gen.write(tmp_path / "cmu" / "16.asf", gen.asf())
    gen.write(tmp_path / "cmu" / "161.asf", gen.asf())
    gen.write(tmp_path / "cmu" / "16_05.amc", gen.amc(10))
    assert find_inputs([tmp_path / "cmu"])[0].skeleton.name == "16.asf"


def test_an_amc_without_a_matching_asf_is_an_error_listing_the_candidates(tmp_path, capsys):
    gen.write(tmp_path / "a" / "actorA.asf", gen.asf())
    gen.write(tmp_path / "a" / "actorB.asf", gen.asf())
    amc = gen.write(tmp_path / "a" / "take01.amc", gen.amc(60))
    code, out, err = run_cli(capsys, *eval_args("--motion", tmp_path / "a", "--output", tmp_path / "r.json"))
    assert code == EXIT_INPUT and len(err.strip().splitlines()) == 1, err
    assert "actorA.asf, actorB.asf" in err and "--skeleton-file" in err and "AMC=ASF" in err
    assert not (tmp_path / "r.json").exists()
    # paired on the command line, or one skeleton for all: both run
    code, out, err = run_cli(
        capsys, *eval_args("--motion", f"{amc}={tmp_path / 'a' / 'actorB.asf'}", "--output", tmp_path / "r.json")
    )
    assert code == 0, err
    assert "1 paired" in err
    code, out, err = run_cli(
        capsys,
        *eval_args("--motion", amc, "--skeleton-file", tmp_path / "a" / "actorA.asf", "--output", tmp_path / "r2.json"),
    )
    assert code == 0 and "1 given" in err, err
    source = json.loads((tmp_path / "r2.json").read_text())[0]["clips"][0]["source"]
    assert "actorA.asf (given)" in source


def test_another_actors_skeleton_is_said(tmp_path, capsys):
    gen.write(tmp_path / "a" / "tall.asf", gen.asf(1.25))  # the only ASF: used, but the feet go through the floor
    gen.write(tmp_path / "a" / "short_walk.amc", gen.amc(120))
    code, out, err = run_cli(capsys, *eval_args("--motion", tmp_path / "a", "--output", tmp_path / "r.json"))
    assert code == 0, err
    assert "warning" in err and "below the floor" in err and "tall.asf (the only ASF in its folder)" in err
    gen.write(tmp_path / "b" / "short.asf", gen.asf(1.0))
    gen.write(tmp_path / "b" / "short_walk.amc", gen.amc(120))
    code, out, err = run_cli(capsys, *eval_args("--motion", tmp_path / "b", "--output", tmp_path / "r2.json"))
    assert code == 0 and "warning" not in err, err


def test_the_amc_rate_is_an_option_and_said(tmp_path, capsys):
    dist = gen.by_motion_class(tmp_path / "dist", frames=120)
    code, _, err = run_cli(capsys, *eval_args("--motion", dist / "run", "--output", tmp_path / "r120.json"))
    assert code == 0 and "captured at 120 Hz" in err, err
    code, _, err = run_cli(
        capsys, *eval_args("--motion", dist / "run", "--amc-fps", 60, "--output", tmp_path / "r60.json")
    )
    assert code == 0 and "captured at 60 Hz" in err, err
    frames = {name: json.loads((tmp_path / name).read_text())[0]["frames"] for name in ("r120.json", "r60.json")}
    assert frames["r60.json"] == 2 * frames["r120.json"] == 2 * 2 * 60  # 120 frames: 1 s at 120 Hz, 2 s at 60 Hz


def test_a_bad_file_is_skipped_and_a_stopped_run_resumes(tmp_path, capsys, monkeypatch):
    dist = gen.by_motion_class(tmp_path / "dist", frames=60)
    gen.write(dist / "walk" / "actorA_walk03.amc", ":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 1 0\n")  # broken
    out = tmp_path / "r.json"
    real, calls = evaluation.evaluate_motion, []

    def stopping(motion, *args, **kwargs):  # the third clip: the user presses Ctrl-C
        calls.append(motion.name)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(motion, *args, **kwargs)

    monkeypatch.setattr(evaluation, "evaluate_motion", stopping)
    code, _, err = run_cli(capsys, *eval_args("--motion", dist, "--output", out))
    assert code == 130
    kept = json.loads(out.read_text())[0]
    assert len(kept["clips"]) == 2  # written as they came
    calls.clear()
    monkeypatch.setattr(evaluation, "evaluate_motion", lambda m, *a, **k: calls.append(m.name) or real(m, *a, **k))
    code, stdout, err = run_cli(capsys, *eval_args("--motion", dist, "--output", out))
    assert code == EXIT_INPUT and "1 of 6 clips skipped" in err and "actorA_walk03.amc" in err, err
    assert len(calls) == 3  # only what was left
    result = json.loads(out.read_text())[0]
    assert len(result["clips"]) == 5 and [s["clip"] for s in result["skipped"]] == ["actorA_walk03.amc"]
    assert result["clips"][:2] == kept["clips"]
    calls.clear()
    code, _, _ = run_cli(capsys, *eval_args("--motion", dist, "--output", out))  # all done: nothing to do
    assert code == EXIT_INPUT and calls == []


def test_a_clips_draws_follow_its_identity_not_its_place(tmp_path, capsys):
    dist = gen.by_motion_class(tmp_path / "dist", frames=60)
    walk = sorted((dist / "walk").glob("*.[aA][mM][cC]"))
    first = evaluation.evaluate("ik", _six(), None, motions=[walk[0], walk[1]], progress=False)
    again = evaluation.evaluate("ik", _six(), None, motions=[walk[2], walk[1], walk[0]], progress=False)

    def per_clip(r):  # as JSON text: NaN == NaN
        return {c: json.dumps(m, sort_keys=True) for c, m in zip(r.clips, r.per_clip, strict=True)}

    assert per_clip(again)[walk[1].name] == per_clip(first)[walk[1].name]
    assert per_clip(again)[walk[0].name] == per_clip(first)[walk[0].name]
    # the same content under another name is another clip: its own draws
    shutil.copy(walk[0], tmp_path / "copy_walk01.amc")
    shutil.copy(dist / "walk" / "actorA.asf", tmp_path / "copy.asf")
    copy = evaluation.evaluate("ik", _six(), None, motions=[tmp_path / "copy_walk01.amc"], progress=False)
    assert per_clip(copy)["copy_walk01.amc"] != per_clip(first)[walk[0].name]


def _six():
    from sparse_body.core.sensors import load_sensor_config

    return load_sensor_config("six_point")


def test_limit_is_balanced_over_folders_and_groups_are_tabled(tmp_path, capsys):
    dist = gen.by_motion_class(tmp_path / "dist", frames=60)
    picked = balanced(find_inputs([dist]), 3)
    assert [i.group for i in picked] == ["run", "walk", "run"]
    code, stdout, err = run_cli(
        capsys, *eval_args("--estimator", "reference", "--motion", dist, "--limit", 4, "--output", tmp_path / "r.json")
    )
    assert code == 0, err
    assert "MPJPE [cm] by folder" in stdout and "run (2 clips)" in stdout and "walk (2 clips)" in stdout
    result = json.loads((tmp_path / "r.json").read_text())
    assert [r["estimator"] for r in result] == ["ik", "reference"]
    groups = result[0]["groups"]
    assert set(groups) == {"run", "walk"} and groups["run"]["clips"] == 2
    low, high = groups["walk"]["interval_95"]["MPJPE [cm]"]
    assert low <= groups["walk"]["summary"]["MPJPE [cm]"] <= high and low < high


def test_each_file_is_parsed_once_for_every_estimator_and_not_again(tmp_path, capsys, monkeypatch):
    dist = gen.by_motion_class(tmp_path / "dist", frames=60)
    real, parsed = catalog.load_amc, []
    monkeypatch.setattr(catalog, "load_amc", lambda path, *a, **k: parsed.append(path.name) or real(path, *a, **k))
    code, _, err = run_cli(
        capsys, *eval_args("--estimator", "reference", "--motion", dist, "--output", tmp_path / "a.json")
    )
    assert code == 0, err
    assert sorted(parsed) == sorted(p.name for p in dist.rglob("*.[aA][mM][cC]"))  # 5 files, 2 estimators
    parsed.clear()
    code, _, err = run_cli(capsys, *eval_args("--motion", dist, "--output", tmp_path / "b.json"))
    assert code == 0 and parsed == [], err  # another run: the cache


def test_results_go_to_a_named_results_folder(tmp_path, capsys, monkeypatch):
    dist = gen.by_motion_class(tmp_path / "dist", frames=60)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    code, stdout, err = run_cli(capsys, *eval_args("--motion", dist / "run"))
    assert code == 0, err
    assert os.listdir(work) == ["sparse_body_results"]
    written = work / "sparse_body_results" / "eval_ik_six_point.json"
    assert written.is_file() and f"results: {written.relative_to(work)}" in err


def test_view_estimates_a_clip_of_a_result_again_and_gets_the_figure_the_file_holds(tmp_path, capsys):
    """A results file keeps metrics, not poses: `view RESULTS --clip` runs the clip again as
    eval did (its file, seed, protocol) and says the figure now beside the stored one."""
    from sparse_body.apps.result_view import METRIC, view_clip

    dist = gen.by_motion_class(tmp_path / "dist")
    out = tmp_path / "results.json"
    argv = eval_args("--estimator", "reference", "--motion", dist / "walk", "--faulty", "5", "--output", out)
    code, _, _ = run_cli(capsys, *argv)
    assert code == 0
    stored = json.loads(out.read_text())
    clip = stored[0]["clips"][0]
    assert clip["source"].endswith(")") and " with " in clip["source"]  # an AMC with its actor's ASF

    shown = view_clip(out, clip["clip"], "ik")
    assert shown.now == pytest.approx(clip[METRIC], rel=1e-9)  # the same estimate, not a similar one
    assert shown.parts()["estimate"].shape == (clip["frames"], 22, 3)
    code, said, _ = run_cli(capsys, "view", out, "--clip", clip["clip"], "--estimator", "ik", "-o", tmp_path / "p.html")
    assert code == 0 and f"(stored {clip[METRIC]:.2f})" in said and (tmp_path / "p.html").stat().st_size > 100_000

    code, _, err = run_cli(capsys, "view", out, "--clip", clip["clip"])
    assert code != 0 and "choose one with --estimator" in err and len(err.strip().splitlines()) == 1
    code, _, err = run_cli(capsys, "view", out, "--clip", "nope.amc", "--estimator", "ik")
    assert code != 0 and "no clip 'nope.amc'" in err

    amc = clip["source"].partition(" with ")[0]
    with open(amc, "a") as f:  # the file is not what was evaluated any more
        f.write("\n")
    code, _, err = run_cli(capsys, "view", out, "--clip", clip["clip"], "--estimator", "ik")
    assert code != 0 and "content changed" in err
    for result in stored:  # a file written before results said their protocol
        del result["protocol_spec"]
    out.write_text(json.dumps(stored))
    code, _, err = run_cli(capsys, "view", out, "--clip", clip["clip"], "--estimator", "ik")
    assert code != 0 and "run the eval again" in err


def test_a_measuring_script_without_motion_capture_is_told_so_in_one_line(monkeypatch, tmp_path):
    """part_items: the scripts' clips, a folder's files or a split's; without either, one line."""
    from sparse_body.data import MotionFileError
    from sparse_body.evaluation import part_items

    monkeypatch.setattr(catalog, "find_mocap_root", lambda explicit=None: None)
    with pytest.raises(catalog.MocapFolderError, match="no motion capture folder found") as caught:
        part_items("selection")
    assert "\n" not in str(caught.value)
    with pytest.raises(MotionFileError, match="no motion files"):  # a folder of one's own, empty
        part_items("selection", str(tmp_path))
