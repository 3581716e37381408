"""`python -m sparse_body.apps.fuzz TARGET RUNS`: coverage-guided fuzzing (atheris, libFuzzer) of
every parser that reads what a user or a device hands us.

Targets: serial (the tracker byte stream), vmc (one UDP datagram), tf (a /tf message as any
peer on the ROS domain can send it, through the ingest the live node and the bag reader
share), bvh (a motion file), asf_amc (a skeleton and its motion), yaml (a sensor configuration
and a calibration), robot (a robot's URDF and mapping YAML, and the URDF as the body's
robot_description from the network, then a retargeting of two poses). tf: half the inputs are
raw bytes, half a well-formed TFMessage of any doubles (NaN, infinities, 1e308, denormals) and
frame names, so both the reader and the guards are reached; a tracker sample must come out
finite or not at all. The corpus starts from well-formed input that libFuzzer then mutates.
serial: the input is split into reads of sizes taken from the input itself and fed to one
FrameDecoder, as a stream with garbage and torn frames. The file targets write the input to a
file and load it: the parser must return finite data or raise its own error type
(MotionFileError, SensorConfigError, CalibrationError) naming the file. Anything else
escaping, a bad decoded sample, or one input taking longer than the time limit (a hang) stops
the run with a crash report and a non-zero exit status; a clean run prints how many inputs it
executed.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import atheris
import numpy as np
import scipy.spatial.transform  # noqa: F401 - imported uninstrumented: coverage of our parsers, not of scipy
import yaml  # noqa: F401 - likewise

import sparse_body.core.kinematics  # noqa: F401 - numba's kernels uninstrumented: atheris's hooks break numba's typing

with atheris.instrument_imports():
    from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
    from pythonosc.osc_message_builder import OscMessageBuilder

    from sparse_body.adapters.serial_protocol import FrameDecoder, encode_frame
    from sparse_body.adapters.vmc import KINDS, VmcDecoder
    from sparse_body.core.calibration import Calibration, CalibrationError
    from sparse_body.core.sensors import SensorConfigError, load_sensor_config
    from sparse_body.data import MotionFileError
    from sparse_body.data.asf_amc import load_amc, load_asf
    from sparse_body.data.bvh import load_bvh
    from sparse_body.data.samples import TINY_AMC, TINY_ASF, TINY_BVH
    from sparse_body.io.cdr import MalformedMessage, read_tf, tf_messages
    from sparse_body.io.tf_cache import TfCache
    from sparse_body.io.urdf import body_skeleton
    from sparse_body.robot.example import MAPPING, urdf
    from sparse_body.robot.retarget import load_retarget
    from sparse_body.robot.urdf_model import RobotFileError


def _check(orientation, position) -> None:
    if not (np.all(np.isfinite(orientation)) and abs(np.linalg.norm(orientation) - 1) < 1e-6):
        raise AssertionError(f"decoded a bad orientation {orientation}")
    if position is not None and not np.all(np.isfinite(position)):
        raise AssertionError(f"decoded a bad position {position}")


_serial = FrameDecoder()
_vmc = VmcDecoder()


def serial_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    cuts = [fdp.ConsumeIntInRange(1, 64) for _ in range(fdp.ConsumeIntInRange(1, 4))]
    rest = fdp.ConsumeBytes(fdp.remaining_bytes())
    i = k = 0
    while i < len(rest):
        for frame in _serial.feed(rest[i : i + cuts[k % len(cuts)]]):
            _check(frame.orientation, frame.position)
        i, k = i + cuts[k % len(cuts)], k + 1


def vmc_input(data: bytes) -> None:
    for sample in _vmc.datagram(data, 0.0):
        _check(sample.orientation, sample.position)


_TF_CONFIG = None
_TF_FRAMES = ("hmd", "left_controller", "world", "other")


def tf_input(data: bytes) -> None:
    global _TF_CONFIG
    if _TF_CONFIG is None:
        _TF_CONFIG = load_sensor_config("four_point")
    fdp = atheris.FuzzedDataProvider(data)
    now = fdp.ConsumeFloat()
    if fdp.ConsumeBool():
        message = fdp.ConsumeBytes(fdp.remaining_bytes())
    else:
        count = fdp.ConsumeIntInRange(1, 4)
        pick = [fdp.ConsumeIntInRange(0, len(_TF_FRAMES)) for _ in range(2 * count)]
        names = [_TF_FRAMES[k] if k < len(_TF_FRAMES) else fdp.ConsumeUnicodeNoSurrogates(8) for k in pick]
        values = np.array([[fdp.ConsumeFloat() for _ in range(7)] for _ in range(count)])
        stamp = abs(fdp.ConsumeFloat()) % 4e9  # a stamp a Time can hold; its values are what is tried
        message = tf_messages([stamp], names[::2], names[1::2], values[None])[0]
    cache = TfCache([site.frame_id for site in _TF_CONFIG.sites])
    try:
        rows = read_tf(message)
    except MalformedMessage:
        return
    cache.ingest_rows(rows, False, now if np.isfinite(now) else None)
    frame, _ = cache.sample(_TF_CONFIG, cache.newest_tracker_stamp(), 0.1)
    if not (np.all(np.isfinite(frame.positions[frame.valid])) and np.all(np.isfinite(frame.orientations[frame.valid]))):
        raise AssertionError(f"a tracker sample that is not finite from {rows}")


_DIR = Path(tempfile.mkdtemp(prefix="sparse_body_fuzz_files_"))
_SPLIT = b"\n%%\n"  # asf_amc and yaml: two files in one input


def _file(name: str, data: bytes) -> Path:
    path = _DIR / name
    path.write_bytes(data)
    return path


def bvh_input(data: bytes) -> None:
    try:
        motion = load_bvh(_file("input.bvh", data))
    except MotionFileError as err:
        assert "input.bvh" in str(err), err
        return
    assert np.all(np.isfinite(motion.positions)) and motion.fps > 0


def asf_amc_input(data: bytes) -> None:
    asf, _, amc = data.partition(_SPLIT)
    try:
        motion = load_amc(_file("input.amc", amc), load_asf(_file("input.asf", asf)))
    except MotionFileError as err:
        assert "input.as" in str(err) or "input.amc" in str(err), err
        return
    assert np.all(np.isfinite(motion.positions))


def yaml_input(data: bytes) -> None:
    sensors, _, calibration = data.partition(_SPLIT)
    try:
        load_sensor_config(_file("sensors.yaml", sensors))
    except SensorConfigError as err:
        assert "sensors.yaml" in str(err), err
    try:
        Calibration.load(_file("calibration.yaml", calibration))
    except CalibrationError as err:
        assert "calibration.yaml" in str(err), err


_BODY = None


def robot_input(data: bytes) -> None:
    """A robot's URDF and mapping YAML as a user hands them (two files), and the URDF as the
    body's robot_description from the network: each is a RobotFileError naming its source or
    a robot whose poses, for a standing and a crouching body, are finite and within limits."""
    global _BODY
    from sparse_body.core.skeleton import Skeleton
    from sparse_body.core.types import BodyPose

    if _BODY is None:
        _BODY = Skeleton.canonical(1.75)
    text, _, mapping = data.partition(_SPLIT)
    try:
        body_skeleton(text.decode("utf-8", errors="replace"))
    except RobotFileError as err:
        assert "robot_description" in str(err), err
    try:
        robot = load_retarget(_file("robot.yaml", mapping), _file("robot.urdf", text), _BODY)
    except RobotFileError as err:
        assert "robot.yaml" in str(err) or "robot.urdf" in str(err), err
        return
    quats = np.zeros((22, 4))
    quats[:, 3] = 1.0
    for k, height in enumerate((0.95, 0.6)):
        pose = robot.step(BodyPose(k / 60, quats, np.array([0.0, 0.0, height]), contact=np.array([True, True])))
        q = pose.positions
        assert np.all(np.isfinite(q)) and np.all((q >= robot.lower) & (q <= robot.upper)), q
        assert np.all(np.isfinite(pose.base_position)) and np.all(np.isfinite(pose.base_quat)), pose


TARGETS = {
    "serial": serial_input,
    "vmc": vmc_input,
    "tf": tf_input,
    "bvh": bvh_input,
    "asf_amc": asf_amc_input,
    "yaml": yaml_input,
    "robot": robot_input,
}
TEXT_TARGETS = {"bvh", "asf_amc", "yaml", "robot"}


def text_seeds() -> list[bytes]:
    from sparse_body.core.resources import config_dir

    return [
        TINY_BVH.encode(),
        TINY_ASF.encode() + _SPLIT + TINY_AMC.encode(),
        (config_dir() / "sensors" / "four_point.yaml").read_bytes() + _SPLIT + _CALIBRATION,
        (config_dir() / "sensors" / "six_point.yaml").read_bytes() + _SPLIT + _calibration_with_body(),
        urdf().encode() + _SPLIT + MAPPING.format(urdf="robot.urdf").encode(),
    ]


_CALIBRATION = b"height: 1.7\nfacing_yaw: 0.1\noffsets:\n  head: [0, 0, 0, 1]\n"


def _calibration_with_body() -> bytes:
    """A calibration file with a fitted body, as the bridge writes it (its skeleton section)."""
    from sparse_body.core.calibration import Calibration
    from sparse_body.core.skeleton import Skeleton

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "calibration.yaml"
        Calibration(1.7, 0.1, {}, Skeleton.canonical(1.7)).save(path)
        return path.read_bytes()


def seeds() -> list[bytes]:
    out = [encode_frame(1, 1000, [0, 0, 0, 1]), encode_frame(2, 2**32 - 5, [0.5, 0.5, 0.5, 0.5], [1, 2, 3])]
    out.append(b"\x02\x01" + out[0] + b"\xa5\x5a\x01" + out[1])
    for address in KINDS:
        b = OscMessageBuilder(address)
        b.add_arg("LHR-1")
        for v in [0.1, 1.6, 0.2, 0.0, 0.0, 0.0, 1.0]:
            b.add_arg(v)
        out.append(b.build().dgram)
    trackers = np.tile([0.1, 0.2, 1.6, 0.0, 0.0, 0.0, 1.0], (1, 2, 1))
    out.append(tf_messages([1.7e9], ["world", "world"], ["hmd", "left_controller"], trackers)[0])
    bundle = OscBundleBuilder(IMMEDIATELY)
    bundle.add_content(OscMessageBuilder("/VMC/Ext/Hmd/Pos").build())
    out.append(bundle.build().dgram)
    return out


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv if argv is None else argv)
    if len(argv) < 3 or argv[1] not in TARGETS:
        sys.exit(f"usage: python -m sparse_body.apps.fuzz {{{','.join(TARGETS)}}} RUNS [libFuzzer flags]")
    target, runs = argv[1], int(argv[2])
    corpus = Path(tempfile.mkdtemp(prefix=f"sparse_body_fuzz_{target}_"))
    for i, seed in enumerate(text_seeds() if target in TEXT_TARGETS else seeds()):
        (corpus / f"seed{i}").write_bytes(seed)
    # -timeout: an input that takes seconds is a hang (a receiver thread stuck for good, a
    # loader that never returns)
    max_len = 16384 if target == "robot" else 4096 if target in TEXT_TARGETS else 512  # (a humanoid's URDF: 8 kB)
    atheris.Setup(
        [argv[0], f"-runs={runs}", f"-max_len={max_len}", "-timeout=10", *argv[3:], str(corpus)], TARGETS[target]
    )
    atheris.Fuzz()


if __name__ == "__main__":
    main()
