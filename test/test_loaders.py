"""BVH and ASF/AMC loaders on tiny files (sparse_body/data/samples.py) with hand-computed answers,
and on broken ones."""

import gzip

import numpy as np
import pytest

from sparse_body.data import MotionFileError
from sparse_body.data.asf_amc import load_amc, load_asf
from sparse_body.data.bvh import load_bvh
from sparse_body.data.samples import TINY_AMC, TINY_ASF, TINY_BVH

BVH, ASF, AMC = TINY_BVH, TINY_ASF, TINY_AMC


def test_bvh_positions_hand_computed(tmp_path):
    path = tmp_path / "tiny.bvh.gz"
    path.write_bytes(gzip.compress(BVH.encode()))
    m = load_bvh(path, length_unit=0.01)
    assert m.joint_names == ["Hips", "Chest", "Chest_End"] and m.parents == [-1, 0, 1]
    assert m.fps == pytest.approx(2.0) and m.name == "tiny"
    np.testing.assert_allclose(m.positions[0], [[0, 1, 0], [0, 1.1, 0], [0, 1.15, 0]], atol=1e-12)
    # Frame 2: root moved 20 cm along x, chest turned 90 degrees about z: its child swings to -x.
    np.testing.assert_allclose(m.positions[1], [[0.2, 1, 0], [0.2, 1.1, 0], [0.15, 1.1, 0]], atol=1e-12)
    np.testing.assert_allclose(m.rest_positions, [[0, 0, 0], [0, 0.1, 0], [0, 0.15, 0]], atol=1e-12)


def test_truncated_bvh_names_file_and_problem(tmp_path):
    path = tmp_path / "cut.bvh"
    path.write_text(BVH.rsplit("\n", 2)[0] + "\n")  # last frame lost
    with pytest.raises(MotionFileError, match=r"cut\.bvh: MOTION declares 2 frames of 9 channels but holds 1"):
        load_bvh(path)
    path.write_text(BVH.split("MOTION")[0])
    with pytest.raises(MotionFileError, match=r"cut\.bvh: no MOTION section"):
        load_bvh(path)
    path.write_text(BVH.replace("20 100", "20 abc"))
    with pytest.raises(MotionFileError, match="non-numeric"):
        load_bvh(path)
    broken_gz = tmp_path / "broken.bvh.gz"
    broken_gz.write_bytes(gzip.compress(BVH.encode())[:60])
    with pytest.raises(MotionFileError, match=r"broken\.bvh\.gz: cannot be read"):
        load_bvh(broken_gz)
    with pytest.raises(MotionFileError, match="no such file"):
        load_bvh(tmp_path / "absent.bvh")


def test_asf_amc_positions_hand_computed(tmp_path):
    (tmp_path / "t.asf").write_text(ASF)
    (tmp_path / "t_01.amc").write_text(AMC)
    m = load_amc(tmp_path / "t_01.amc", load_asf(tmp_path / "t.asf"))
    u = 0.254  # 10 units of 1/1.0 inch
    assert m.joint_names == ["root", "a", "b", "c"]
    a, b, c = 1, 2, 3
    np.testing.assert_allclose(m.positions[0, [b, c]], [[u, 0, 0], [u, u, 0]], atol=1e-12)
    # Frame 2: a turns 90 degrees about z; b and c follow it.
    np.testing.assert_allclose(m.positions[1, [b, c]], [[0, u, 0], [-u, u, 0]], atol=1e-12)
    # Frame 3: b's rx acts in b's axis frame C = Rz(90), i.e. about world y: b's vector
    # (0, 1, 0) lies on that axis, so c stays put, but b's frame has turned.
    np.testing.assert_allclose(m.positions[2, [b, c]], [[u, 0, 0], [u, u, 0]], atol=1e-12)
    expected = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], dtype=float)  # 90 degrees about y
    np.testing.assert_allclose(m.rotations[2, b], expected, atol=1e-12)
    np.testing.assert_allclose(m.rotations[2, a], np.eye(3), atol=1e-12)


def test_amc_frame_missing_a_bone_is_named(tmp_path):
    (tmp_path / "t.asf").write_text(ASF)
    (tmp_path / "t_02.amc").write_text(AMC.replace("2\nroot 0 0 0 0 0 0\na 90\nb 0\n", "2\nroot 0 0 0 0 0 0\nb 0\n"))
    with pytest.raises(MotionFileError, match=r"t_02\.amc: frame 2 is missing bone\(s\) a"):
        load_amc(tmp_path / "t_02.amc", load_asf(tmp_path / "t.asf"))
    (tmp_path / "t_03.amc").write_text(AMC.replace("a 90", "a 90 4"))
    with pytest.raises(MotionFileError, match=r"bone 'a' has 2 values, its dof needs 1"):
        load_amc(tmp_path / "t_03.amc", load_asf(tmp_path / "t.asf"))
    (tmp_path / "bad.asf").write_text(ASF.replace("    b c\n", "    b zz\n"))
    with pytest.raises(MotionFileError, match=r"bad\.asf: hierarchy names undefined bones: zz"):
        load_asf(tmp_path / "bad.asf")


