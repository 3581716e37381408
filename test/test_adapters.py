"""Tracker adapters without ROS: the serial protocol over a real pseudo-terminal, device
clocks, VMC over real UDP with python-osc, T-pose calibration, and a short fuzzing run."""

import re
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sparse_body.adapters.device_clock import WRAP_US, DeviceClock
from sparse_body.adapters.serial_protocol import FrameDecoder, encode_frame
from sparse_body.adapters.vmc import VmcDecoder, VmcReceiver, map_device, parse_device_map, unity_to_rep103
from sparse_body.core.calibration import Calibration, CalibrationError, calibrate_tpose
from sparse_body.core.kinematics import forward_kinematics
from sparse_body.core.rotations import yaw_matrix
from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.core.skeleton import Skeleton


def _frames(n, rng):
    out = []
    for i in range(n):
        q = Rotation.random(random_state=rng).as_quat()
        pos = rng.normal(size=3) if i % 2 else None
        out.append((i % 5 + 1, 1000 * i, q, pos))
    return out


def test_serial_frames_survive_garbage_splits_and_bad_checksums(rng):
    sent = _frames(200, rng)
    stream, expected = bytearray(), []
    for k, (dev, t, q, pos) in enumerate(sent):
        frame = bytearray(encode_frame(dev, t, q, pos))
        if k % 7 == 3:
            frame[-5] ^= 0x40  # a corrupted payload: the checksum fails
        else:
            expected.append((dev, t))
        if k % 5 == 1:
            stream += bytes(rng.integers(0, 256, 23, dtype=np.uint8))  # line noise
        if k % 11 == 0:
            stream += b"\xa5\x5a\x01"  # a torn frame: sync and a bit of header
        stream += frame
    decoder = FrameDecoder()
    got = []
    i = 0
    while i < len(stream):  # reads of 1..17 bytes
        n = int(rng.integers(1, 18))
        got += decoder.feed(bytes(stream[i : i + n]))
        i += n
    assert [(f.device_id, f.device_time_us) for f in got] == expected
    assert decoder.stats.bad_checksums == len(sent) - len(expected)
    assert decoder.stats.garbage_bytes > 0
    by_time = {t: (q, pos) for _, t, q, pos in sent}
    for f in got:
        q, pos = by_time[f.device_time_us]
        assert abs(abs(np.dot(f.orientation, q)) - 1) < 1e-6  # float32 on the wire
        assert (f.position is None) == (pos is None)


def test_serial_frames_with_impossible_values_are_dropped_and_counted():
    decoder = FrameDecoder()
    out = decoder.feed(
        encode_frame(1, 0, [0, 0, 0, 0])
        + encode_frame(1, 1, [np.nan, 0, 0, 1])
        + encode_frame(1, 2, [0, 0, 0, 1], [np.inf, 0, 0])
        + encode_frame(1, 3, [0, 0, 0, 2])
    )
    assert out == [] and decoder.stats.bad_values == 4


def test_device_clock_follows_drift_unwraps_and_survives_a_restart(rng):
    clock = DeviceClock(window=2.0)
    errors = []
    start_us = WRAP_US - 3_000_000  # wraps 3 s in
    for i in range(2000):  # 10 s at 200 Hz
        true_host = 1000.0 + i / 200
        device_s = (true_host - 1000.0) * (1 + 200e-6)  # the device clock runs 200 ppm fast
        raw = (start_us + int(device_s * 1e6)) % WRAP_US
        arrival = true_host + 0.002 + abs(rng.normal(0, 0.003))  # transport delay >= 2 ms
        errors.append(clock.to_host(raw, arrival) - true_host)
    errors = np.abs(np.array(errors[400:]))
    assert errors.max() < 0.006 and np.median(errors) < 0.004
    assert clock.restarts == 0
    # the device restarts: its counter starts again from zero
    stamp = clock.to_host(5000, 1011.0)
    assert clock.restarts == 1 and abs(stamp - 1011.0) < 1e-6


