"""Inputs within limits, and the exit codes of the README's table. Each case was a reproduction
on main: a 455-byte sensor configuration of nested YAML aliases grew past 2.2 GB (a 6-level one
printed a 52 MB "one-line" error); a 4.9 MB .npz declared 4.4 GB; a 5-minute `make-bag` walk
left the play space; a folder named x.mcap was left out of a batch without a word; a motion
holding 1e308 failed with "SVD did not converge"; and five errors had the wrong exit code."""

from __future__ import annotations

import re
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from sparse_body.cli import EXIT_INPUT, EXIT_OUTPUT, EXIT_TOO_LARGE, EXIT_USAGE, main
from sparse_body.core.sensors import SensorConfigError, load_sensor_config
from sparse_body.core.textfile import InputTooLarge, load_yaml

TABLE = Path(__file__).resolve().parents[1] / "docs" / "outputs.md"  # the exit codes' table, linked from the README


def run_cli(capsys, *argv) -> tuple[int, str]:
    with pytest.raises(SystemExit) as ended:
        main([str(a) for a in argv])
    return ended.value.code, capsys.readouterr().err


def alias_bomb(levels: int) -> str:
    """Nine aliases of the level below on each level: 9**levels values from a few hundred bytes."""
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for k in range(1, levels + 1):
        lines.append(f"a{k}: &a{k} [" + ", ".join([f"*a{k - 1}"] * 9) + "]")
    return "\n".join(lines) + "\nsites: *a" + str(levels) + "\n"


@pytest.mark.parametrize("levels", [6, 9])
def test_a_yaml_alias_bomb_is_refused_at_once_in_one_short_line(tmp_path, capsys, levels):
    path = tmp_path / "bomb.yaml"
    path.write_text(alias_bomb(levels))
    assert len(path.read_bytes()) < 600
    start = time.monotonic()
    with pytest.raises(SensorConfigError) as refused:
        load_sensor_config(str(path))
    assert isinstance(refused.value, InputTooLarge) and "aliases" in str(refused.value)
    assert time.monotonic() - start < 5.0
    code, err = run_cli(capsys, "make-bag", tmp_path / "out", "--seconds", "1", "--sensors", path)
    assert code == EXIT_TOO_LARGE and len(err) < 1000 and err.count("\n") == 1, err[:300]
    assert not (tmp_path / "out").exists()


def test_yaml_that_is_deep_or_refers_to_itself_is_too_large_and_plain_yaml_loads():
    for text in ("[" * 100_000 + "]" * 100_000, "&a [*a, *a]"):
        with pytest.raises(InputTooLarge):
            load_yaml(text)
    assert load_yaml("a: &x [1, 2]\nb: *x\n") == {"a": [1, 2], "b": [1, 2]}  # aliases as such are fine