def _refused_quickly(load, path, *args):
    """A MotionFileError naming the file within a few seconds (a hang is a failure too)."""
    import signal

    def hang(*_):
        raise TimeoutError(f"{path.name}: the loader hangs")

    old = signal.signal(signal.SIGALRM, hang)
    signal.alarm(5)
    try:
        with pytest.raises(MotionFileError) as err:
            load(path, *args)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    assert path.name in str(err.value)
    return str(err.value)


@pytest.mark.parametrize(
    "old,new,problem",
    [
        ("CHANNELS 3 Zrotation", "CHANNELS -2 Zrotation", "CHANNELS"),  # looped forever
        ("Frame Time: 0.5", "Frame Time: 0", "Frame Time"),  # ZeroDivisionError
        ("Frame Time: 0.5", "Frame Time: inf", "Frame Time"),  # OverflowError
        ("Frame Time: 0.5", "Frame Time: nan", "Frame Time"),
        ("Frame Time: 0.5", "Frame Time: -0.5", "Frame Time"),
        ("Frame Time: 0.5", "Frame Time: 1e-300", "Frame Time"),  # frames collapsed
        ("Zrotation Xrotation Yrotation\n    End", "Wposition Xrotation Yrotation\n    End", "unknown channel"),
        ("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 3 Xrotation Xrotation Yrotation", "twice"),
        ("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 2 Xrotation Yrotation", "rotation channels"),
    ],
)
def test_malformed_bvh_is_a_clear_error_naming_the_file(tmp_path, old, new, problem):
    assert old in BVH
    path = tmp_path / "bad.bvh"
    text = BVH.replace(old, new, 1)
    if "CHANNELS 2" in new:  # keep the data consistent: one value fewer per frame
        text = text.replace("0 100 0 0 0 0 0 0 0", "0 100 0 0 0 0 0 0").replace(
            "20 100 0 0 0 0 90 0 0", "20 100 0 0 0 0 90 0"
        )
    path.write_text(text)
    assert problem in _refused_quickly(load_bvh, path)


@pytest.mark.parametrize(
    "old,new,problem",
    [
        ("    b c\n", "    b c\n    a a\n", "second parent"),  # a bone its own child: looped forever
        ("  length 1.0\n", "  length 0\n", "units length"),  # ZeroDivisionError
        ("order TX TY TZ RX RY RZ", "order X", "root order"),  # IndexError
        ("order TX TY TZ RX RY RZ", "order TX TY TW", "root order"),
        ("    dof rz", "    dof rx rx", "dof"),
        ("direction 1 0 0", "direction 1 0", "three finite numbers"),  # found by make fuzz: a matmul error
        ("    b c\n", "    b c\n    c b\n", "second parent"),  # found by make fuzz: a KeyError
        ("     length 10\n", "     length nan\n", "bone length"),
    ],
)
def test_malformed_asf_is_a_clear_error_naming_the_file(tmp_path, old, new, problem):
    assert old in ASF
    path = tmp_path / "bad.asf"
    path.write_text(ASF.replace(old, new, 1))
    assert problem in _refused_quickly(load_asf, path)


def test_angle_units_are_read_from_the_asf_and_the_amc(tmp_path):
    """`:units angle rad` (the ASF's axis angles) and `:RADIANS` (the AMC's values) are read,
    not assumed: the same motion in radians gives the same positions."""
    (tmp_path / "deg.asf").write_text(ASF)
    (tmp_path / "deg.amc").write_text(AMC)
    degrees = load_amc(tmp_path / "deg.amc", load_asf(tmp_path / "deg.asf"))
    rad = ASF.replace("angle deg", "angle rad").replace("axis 0 0 90 XYZ", f"axis 0 0 {np.pi / 2!r} XYZ")
    (tmp_path / "rad.asf").write_text(rad)
    amc_rad = (
        AMC.replace(":DEGREES", ":RADIANS").replace("a 90", f"a {np.pi / 2!r}").replace("b 90", f"b {np.pi / 2!r}")
    )
    (tmp_path / "rad.amc").write_text(amc_rad)
    radians = load_amc(tmp_path / "rad.amc", load_asf(tmp_path / "rad.asf"))
    np.testing.assert_allclose(radians.positions, degrees.positions, atol=1e-12)
    # an AMC in radians under a degrees ASF: its own header decides
    (tmp_path / "mixed.amc").write_text(amc_rad)
    np.testing.assert_allclose(
        load_amc(tmp_path / "mixed.amc", load_asf(tmp_path / "deg.asf")).positions, degrees.positions, atol=1e-12
    )
    (tmp_path / "bad.asf").write_text(ASF.replace("angle deg", "angle grad"))
    assert "deg or rad" in _refused_quickly(load_asf, tmp_path / "bad.asf")


