"""/tf poisoning: what any process on the ROS domain could send, and what the one TF ingest
(io/tf_cache.py, the live node's and the bag reader's) does with it. Each case was found to
break the input before the guards: one wrong frame cleared every tracker, a frame stamped 0
or two alternating stamps reset the estimator again and again, a long parent chain or a
flood of frames cost seconds and memory that was never freed, and absurd positions passed."""

from __future__ import annotations

import gc
import os
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from sparse_body.core.sensors import load_sensor_config
from sparse_body.io.tf_cache import Accepted, TfCache, TfGuards

CONFIG = load_sensor_config("four_point")
TRACKERS = [s.frame_id for s in CONFIG.sites]
T0 = 1_700_000_000.0
RATE = 60.0


def tf(parent: str, child: str, stamp: float, xyz=(0.0, 0.0, 1.0), q=(0.0, 0.0, 0.0, 1.0)):
    """A TransformStamped's fields, as rclpy's and rosbags' messages both have them."""
    sec = int(np.floor(stamp))
    return SimpleNamespace(
        header=SimpleNamespace(
            frame_id=parent, stamp=SimpleNamespace(sec=sec, nanosec=int(round((stamp - sec) * 1e9)))
        ),
        child_frame_id=child,
        transform=SimpleNamespace(
            translation=SimpleNamespace(x=xyz[0], y=xyz[1], z=xyz[2]),
            rotation=SimpleNamespace(x=q[0], y=q[1], z=q[2], w=q[3]),
        ),
    )


def trackers_at(stamp: float, skip=()) -> list:
    return [tf("world", f, stamp, (0.1 * i, 0.0, 1.0)) for i, f in enumerate(TRACKERS) if f not in skip]


def run(extra, frames: int = 300, clock: bool = True, guards: TfGuards | None = None):
    """Feed `frames` messages of the four trackers at 60 Hz, with extra(i, stamp) -> messages
    sent after message i; return (cache, valid per frame and tracker, input restarts)."""
    cache = TfCache(TRACKERS, guards)
    valid, restarts = [], 0
    for i in range(frames):
        stamp = T0 + i / RATE
        for msg in [trackers_at(stamp)] + extra(i, stamp):
            cache.ingest(msg, now=stamp + 0.005 if clock else None)
        restarts += cache.jumped_back
        cache.jumped_back = False
        frame, _ = cache.sample(CONFIG, cache.newest_tracker_stamp(), 0.1)
        valid.append(frame.valid.copy())
    return cache, np.array(valid), restarts


def test_plain_input_is_valid_in_every_frame():
    _, valid, restarts = run(lambda i, s: [])
    assert valid.all() and restarts == 0


def test_one_unrelated_frame_going_back_clears_nothing():
    # an unrelated frame whose stamp goes back 5 s half-way (it cleared every tracker before)
    cache, valid, restarts = run(lambda i, s: [[tf("world", "other", s - (5.0 if i >= 150 else 0.0))]])
    assert valid.all() and restarts == 0


@pytest.mark.parametrize("clock", [True, False])
def test_a_head_stamped_0_at_10_hz_never_restarts_the_input(clock):
    head = CONFIG.sites[0].frame_id
    cache, valid, restarts = run(lambda i, s: [[tf("world", head, 0.0)]] if i % 6 == 0 else [], clock=clock)
    assert restarts == 0
    if clock:  # judged by the clock: refused and counted, so the head stays valid
        assert valid.all() and cache.refused[Accepted.FAR_FROM_CLOCK] == 50
    else:  # no clock: the head alone starts again and is stale until its next sample
        assert valid[:, 1:].all() and valid[:, 0].mean() > 0.8


def test_a_frame_oscillating_between_two_stamps_restarts_only_itself():
    head = CONFIG.sites[0].frame_id
    cache, valid, restarts = run(lambda i, s: [[tf("world", head, s - 3.0)]] if i % 2 else [])
    assert restarts == 0 and valid[:, 1:].all()
    assert valid[::2, 0].all()  # fresh again after each good sample


