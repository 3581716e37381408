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


def test_the_synthetic_walk_plants_its_feet():
    """The walk a user without motion capture sees: its feet stand on the floor for about
    half of each stride and do not slide there (it slid at 3.8 m/s, so the demo's skate was
    "n/a: no frame has a foot in contact"), measured by the metrics' own contact labels."""
    import numpy as np

    from sparse_body.core.contacts import FOOT_JOINTS, contact_labels, estimate_floor
    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.metrics import foot_skate
    from sparse_body.core.rotations import quat_to_matrix
    from sparse_body.data.synthetic import synthetic_walk

    walk = synthetic_walk(60.0)  # the straight and the circle
    _, pos = forward_kinematics(quat_to_matrix(walk.local_quats), walk.root_positions, walk.skeleton.offsets)
    contacts = contact_labels(pos, walk.fps)
    assert 0.4 < contacts.mean() < 0.7 and contacts.any(axis=1).all()  # a foot always stands
    assert foot_skate(pos, contacts, walk.fps) < 2.0  # cm/s
    assert pos[:, FOOT_JOINTS, 2].min() >= estimate_floor(pos) - 1e-9  # no foot under the floor
    speed = np.linalg.norm(np.diff(walk.root_positions[:, :2], axis=0), axis=1) * walk.fps
    assert abs(speed.mean() - 1.0) < 0.05  # the speed asked for
    metrics = run_demo_metrics()
    assert metrics["Contact acc [%]"] > 90.0 and metrics["Skate [cm/s]"] < 5.0


def run_demo_metrics() -> dict:
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        return run_demo(Path(folder), load_sensor_config("six_point"), "ik", mocap_root=None, seconds=3.0, gif=False)


def test_the_animation_follows_the_body_large_with_a_head_and_labelled_axes(tmp_path):
    """The GIF once framed a 6.5 m box: the body about 100 px tall in 560, no z label, the head
    a square. Now a 2.5 m box follows the pelvis."""
    import numpy as np

    from sparse_body.apps.demo import FOLLOW_HALF, animate, follow_box
    from sparse_body.data.synthetic import synthetic_walk

    walk = synthetic_walk(4.0)
    positions = walk.positions
    centres, top = follow_box(positions, 0.0)
    assert np.abs(centres - positions[:, 0, :2]).max() < FOLLOW_HALF / 2  # the box stays on the body
    assert top > positions[..., 2].max() + 0.3
    animate(tmp_path / "a.gif", positions, positions, positions[:, [15, 20, 21]], walk.fps, "walk")
    gif = Image.open(tmp_path / "a.gif")
    for k in (0, gif.n_frames - 1):  # the body as large at the end of the walk as at its start
        gif.seek(k)
        image = np.asarray(gif.convert("RGB"), dtype=int)
        blue = np.all(np.abs(image - [0x1F, 0x77, 0xB4]) < 40, axis=-1)  # tab:blue, the estimate
        rows = np.flatnonzero(blue.any(axis=1))
        assert rows[-1] - rows[0] > 150, (k, rows[-1] - rows[0])