def test_user_motion_files_upper_case_and_unknown_layouts(tmp_path, mocap_root):
    import gzip
    import shutil

    from sparse_body.data.catalog import load_motion_file
    from sparse_body.data.motion_inputs import find_inputs

    subject = mocap_root / "asfamc" / "subjects" / "02"
    if not subject.is_dir():
        pytest.skip("the CMU ASF/AMC subject 02 is not in the indexed motion capture")
    shutil.copy(subject / "02.asf", tmp_path / "02.ASF")
    (tmp_path / "02_05.AMC").write_bytes(gzip.decompress((subject / "02_05.amc.gz").read_bytes()))
    assert [i.path for i in find_inputs([tmp_path])] == [tmp_path / "02_05.AMC"]
    motion = load_motion_file(tmp_path / "02_05.AMC", 60.0)
    assert len(motion) > 100 and np.all(np.isfinite(motion.positions))
    (tmp_path / "other.bvh").write_text(BVH)  # a layout we have no joint map for
    with pytest.raises(MotionFileError, match=r"other\.bvh: .*known layouts: cmu_asf, cmu_bvh_mb2"):
        load_motion_file(tmp_path / "other.bvh", 60.0)


def _long_bvh(path, frames: int, joints: int = 31) -> None:
    """A chain of `joints` joints (CMU's count) over `frames` frames of one row."""
    lines = ["HIERARCHY", "ROOT Hips", "{", "OFFSET 0 0 0"]
    lines.append("CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
    for j in range(1, joints):
        lines += [f"JOINT J{j}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * joints
    row = " ".join(f"{v:.6f}" for v in np.linspace(-10, 10, 6 + 3 * (joints - 1))) + "\n"
    lines += ["MOTION", f"Frames: {frames}", "Frame Time: 0.008333", row * frames]
    path.write_text("\n".join(lines))


def test_a_bvh_is_read_in_memory_of_the_order_of_its_arrays_and_refused_past_the_limit(tmp_path):
    """A 70 MB BVH once peaked at 1.63 GB (23 times its size: every number a Python string);
    at the 512 MiB file limit that was about 12 GB. The rule at a test's size (a 64 MiB limit):
    a file whose frames need more than the limit once read is refused before they are read,
    and one within it is read in memory of the order of the limit."""
    import subprocess
    import sys

    env = {"SPARSE_BODY_MAX_MOTION_MIB": "64"}
    # the peak of this process's own memory (VmHWM: getrusage's maxrss is inherited from the parent)
    script = (
        "import sys; from sparse_body.data import MotionFileError; from sparse_body.data.bvh import load_bvh\n"
        "peak = lambda: int(next(l for l in open('/proc/self/status') if l.startswith('VmHWM')).split()[1])\n"
        "before = peak()\n"
        "try:\n    m = load_bvh(sys.argv[1]); print('read', m.positions.shape[0])\n"
        "except MotionFileError as err:\n    print('refused', err)\n"
        "print((peak() - before) / 1024)\n"
    )
    import os

    results = {}
    for name, frames in (("within", 16_000), ("over", 60_000)):  # 16,000 frames (14 MB) need 58 MiB; 60,000 219
        path = tmp_path / f"{name}.bvh"
        _long_bvh(path, frames)
        out = subprocess.run(
            [sys.executable, "-c", script, str(path)],
            capture_output=True,
            text=True,
            env={**os.environ, **env},
            timeout=120,
            check=True,
        ).stdout.splitlines()
        results[name] = (out[0], float(out[-1]))
    assert results["within"][0] == "read 16000" and results["within"][1] < 2 * 64, results
    assert results["over"][0].startswith("refused") and "need 220 MiB once read" in results["over"][0], results
    assert "SPARSE_BODY_MAX_MOTION_MIB" in results["over"][0] and results["over"][1] < 20, results