def test_a_looping_bag_restarts_the_input_once_and_drops_a_tracker_left_behind():
    cache = TfCache(TRACKERS)
    for i in range(120):
        cache.ingest(trackers_at(T0 + i / RATE), now=None)
    cache.ingest(trackers_at(T0 + 1.5, skip=TRACKERS[:3]))  # the pelvis alone, then it stops
    assert not cache.jumped_back
    cache.ingest(trackers_at(T0, skip=TRACKERS[3:]))  # the bag starts over, without the pelvis
    assert cache.jumped_back and cache.stamp(TRACKERS[3]) == -np.inf  # not taken as fresh
    frame, _ = cache.sample(CONFIG, cache.newest_tracker_stamp(), 0.1)
    assert list(frame.valid) == [True, True, True, False]


def test_a_2000_frame_parent_chain_is_cut_at_max_depth_and_costs_little():
    head = CONFIG.sites[0].frame_id

    def chain(stamp: float) -> list:
        links = [tf(f"link{k - 1}" if k else "world", f"link{k}", stamp) for k in range(2000)]
        return [*links, tf("link1999", head, stamp)]

    start = time.process_time()
    cache, valid, restarts = run(lambda i, s: [chain(s)] if i % 6 == 0 else [])
    # the head's own world samples keep coming; whenever the chain names its parent it is cut
    assert cache.refused[Accepted.TOO_DEEP] > 0 and valid[:, 1:].all()
    kept = len(cache._edges) + len(cache._others)
    assert kept <= len(TRACKERS) * (TfGuards.max_depth + 1) + TfGuards.other_frames
    assert time.process_time() - start < 60  # 50 messages of 2000 transforms and 300 samples


def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.skipif(not Path("/proc/self/statm").exists(), reason="needs /proc (Linux) to read the resident memory")
def test_a_flood_of_100000_frames_in_messages_of_20000_keeps_memory_bounded():
    cache = TfCache(TRACKERS)
    cache.ingest(trackers_at(T0), now=T0)
    floods = [[tf("world", f"spam{m}_{k}", T0, (float(k), 0.0, 0.0)) for k in range(20_000)] for m in range(5)]
    gc.collect()
    before = _rss()
    for flood in floods:  # the messages stay alive: only what the cache keeps can grow
        cache.ingest(flood, now=T0)
    gc.collect()
    grown = _rss() - before
    # kept: the trackers and the newest 256 others (the unguarded cache kept all 100,000: +40 MB)
    assert len(cache._edges) == len(TRACKERS) and len(cache._others) == TfGuards.other_frames
    assert grown < 4_000_000, grown
    assert cache.sample(CONFIG, T0, 0.1)[0].valid.all()


def test_reparenting_a_tracker_again_and_again_keeps_memory_bounded():
    cache = TfCache(TRACKERS)
    head = TRACKERS[0]
    for k in range(5000):
        cache.ingest([tf(f"parent{k}", head, T0 + k / RATE), tf("world", f"parent{k}", T0 + k / RATE)], now=None)
    assert len(cache._depth) <= len(TRACKERS) * (TfGuards.max_depth + 1)
    assert cache.lookup("world", head) is not None  # the current chain still resolves


@pytest.mark.parametrize("position", [(1e20, 0.0, 0.0), (0.0, 1e6, 0.0), (60.0, 60.0, 60.0)])
def test_a_tracker_outside_the_play_space_is_refused_and_counted(position):
    cache = TfCache(TRACKERS)
    cache.ingest([*trackers_at(T0, skip=TRACKERS[:1]), tf("world", TRACKERS[0], T0, position)], now=T0)
    frame, _ = cache.sample(CONFIG, T0, 0.1)
    assert list(frame.valid) == [False, True, True, True] and cache.refused[Accepted.OUT_OF_PLAY_SPACE] == 1
    wide = TfCache(TRACKERS, TfGuards(play_radius=1e21))
    wide.ingest([tf("world", TRACKERS[0], T0, position)], now=T0)
    assert wide.sample(CONFIG, T0, 0.1)[0].valid[0]