def test_serial_reader_reads_a_pseudo_terminal_and_reconnects(tmp_path):
    """The reference sender process writes through a pty at 200 Hz, with garbage, split
    frames and bad checksums, and is unplugged for a second half way."""
    from sparse_body.adapters.serial_reader import SerialTrackerReader

    link = tmp_path / "ttyTRACKERS"
    sender = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "sparse_body.apps.serial_sender",
            "--pty",
            str(link),
            "--rate",
            "200",
            "--seconds",
            "4",
            "--garbage",
            "0.05",
            "--bad-crc",
            "0.02",
            "--split",
            "--disconnect-at",
            "1.5",
            "--offline",
            "1.0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    got, lock = [], threading.Lock()

    def keep(samples):
        with lock:
            got.extend((time.time(), s) for s in samples)

    deadline = time.monotonic() + 120  # a starved machine starts the sender slowly
    while not link.exists() and time.monotonic() < deadline:
        time.sleep(0.02)
    reader = SerialTrackerReader(str(link), keep, reconnect_interval=0.1)
    try:
        out, _ = sender.communicate(timeout=300)
        time.sleep(0.2)
    finally:
        reader.close()
    assert "reconnected" in out, out
    assert reader.connects >= 2 and reader.disconnects >= 1
    stats = reader.decoder.stats
    assert stats.bad_checksums > 0 and stats.garbage_bytes > 0
    devices = {s.device for _, s in got}
    assert devices == {"serial:1", "serial:2", "serial:3", "serial:4"}
    # every device is heard before the unplugging and again after it (how many samples a
    # starved sender manages to write is not the reader's business)
    arrival = np.array([t for t, _ in got])
    before = {s.device for t, s in got if t < arrival[0] + 1.0}
    after = {s.device for t, s in got if t > arrival[-1] - 1.0}
    assert before == after == devices and arrival[-1] - arrival[0] > 1.5
    lag = np.array([t - s.stamp for t, s in got])
    # device time mapped onto host time (unmapped it would be off by the device's epoch); a
    # starved reader takes samples late, which only the bench measures
    assert np.all(lag > -0.005) and np.median(lag) < 0.5
    assert all(s.position is not None for _, s in got)


def test_unity_to_rep103_is_the_axis_change(rng):
    M = np.array([[0, 0, 1], [-1, 0, 0], [0, 1, 0]])
    for _ in range(20):
        q = Rotation.random(random_state=rng).as_quat()
        p = rng.normal(size=3)
        pr, qr = unity_to_rep103(p, q)
        np.testing.assert_allclose(pr, M @ p)
        np.testing.assert_allclose(
            Rotation.from_quat(qr).as_matrix(), M @ Rotation.from_quat(q).as_matrix() @ M.T, atol=1e-12
        )
    # Unity's up (y) is REP-103's z, Unity's forward (z) is x
    np.testing.assert_allclose(unity_to_rep103([0, 1.7, 0], [0, 0, 0, 1])[0], [0, 0, 1.7])
    np.testing.assert_allclose(unity_to_rep103([0, 0, 2.0], [0, 0, 0, 1])[0], [2.0, 0, 0])