def test_an_npz_that_declares_more_than_the_motion_limit_is_refused_before_reading(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SPARSE_BODY_MAX_MOTION_MIB", "1")  # the same rule as 512 MiB, at test size
    bomb = tmp_path / "bomb.npz"
    header = b"\x93NUMPY\x01\x00v\x00{'descr': '<f8', 'fortran_order': False, 'shape': (524288, 22, 4), }"
    header += b" " * (127 - len(header)) + b"\n"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as archive:
        with archive.open("local_quats.npy", "w", force_zip64=True) as member:
            member.write(header)
            for _ in range(4):  # 4 MiB of zeros: a few kB compressed
                member.write(bytes(1 << 20))
        archive.writestr("root_positions.npy", b"")
    assert bomb.stat().st_size < 100_000
    code, err = run_cli(capsys, "view", bomb, "-o", tmp_path / "page.html")
    assert code == EXIT_TOO_LARGE and "once decompressed" in err and "SPARSE_BODY_MAX_MOTION_MIB" in err, err
    assert not (tmp_path / "page.html").exists()


def test_a_long_synthetic_walk_stays_in_the_play_space_and_moves_smoothly():
    from sparse_body.data.synthetic import synthetic_walk
    from sparse_body.io.tf_guards import TfGuards

    walk = synthetic_walk(300.0)
    radius = np.linalg.norm(walk.root_positions[:, :2], axis=1)
    assert radius.max() < TfGuards.play_radius / 2
    step = np.linalg.norm(np.diff(walk.root_positions, axis=0), axis=1) * walk.fps
    assert step.max() < 1.3  # m/s: the turn onto the circle does not jump
    short = synthetic_walk(4.0)  # a short walk is what it was: straight along +x
    assert np.allclose(short.root_positions[:, 1], 0.0) and np.all(np.diff(short.root_positions[:, 0]) > 0)


def test_a_five_minute_make_bag_walk_gives_valid_estimates(tmp_path, capsys):
    from sparse_body.io.bagio import read_topic

    assert run_cli(capsys, "make-bag", tmp_path / "walk", "--seconds", "300", "--sensors", "six_point")[0] == 0
    assert run_cli(capsys, "process", tmp_path / "walk", tmp_path / "out", "--quiet")[0] == 0
    statuses = read_topic(tmp_path / "out", "/estimate_status")
    assert len(statuses) == 18_000 and all(s.valid for s in statuses[60:])


def test_a_folder_named_like_an_mcap_file_is_reported_not_left_out(tmp_path, capsys):
    from sparse_body.apps.offline import make_bag
    from sparse_body.data.synthetic import synthetic_walk

    (tmp_path / "in").mkdir()
    make_bag(synthetic_walk(1.0), load_sensor_config("six_point"), tmp_path / "in" / "walk")
    (tmp_path / "in" / "x.mcap").mkdir()
    code, err = run_cli(capsys, "process", tmp_path / "in", tmp_path / "out", "--quiet")
    assert code == EXIT_INPUT and "x.mcap" in err and err.count("\n") == 1, err


def test_a_motion_holding_1e308_is_refused_naming_the_file(tmp_path):
    from generated_mocap import amc, asf, write

    from sparse_body.data import MotionFileError
    from sparse_body.data.catalog import load_motion_file

    write(tmp_path / "actor.asf", asf())
    lines = amc().splitlines()
    first_root = next(i for i, line in enumerate(lines) if line.startswith("root"))
    lines[first_root] = "root 1e308 0 0 0 0 0"
    clip = write(tmp_path / "actor_walk.amc", "\n".join(lines) + "\n")
    with pytest.raises(MotionFileError, match=r"actor_walk\.amc: holds positions that are not finite"):
        load_motion_file(clip)


def test_every_exit_code_of_the_table_is_what_the_commands_give(tmp_path, capsys):
    """The table, walked: each row's code from a command whose error is of that kind."""
    table = dict(re.findall(r"^\| (\d+) \| (.+?) \|$", TABLE.read_text(), re.M))
    assert {"1", "2", "3", "4", "5"} <= set(table)
    from sparse_body.data.synthetic import synthetic_walk

    (tmp_path / "empty").mkdir()
    (tmp_path / "notes.html").write_text("<html><head></head><body>mine</body></html>")
    synthetic_walk(0.5).save(tmp_path / "walk.npz")
    assert run_cli(capsys, "make-bag", tmp_path / "trackers", "--seconds", "1")[0] == 0
    deep = tmp_path / "deep.yaml"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    readonly = tmp_path / "readonly"
    readonly.mkdir(mode=0o500)
    cases = [
        (EXIT_INPUT, ["eval", "--mocap", tmp_path / "empty", "--estimator", "ik"]),  # no indexed capture there
        (EXIT_INPUT, ["make-bag", tmp_path / "b", "--seconds", "1", "--sensors", tmp_path / "none.yaml"]),
        (EXIT_USAGE, ["make-bag", tmp_path / "b", "--seconds", "-1"]),
        (EXIT_INPUT, ["process", tmp_path / "trackers", tmp_path / "o", "--estimator", "lobstr:model_path=none.onnx"]),
        (EXIT_OUTPUT, ["view", tmp_path / "walk.npz", "-o", tmp_path / "notes.html"]),
        (EXIT_OUTPUT, ["process", tmp_path / "trackers", tmp_path / "notes.html"]),
        # an output whose parent is a file: refused alike by every command (view and eval said 4)
        (EXIT_OUTPUT, ["view", tmp_path / "walk.npz", "-o", tmp_path / "notes.html" / "page.html"]),
        (EXIT_OUTPUT, ["process", tmp_path / "trackers", tmp_path / "notes.html" / "out"]),
        (EXIT_OUTPUT, ["make-bag", tmp_path / "notes.html" / "b", "--seconds", "1"]),
        (
            EXIT_OUTPUT,
            [
                "eval",
                "--motion",
                tmp_path / "walk.npz",
                "--estimator",
                "ik",
                "--sensors",
                "six_point",
                "--output",
                tmp_path / "notes.html" / "r.json",
            ],
        ),
        (EXIT_TOO_LARGE, ["make-bag", tmp_path / "b", "--seconds", "1", "--sensors", deep]),
    ]
    import os

    if os.geteuid() != 0:  # root writes anywhere: the OS refuses nothing to it
        from sparse_body.cli import EXIT_OS

        cases.append((EXIT_OS, ["make-bag", readonly / "b", "--seconds", "1"]))
    for code, argv in cases:
        got, err = run_cli(capsys, *argv)
        assert (got, err.count("\n")) == (code, 1), (argv, got, err)
        assert str(code) in table


def test_training_without_the_training_tools_is_one_line_naming_the_setup(tmp_path):
    """`make setup` leaves torch out: `sparse-body train` there says how to get it (it printed
    a ModuleNotFoundError traceback). Run where torch cannot be imported, whatever is installed."""
    import subprocess
    import sys

    hide = "import sys; sys.modules['torch'] = None; from sparse_body.cli import main; main(sys.argv[1:])"
    done = subprocess.run(
        [sys.executable, "-c", hide, "train", "lobstr", "--steps", "1", "--out", str(tmp_path / "m.onnx")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == EXIT_INPUT, done.stderr
    assert done.stderr.count("\n") == 1 and "make setup-train" in done.stderr and "torch" in done.stderr


@pytest.mark.parametrize("damage", ["flipped byte", "understated size"])
def test_a_damaged_npz_is_one_line_and_exit_1(tmp_path, capsys, damage):
    """A member whose bytes fail their CRC, or whose size its directory understates, raised
    zipfile's own error from inside the reading: a traceback."""
    from sparse_body.data.synthetic import synthetic_walk

    good = tmp_path / "walk.npz"
    synthetic_walk(1.0).save(good)
    data = bytearray(good.read_bytes())
    with zipfile.ZipFile(good) as archive:
        member = archive.getinfo("local_quats.npy")
    if damage == "flipped byte":
        data[member.header_offset + 30 + len(member.filename) + 200] ^= 0xFF  # inside the member's data
    else:  # the central directory's uncompressed size of the member, halved
        central = bytes(data).find(b"local_quats.npy", data.find(b"PK\x01\x02")) - 46
        size = int.from_bytes(data[central + 24 : central + 28], "little")
        data[central + 24 : central + 28] = (size // 2).to_bytes(4, "little")
    bad = tmp_path / "damaged.npz"
    bad.write_bytes(bytes(data))
    code, err = run_cli(capsys, "view", bad, "-o", tmp_path / "page.html")
    assert code == 1 and err.count("\n") == 1 and "Traceback" not in err and str(bad) in err, err
    assert not (tmp_path / "page.html").exists()


def test_missing_inputs_and_refused_outputs_are_said_before_any_work_or_folder(tmp_path, capsys, monkeypatch):
    """`view nothing_here` said "unknown motion format"; `demo --estimator iik` made its folder
    before refusing; `view` of a bag whose page may not be replaced read the whole bag first."""
    import time

    from sparse_body.apps.offline import make_bag
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.data.synthetic import synthetic_walk

    monkeypatch.chdir(tmp_path)
    code, err = run_cli(capsys, "view", "nothing_here")
    assert code == EXIT_INPUT and "nothing_here: no such file or folder" in err, err
    code, err = run_cli(capsys, "process", "nothing_here", "out")
    assert code == EXIT_INPUT and "nothing_here: no such file or folder" in err, err
    code, err = run_cli(capsys, "demo", "--estimator", "iik")
    assert code == EXIT_INPUT and "unknown estimator 'iik'" in err and not (tmp_path / "sparse_body_demo").exists()
    make_bag(synthetic_walk(1.0), load_sensor_config("six_point"), tmp_path / "bag")
    (tmp_path / "bag.html").write_text("<html><head></head><body>mine</body></html>")
    start = time.monotonic()
    code, err = run_cli(capsys, "view", "bag")  # its page would be bag.html: the user's
    assert code == EXIT_OUTPUT and "bag.html: exists and is not a page" in err, err
    assert time.monotonic() - start < 5.0  # (reading the bag first took 6 s for 5 s of it)
