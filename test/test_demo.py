from PIL import Image

from sparse_body.apps.demo import run_demo
from sparse_body.core.sensors import load_sensor_config


def test_demo_without_mocap_says_so_and_writes_bags_and_animation(tmp_path, capsys):
    metrics = run_demo(tmp_path, load_sensor_config("six_point"), "ik", mocap_root=None, seconds=1.0)
    out = capsys.readouterr().out
    assert "SYNTHETIC walk" in out
    assert (tmp_path / "trackers").is_dir() and (tmp_path / "estimates").is_dir()
    gif = Image.open(tmp_path / "demo.gif")
    durations = []
    for k in range(gif.n_frames):
        gif.seek(k)
        durations.append(gif.info["duration"])
    # the motion's real speed: 1 s of motion plays for 1 s (the old GIF ran 10 % fast)
    assert gif.n_frames == 20 and sum(durations) == 1000, (gif.n_frames, set(durations))
    assert "nan" not in out  # a metric without a value says why
    # a second run replaces its own bags; a folder of the user's in their place is refused
    run_demo(tmp_path, load_sensor_config("six_point"), "ik", mocap_root=None, seconds=0.5, gif=False)
    import shutil

    import pytest

    from sparse_body.io.bagio import OutputError

    shutil.rmtree(tmp_path / "trackers")
    (tmp_path / "trackers").mkdir()
    (tmp_path / "trackers" / "mine.txt").write_text("a user's file")
    with pytest.raises(OutputError, match="never replaced"):
        run_demo(tmp_path, load_sensor_config("six_point"), "ik", mocap_root=None, seconds=0.5, gif=False)
    assert (tmp_path / "trackers" / "mine.txt").read_text() == "a user's file"
    assert metrics["End-effector PE [cm]"] < 1.0