def test_vmc_over_udp_with_python_osc():
    from pythonosc.udp_client import SimpleUDPClient

    got = []
    receiver = VmcReceiver(got.extend, "127.0.0.1", 0)
    try:
        client = SimpleUDPClient(*receiver.address)
        client.send_message("/VMC/Ext/Hmd/Pos", ["HMD", 0.1, 1.6, 0.3, 0.0, 0.0, 0.0, 1.0])
        client.send_message("/VMC/Ext/Con/Pos", ["LHR-AAAA", -0.2, 1.2, 0.1, 0.0, 0.7071068, 0.0, 0.7071068])
        client.send_message("/VMC/Ext/Tra/Pos", ["tracker", 1.0])  # too few arguments
        client.send_message("/VMC/Ext/Tra/Pos", ["t2", 0, 0, 0, 0, 0, 0, 0])  # zero quaternion
        client.send_message("/VMC/Ext/Bone/Pos", ["Hips", 0, 0, 0, 0, 0, 0, 1])  # not ours
        client._sock.sendto(b"\x00garbage", receiver.address)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and sum(receiver.decoder.errors.values()) < 3:
            time.sleep(0.01)
    finally:
        receiver.close()
    assert [s.device for s in got] == ["hmd:HMD", "con:LHR-AAAA"]
    np.testing.assert_allclose(got[0].position, [0.3, -0.1, 1.6], atol=1e-6)
    assert receiver.decoder.errors == {"bad arguments": 1, "not a pose": 1, "not OSC": 1}
    # a quarter turn about Unity's up is a quarter turn about REP-103's z, the other way round
    np.testing.assert_allclose(Rotation.from_quat(got[1].orientation).as_rotvec(), [0, 0, -np.pi / 2], atol=1e-6)


def test_device_map():
    device_map = parse_device_map(["hmd:*=head", "con:LHR-A*=left_hand", "con:*=right_hand"])
    assert map_device("hmd:x", device_map) == "head"
    assert map_device("con:LHR-AB", device_map) == "left_hand"
    assert map_device("con:LHR-B", device_map) == "right_hand"
    assert map_device("tra:1", device_map) is None
    with pytest.raises(ValueError, match="unknown body site 'tail'"):
        parse_device_map(["tra:*=tail"])
    with pytest.raises(ValueError, match="PATTERN=SITE"):
        parse_device_map(["head"])


def _tpose_samples(height, yaw, mounts, rng, noise=0.0):
    skeleton = Skeleton.canonical(height)
    local = np.tile(np.eye(3), (22, 1, 1))
    local[0] = yaw_matrix(yaw)
    glob, pos = forward_kinematics(local, [0.3, -0.2, -skeleton.rest_positions()[:, 2].min()], skeleton.offsets)
    joints = {"head": J["head"], "left_hand": J["left_wrist"], "right_hand": J["right_wrist"], "pelvis": J["pelvis"]}
    samples = {}
    for site, mount in mounts.items():
        j = joints[site]
        samples[site] = [
            (
                pos[j] + rng.normal(0, noise, 3),
                (Rotation.from_rotvec(rng.normal(0, noise, 3)) * Rotation.from_matrix(glob[j]) * mount).as_quat(),
            )
            for _ in range(60)
        ]
    return samples


def test_tpose_calibration_recovers_mounting_and_height(rng, tmp_path):
    mounts = {
        "head": Rotation.from_euler("y", 0.3),
        "left_hand": Rotation.from_euler("xz", [1.2, 0.4]),
        "right_hand": Rotation.from_euler("x", -1.0),
        "pelvis": Rotation.from_euler("z", 2.0),
    }
    samples = _tpose_samples(1.62, 2.5, mounts, rng, noise=0.005)
    cal = calibrate_tpose(samples)
    assert abs(cal.height - 1.62) < 0.02
    assert abs(np.angle(np.exp(1j * (cal.facing_yaw - 2.5)))) < 0.02
    for site, mount in mounts.items():
        assert (Rotation.from_quat(cal.offsets[site]) * mount.inv()).magnitude() < 0.02, site
    # applied, a tracker's orientation becomes its joint's: facing yaw for every joint in a T-pose
    q = cal.apply("left_hand", samples["left_hand"][0][1])
    assert (Rotation.from_quat(q) * Rotation.from_matrix(yaw_matrix(2.5)).inv()).magnitude() < 0.03
    cal.save(tmp_path / "cal.yaml")
    back = Calibration.load(tmp_path / "cal.yaml")
    assert back.height == pytest.approx(cal.height, abs=1e-4) and set(back.offsets) == set(cal.offsets)


