from PIL import Image

from sparse_body.core.sensors import load_sensor_config
from sparse_body.demo import run_demo


def test_demo_without_mocap_says_so_and_writes_bags_and_animation(tmp_path, capsys):
    metrics = run_demo(tmp_path, load_sensor_config("six_point"), "ik", mocap_root=None, seconds=1.0)
    out = capsys.readouterr().out
    assert "SYNTHETIC walk" in out
    assert (tmp_path / "trackers").is_dir() and (tmp_path / "estimates").is_dir()
    assert Image.open(tmp_path / "demo.gif").n_frames == 15
    assert metrics["End-effector PE [cm]"] < 1.0