@pytest.mark.parametrize(
    "xyz, q",
    [
        ((0.0, 0.0, 1.0), (2e154, 0.0, 0.0, 1.0)),  # its square overflowed: OverflowError stopped the node
        ((1e300, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0)),
        ((0.0, 0.0, 1.0), (1e-320, 0.0, 0.0, 1e-320)),  # denormals: a degenerate quaternion
        ((0.0, 0.0, 1.0), (-1.7e308, 1.7e308, 0.0, 1.0)),
    ],
)
@pytest.mark.parametrize("child", ["someone_elses_frame", TRACKERS[0]])
def test_absurd_values_are_refused_and_counted_never_raised(xyz, q, child):
    cache = TfCache(TRACKERS)
    cache.ingest([*trackers_at(T0)], now=T0)
    result = cache.ingest([tf("world", child, T0 + 0.01, xyz, q)], now=T0 + 0.01)
    assert sum(cache.refused.values()) == 1
    assert cache.refused[Accepted.NON_FINITE] + cache.refused[Accepted.BAD_QUATERNION] == 1
    frame, _ = cache.sample(CONFIG, T0 + 0.01, 0.1)
    assert frame.valid.all() and np.isfinite(frame.positions).all()  # the earlier sample still holds
    assert result.refused == ({child} if child in TRACKERS else set())


def test_a_stamp_ahead_of_the_clock_is_refused_unless_the_clock_is_not_judged():
    head = TRACKERS[0]
    cache = TfCache(TRACKERS)
    cache.ingest(trackers_at(T0), now=T0)
    cache.ingest([tf("world", head, T0 + 9.0)], now=T0 + 0.01)  # a headset 9 s ahead
    assert cache.refused[Accepted.AHEAD_OF_CLOCK] == 1 and cache.newest_tracker_stamp() == T0
    cache.ingest([tf("world", head, T0 + 0.3)], now=T0 + 0.01)  # within the window: a clock a little ahead
    assert cache.refused[Accepted.AHEAD_OF_CLOCK] == 1 and cache.newest_tracker_stamp() == T0 + 0.3
    unjudged = TfCache(TRACKERS, TfGuards(clock_window=0.0))  # simulated time: no clock check at all
    unjudged.ingest([tf("world", head, T0 + 9.0)], now=T0)
    assert unjudged.newest_tracker_stamp() == T0 + 9.0


def test_a_bag_with_poisoned_tf_gives_valid_estimates_offline(tmp_path):
    """The same ingest offline: `process` on a bag with an unrelated frame going back, a head
    stamped 0 at 10 Hz and a far-away frame; the bag's receive times are the clock."""
    from sparse_body.apps.offline import process_bag
    from sparse_body.data.synthetic import synthetic_walk
    from sparse_body.data.virtual_trackers import synthesize_trackers
    from sparse_body.io.bagio import TF_TOPIC, TF_TYPE, _transform_msg, bag_writer, typestore

    motion = synthetic_walk(5.0)
    stream = synthesize_trackers(motion, CONFIG)
    store = typestore()
    with bag_writer(tmp_path / "poisoned") as writer:
        conn = writer.add_connection(TF_TOPIC, TF_TYPE, typestore=store)
        for i in range(len(stream)):
            t = T0 + float(stream.times[i])
            msgs = [
                [
                    _transform_msg(store, t, "world", site.frame_id, stream.positions[i, s], stream.orientations[i, s])
                    for s, site in enumerate(CONFIG.sites)
                ],
                [
                    _transform_msg(
                        store, t - (5.0 if i > len(stream) // 2 else 0.0), "world", "other", np.zeros(3), [0, 0, 0, 1.0]
                    )
                ],
            ]
            if i % 6 == 3:
                msgs.append(
                    [_transform_msg(store, 0.0, "world", CONFIG.sites[0].frame_id, np.zeros(3), [0, 0, 0, 1.0])]
                )
            if i == 10:  # one value whose square overflows (it refused the whole bag)
                msgs.append([_transform_msg(store, t, "world", "other", np.zeros(3), [2e154, 0, 0, 1.0])])
            for k, transforms in enumerate(msgs):
                data = store.serialize_cdr(store.types[TF_TYPE](transforms=transforms), TF_TYPE)
                writer.write(conn, int(t * 1e9) + k, data)
    refused: dict[str, int] = {}
    poses = process_bag(
        tmp_path / "poisoned",
        tmp_path / "out",
        "ik",
        CONFIG,
        motion.skeleton,
        progress=False,
        refused=refused,
        keep_poses=True,
    ).poses
    assert len(poses) == len(stream) + len(range(3, len(stream), 6))  # the head-at-0 messages are input frames too
    assert sum(p.valid for p in poses) >= len(stream)  # every real frame valid
    assert refused["stamp far from the clock"] == len(range(3, len(stream), 6))
    assert refused["non-finite or absurd value"] == 1