def test_calibration_refuses_what_is_not_a_tpose(rng, tmp_path):
    samples = _tpose_samples(
        1.75,
        0.0,
        {"head": Rotation.identity(), "left_hand": Rotation.identity(), "right_hand": Rotation.identity()},
        rng,
    )
    samples["left_hand"] = [(samples["right_hand"][0][0] + [0, 0.1, 0], q) for _, q in samples["left_hand"]]
    with pytest.raises(CalibrationError, match="not a T-pose"):
        calibrate_tpose(samples)
    with pytest.raises(CalibrationError, match="no tracker samples"):
        calibrate_tpose({})
    (tmp_path / "bad.yaml").write_text("height: 1.7\noffsets:\n  left_hand: [0, 0, 0, 3]\n")
    with pytest.raises(CalibrationError, match="bad.yaml.*left_hand"):
        Calibration.load(tmp_path / "bad.yaml")
    (tmp_path / "worse.yaml").write_text("height: [\n")
    with pytest.raises(CalibrationError, match="worse.yaml: not valid YAML"):
        Calibration.load(tmp_path / "worse.yaml")


@pytest.mark.parametrize(
    "target,runs",
    [
        ("serial", 20000),
        ("vmc", 20000),
        ("tf", 20000),
        ("bvh", 3000),
        ("asf_amc", 3000),
        ("yaml", 3000),
        ("robot", 2000),
    ],
)
def test_a_short_fuzzing_run_finds_nothing(target, runs):
    """The full run (a million inputs each) is `make fuzz`; this keeps the harness working."""
    pytest.importorskip("atheris")
    out = subprocess.run(
        [sys.executable, "-m", "sparse_body.apps.fuzz", target, str(runs)], capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr[-3000:]
    # libFuzzer may run a few inputs more than asked (a clean CI run printed "Done 3010 runs")
    done = re.search(r"Done (\d+) runs", out.stderr)
    assert done and int(done.group(1)) >= runs, out.stderr[-3000:]


def test_a_bundle_with_a_negative_element_size_does_not_hang_the_decoder():
    """Found by the fuzzer: python-osc 1.10 loops forever on this datagram."""
    datagram = b"#bundle\x00" + b"\x00" * 4 + b"\xff\xff\xff\xe7" + b"\xff" * 52 + b"\x00" * 4
    decoder = VmcDecoder()
    done = threading.Event()
    worker = threading.Thread(target=lambda: (decoder.datagram(datagram, 0.0), done.set()), daemon=True)
    worker.start()
    assert done.wait(5.0), "the decoder hangs"
    assert decoder.errors["not OSC"] == 1


def test_orientation_only_foot_imus_turn_the_ankles_and_invent_no_position():
    from sparse_body.core.rotations import quat_to_matrix
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.data.synthetic import synthetic_walk
    from sparse_body.data.virtual_trackers import synthesize_trackers
    from sparse_body.methods.factory import create_estimator

    config = load_sensor_config("four_point_foot_imus")
    motion = synthetic_walk(2.0)
    stream = synthesize_trackers(motion, config)
    feet = [config.site_names.index(s) for s in ("left_foot", "right_foot")]
    assert np.isnan(stream.positions[:, feet]).all() and np.isfinite(stream.orientations[:, feet]).all()
    est = create_estimator("ik", config, motion.skeleton, filter=False)  # exact input, exact ankles
    assert est.joint_target(stream.frame(0), "left_foot")[0] is None
    poses = est.process(stream)
    assert all(p.valid and p.is_finite() for p in poses)
    for t in (10, 60, 110):
        local = quat_to_matrix(poses[t].local_quats)
        glob, _ = forward_kinematics(local, poses[t].root_position, motion.skeleton.offsets)
        for joint in ("left_ankle", "right_ankle"):
            np.testing.assert_allclose(glob[J[joint]], motion.global_rotations[t, J[joint]], atol=1e-6)
