"""Output a lab can store (issue 55): estimate bags with MCAP chunk compression by default,
the same messages as without it, only the topics asked for, and the command saying what
bounds the run. A ten-minute six-point ik bag was 319 MB."""

import pytest
from rosbags.rosbag2 import Reader

from sparse_body.apps.offline import make_bag, process_bag
from sparse_body.cli import EXIT_USAGE, main
from sparse_body.core.sensors import load_sensor_config
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.io.bagio import CONTACTS_TOPIC, ESTIMATE_TOPICS, JOINT_STATES_TOPIC, made_with

SIX = load_sensor_config("six_point")


@pytest.fixture(scope="module")
def walk_bag(tmp_path_factory):
    folder = tmp_path_factory.mktemp("walk")
    make_bag(synthetic_walk(120.0), SIX, folder / "walk")
    return folder / "walk"


def messages(bag):
    """(topic, time, bytes) of each message as rosbags reads the bag, and the compressions of
    its chunks as the MCAP format's own reader reads them (with its messages, the same)."""
    from mcap.reader import make_reader

    with Reader(bag) as reader:
        read = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    (file,) = bag.glob("*.mcap")
    with open(file, "rb") as stream:
        mcap = make_reader(stream)
        chunks = {index.compression for index in mcap.get_summary().chunk_indexes}
        assert [(c.topic, m.log_time, m.data) for _, c, m in mcap.iter_messages(log_time_order=False)] == read
    return read, chunks


def size(bag) -> int:
    return sum(f.stat().st_size for f in bag.iterdir())


def test_compressed_bags_hold_the_same_messages_in_a_fraction_of_the_space(walk_bag, tmp_path):
    written = {}
    for compression in ("none", "zstd", "lz4"):
        out = tmp_path / compression
        process_bag(walk_bag, out, "ik", SIX, synthetic_walk(0.1).skeleton, progress=False, compression=compression)
        written[compression] = messages(out)
    assert written["zstd"][0] == written["none"][0] == written["lz4"][0]
    assert written["zstd"][1] == {"zstd"} and written["lz4"][1] == {"lz4"} and written["none"][1] == {""}
    # the default, measured on two minutes: a ten-minute bag within 40 MB (it was 319)
    default = tmp_path / "default"
    process_bag(walk_bag, default, "ik", SIX, synthetic_walk(0.1).skeleton, progress=False)
    assert messages(default)[1] == {"zstd"}
    assert size(default) * 5 < 40e6, size(default)
    assert size(default) < size(tmp_path / "lz4") < size(tmp_path / "none") / 2


def test_only_the_topics_asked_for_are_written_and_the_run_says_what_bounds_it(walk_bag, tmp_path, capsys):
    out = tmp_path / "joints"
    argv = ["process", str(walk_bag), str(out), "--topics", "joint_states,/foot_contacts", "--quiet"]
    with pytest.raises(SystemExit) as ended:
        main(argv)
    assert ended.value.code == 0
    said = capsys.readouterr().out
    assert "estimation" in said and "writing" in said and "frames/s" in said
    with Reader(out) as reader:
        assert {c.topic for c in reader.connections} == {JOINT_STATES_TOPIC, CONTACTS_TOPIC}
    assert '"topics"' in made_with(out)  # a resumed batch never mixes bags of other topics
    with pytest.raises(SystemExit) as ended:
        main(["process", str(walk_bag), str(tmp_path / "x"), "--topics", "/joint_states,/nope"])
    err = capsys.readouterr().err
    assert ended.value.code == EXIT_USAGE and err.count("\n") == 1 and "/nope" in err
    assert all(topic in err for topic in ESTIMATE_TOPICS)  # the choices are named
    assert not (tmp_path / "x").exists()


