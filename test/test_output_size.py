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