def test_chunks_read_and_written_beside_the_estimation_or_in_turn_give_the_bytes_of_one_whole_write(
    walk_bag, tmp_path, monkeypatch
):
    """Eight chunks of 1024 frames (and seven of 1000: the chunk size is no boundary of the
    result), forked reader and writer or all in this process: every message is the one that
    writing the whole recording at once makes."""
    from sparse_body.core.skeleton import Skeleton
    from sparse_body.io import bagio
    from sparse_body.io.bagio import read_tracker_stream
    from sparse_body.io.estimate_bag import write_estimate_bag

    body = Skeleton.canonical(1.75)
    whole = process_bag(walk_bag, tmp_path / "poses", "ik", SIX, body, progress=False, keep_poses=True).poses
    write_estimate_bag(
        tmp_path / "whole", whole, body, SIX.fixed_frame, trackers=(SIX, read_tracker_stream(walk_bag, SIX))
    )
    expected = messages(tmp_path / "whole")[0]
    for parallel, chunk in ((True, 1024), (False, 1024), (True, 1000)):
        monkeypatch.setattr(bagio, "CHUNK_FRAMES", chunk)
        out = tmp_path / f"{parallel}{chunk}"
        timings: dict = {}
        done = process_bag(walk_bag, out, "ik", SIX, body, progress=False, parallel=parallel, timings=timings)
        assert done.frames == len(whole) and done.poses is None  # none kept unless asked
        assert messages(out)[0] == expected, (parallel, chunk)
        assert timings["parallel"] == parallel and timings["read"] > 0 and timings["write"] > 0


def _hour_bag(path, walk_bag):
    """An hour of six-point trackers: the two-minute walk thirty times, one after the other
    (written in chunks, as fast as the estimate bag's encoder writes)."""
    import numpy as np

    from sparse_body.io import cdr
    from sparse_body.io.bagio import TF_TOPIC, TF_TYPE, bag_writer, read_tracker_stream, typestore
    from sparse_body.io.output import tracker_table

    walk = read_tracker_stream(walk_bag, SIX)
    span = walk.times[-1] - walk.times[0] + 1.0 / 60.0
    table = tracker_table(SIX, walk, np.arange(len(walk)), tuple(range(len(SIX.sites))))
    with bag_writer(path) as writer:
        conn = writer.add_connection(TF_TOPIC, TF_TYPE, typestore=typestore())
        for k in range(30):
            stamps = walk.times + k * span
            for t, data in zip(
                stamps, cdr.tf_messages(stamps, table.parents, table.children, table.values), strict=True
            ):
                writer.write(conn, int(round(t * 1e9)), data)
    return 30 * len(walk)


def _peak_rss_mb(argv) -> float:
    """The largest resident set of `sparse-body ARGV` and the processes it forks, in MB."""
    import subprocess
    import sys

    probe = (
        "import resource, subprocess, sys; "
        "code = subprocess.run(sys.argv[1:]).returncode; "
        "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024); sys.exit(code)"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe, sys.executable, "-m", "sparse_body.cli", *argv],
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return float(done.stdout.strip().splitlines()[-1])


def test_memory_stays_flat_over_an_hour_long_recording(walk_bag, tmp_path):
    """Memory does not grow with the recording: an hour takes no more than two minutes
    (before streaming, ten minutes took 666 MiB and an hour would have taken about 4 GB)."""
    from sparse_body.io.bagio import joint_state_count

    frames = _hour_bag(tmp_path / "hour", walk_bag)
    common = ["--estimator", "ik", "--play-radius", "1e6", "--quiet"]
    short = _peak_rss_mb(["process", str(walk_bag), str(tmp_path / "short_out"), *common])
    hour = _peak_rss_mb(["process", str(tmp_path / "hour"), str(tmp_path / "hour_out"), *common])
    print(f"peak RSS: {short:.0f} MB for two minutes, {hour:.0f} MB for an hour")
    assert joint_state_count(tmp_path / "hour_out") == frames == 216_000
    assert hour <= 1.2 * short + 20, f"peak RSS: {short:.0f} MB for two minutes, {hour:.0f} MB for an hour"
