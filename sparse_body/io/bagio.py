"""rosbag2 files without ROS (rosbags): tracker TF in, estimates out.

Bags use the message definitions of Humble and later (sensor_msgs/JointState,
tf2_msgs/TFMessage) plus this package's msg/ files, registered from their text, so
`ros2 bag play` on a ROS machine plays them to the nodes.
"""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
from collections.abc import Generator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import yaml
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, ReaderError, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from .. import __version__
from ..core.file_output import OutputError as FileOutputError
from ..core.resources import share_dir
from ..core.sensors import SensorConfig
from ..core.textfile import load_yaml, read_limited
from ..core.types import TrackerStream
from . import cdr
from .output import (
    stamp_parts,
)
from .tf_cache import TfCache, TfGuards
from .topics import (  # noqa: F401 (the names callers import from here)
    COMPRESSIONS,
    CONTACTS_TOPIC,
    DESCRIPTION_TOPIC,
    ESTIMATE_TOPICS,
    JOINT_STATES_TOPIC,
    STATUS_TOPIC,
    TF_STATIC_TOPIC,
    TF_TOPIC,
)

TF_TYPE = "tf2_msgs/msg/TFMessage"


class BagError(ValueError):
    """A bag that cannot be read or written; the message names it and the problem."""


class OutputError(BagError, FileOutputError):
    """An output path refused: it would replace an input, a user's file, folder or device."""


def typestore():
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    for path in sorted((share_dir() / "msg").glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"sparse_body/msg/{path.stem}"))
    store.register(types)
    return store


def _time(store, seconds: float):
    sec, nanosec = stamp_parts(seconds)
    return store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _header(store, seconds: float, frame_id: str):
    return store.types["std_msgs/msg/Header"](stamp=_time(store, seconds), frame_id=frame_id)


def _transform_msg(store, seconds, parent, child, translation, rotation):
    T = store.types
    return T["geometry_msgs/msg/TransformStamped"](
        header=_header(store, seconds, parent),
        child_frame_id=child,
        transform=T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](*map(float, translation)),
            rotation=T["geometry_msgs/msg/Quaternion"](*map(float, rotation)),
        ),
    )


def log_times(stamps, last: int = -1) -> list[int]:
    """Bag (receive) times in ns: the stamps, kept increasing from `last` (the time written
    before them, for a recording written in chunks). Readers return messages in this order,
    so a header clock that jumps back must not reorder the recording."""
    out = []
    for t in stamps:
        last = max(last + 1, int(round(t * 1e9)))
        out.append(last)
    return out


def check_compression(compression: str) -> None:
    """ValueError naming the choices for a compression an output bag cannot have."""
    if compression not in COMPRESSIONS:
        raise ValueError(f"compression {compression!r}: one of {', '.join(COMPRESSIONS)}")


# The key this package writes into every bag's metadata.yaml (custom_data): an existing path
# is replaced only when it carries it, so --overwrite can never remove what a user owns.
WRITER_KEY = "sparse_body.writer"


def written_by_us(path: Path) -> bool:
    """Whether `path` is a bag directory this package wrote: a real directory (not a link)
    holding metadata.yaml with our custom_data key, and nothing but the files it lists."""
    path = Path(path)
    meta = path / "metadata.yaml"
    if path.is_symlink() or not path.is_dir() or meta.is_symlink() or not meta.is_file():
        return False
    try:
        info = load_yaml(read_limited(meta, "yaml"))["rosbag2_bagfile_information"]
        ours = WRITER_KEY in (info.get("custom_data") or {})
        listed = {"metadata.yaml", *(str(f) for f in info.get("relative_file_paths") or [])}
    except (OSError, ValueError, yaml.YAMLError, KeyError, TypeError, AttributeError, RecursionError):
        return False
    present = {entry.name for entry in path.iterdir()}
    return ours and present <= listed and all((path / f).is_file() and not (path / f).is_symlink() for f in present)


# What an estimate bag was made with (estimator, options, sensors...: apps/offline.py's
# settings_record), so that a resumed batch run never mixes bags of other settings.
MADE_WITH_KEY = "sparse_body.made_with"


def made_with(path: Path) -> str:
    """The settings record of a bag of ours ("" for one written before it was recorded)."""
    try:
        info = load_yaml(read_limited(Path(path) / "metadata.yaml", "yaml"))["rosbag2_bagfile_information"]
        return str((info.get("custom_data") or {}).get(MADE_WITH_KEY, ""))
    except (OSError, ValueError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return ""


def joint_state_count(path: Path) -> int:
    """How many estimates a complete bag of ours holds, from its metadata (no message is read)."""
    try:
        with Reader(path) as reader:
            return sum(c.msgcount for c in reader.connections if c.topic == JOINT_STATES_TOPIC)
    except ReaderError as err:  # (not a ValueError)
        raise BagError(f"{path}: cannot be read ({err})") from None


def _same_or_inside(a: Path, b: Path) -> bool:
    a, b = a.resolve(), b.resolve()
    return a == b or b in a.parents or a in b.parents


def check_output(path: Path, overwrite: bool = False, inputs: tuple[Path, ...] = ()) -> Path:
    """Refuse, before any work, an output path that would destroy something: an input of the
    same command (or a folder holding one), anything existing unless --overwrite, and even
    with it anything but a bag this package wrote (a device, a plain file, another folder).
    The parent folder must exist."""
    path = Path(path)
    for given in inputs:
        if Path(given).exists() and _same_or_inside(Path(given), path):
            raise OutputError(f"{path}: is (or holds) the input {given}; choose another output")
    if path.exists() or path.is_symlink():
        if not written_by_us(path):
            kind = (
                "a link"
                if path.is_symlink()
                else "a folder that is not a bag written by sparse_body"
                if path.is_dir()
                else "a file"
                if path.is_file()
                else "a device or special file"
            )
            raise OutputError(f"{path}: exists and is {kind}; it is never replaced, choose another output")
        if not overwrite:
            raise OutputError(f"{path}: already exists (choose another name, or --overwrite to replace this bag)")
    parent = path.absolute().parent
    if not parent.is_dir():
        raise OutputError(f"{path}: {parent} is not an existing folder")
    # a folder we may not write in (read-only, another's, full) fails now, not after the work
    _probe_writable(parent, path.name)
    return path


# the signals the command line turns into exceptions (SIGINT, SIGTERM)
_INTERRUPTS = frozenset({signal.SIGINT, signal.SIGTERM})


@contextmanager
def interrupts_held():
    """SIGINT and SIGTERM wait until the block ends (then a signal held meanwhile is delivered):
    for two steps that must not be parted, such as making something and taking charge of it."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, _INTERRUPTS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def _probe_writable(parent: Path, name: str) -> None:
    """Make and remove an empty hidden folder in `parent` (OSError where we may not write).
    Ctrl-C and SIGTERM wait until it is gone: landing between the two, they left the probe
    behind in a user's folder (test_batch's Ctrl-C test, once on a loaded machine)."""
    with interrupts_held():
        os.rmdir(tempfile.mkdtemp(prefix=f".{name}.probe-", dir=parent))


def _partial(path: Path, pid: int | str) -> Path:
    """The hidden folder a bag is written in before it takes its name."""
    return path.with_name(f".{path.name}.partial-{pid}")


def remove_leftovers(path: Path) -> None:
    """What killed writers of `path` left (SIGKILL: bag_writer could not clean up): our hidden
    partial folders beside it holding nothing but the bag. Only while no writer of it runs."""
    for left in path.parent.glob(_partial(path, "*").name):
        if left.is_dir() and not left.is_symlink() and {p.name for p in left.iterdir()} <= {path.name}:
            shutil.rmtree(left, ignore_errors=True)


@contextmanager
def bag_folder(path: Path, overwrite: bool = False, inputs: tuple[Path, ...] = ()):
    """The path a bag is written at: a temporary name beside `path`, moved into place only
    when the block ends without an error (SIGINT and SIGTERM included: the command line turns
    both into exceptions), so an interrupted or failed write leaves nothing behind. `path` is
    checked by check_output before and again just before it is replaced. The writer may be in
    another process (apps/pipeline.py): this one owns the name."""
    path = check_output(path, overwrite, inputs)
    # the bag is made under its own name inside a hidden folder, so that its file is NAME.mcap
    partial = _partial(path, os.getpid())
    tmp = partial / path.name
    old = path.with_name(f".{path.name}.replaced-{os.getpid()}")
    shutil.rmtree(partial, ignore_errors=True)
    try:
        partial.mkdir()  # inside: an interrupt right after it must not leave the folder
        yield tmp
        check_output(path, overwrite, inputs)  # nothing else may have appeared meanwhile
        if path.exists():
            os.replace(path, old)  # a bag of ours: moved aside, removed once replaced
        os.replace(tmp, path)
    finally:
        shutil.rmtree(partial, ignore_errors=True)
        if old.is_dir() and written_by_us(old):
            shutil.rmtree(old, ignore_errors=True)


@contextmanager
def open_writer(tmp: Path, made_with: str = "", compression: str = "zstd"):
    """A rosbag2 (MCAP) Writer at bag_folder's temporary path, closed (its summary and
    metadata written) when the block ends. Its chunks are compressed with `compression`
    (COMPRESSIONS)."""
    check_compression(compression)
    writer = Writer(tmp, version=8, storage_plugin=StoragePlugin.MCAP)
    if compression != "none":
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)  # chunks, not the file
    with writer:
        if compression == "lz4":
            _chunks_in_lz4(writer)
        writer.set_custom_data(WRITER_KEY, f"sparse_body {__version__}")
        if made_with:
            writer.set_custom_data(MADE_WITH_KEY, made_with)
        yield writer


@contextmanager
def bag_writer(
    path: Path, overwrite: bool = False, inputs: tuple[Path, ...] = (), made_with: str = "", compression: str = "zstd"
):
    """open_writer in bag_folder: a bag that takes its name only once it is whole."""
    check_compression(compression)  # before any folder is made
    with bag_folder(path, overwrite, inputs) as tmp, open_writer(tmp, made_with, compression) as writer:
        yield writer


def _chunks_in_lz4(writer: Writer) -> None:
    """rosbags writes zstd chunks only; its MCAP storage takes another chunk compressor
    (lz4 frames, the MCAP format's other one, which rosbags and every MCAP reader read)."""
    import lz4.frame

    storage = getattr(writer, "storage", None)
    if storage is None or not hasattr(storage, "compressor") or not hasattr(storage, "compression"):
        raise BagError("this version of rosbags cannot write lz4 chunks; use --compression zstd or none")
    storage.compression, storage.compressor = "lz4", lz4.frame.compress


def write_tracker_bag(
    path: Path,
    stream: TrackerStream,
    config: SensorConfig,
    start: float = 1_700_000_000.0,
    overwrite: bool = False,
    inputs: tuple[Path, ...] = (),
) -> None:
    """One /tf message per frame with every valid tracker; dropped samples are left out."""
    if len(stream) == 0:
        raise BagError(f"{path}: no frames to write (an empty motion)")
    store = typestore()
    TFMessage = store.types[TF_TYPE]
    with bag_writer(path, overwrite, inputs) as writer:
        conn = writer.add_connection(TF_TOPIC, TF_TYPE, typestore=store)
        log_ns = log_times(start + np.asarray(stream.times, dtype=float))
        for i in range(len(stream)):
            t = start + float(stream.times[i])
            transforms = []
            for s, site in enumerate(config.sites):
                if not stream.valid[i, s]:
                    continue
                pos = stream.positions[i, s] if site.has_position else np.zeros(3)
                rot = stream.orientations[i, s] if site.has_orientation else np.array([0.0, 0.0, 0.0, 1.0])
                transforms.append(_transform_msg(store, t, config.fixed_frame, site.frame_id, pos, rot))
            data = store.serialize_cdr(TFMessage(transforms=transforms), TF_TYPE)
            writer.write(conn, log_ns[i], data)


def _tf_messages(path: Path):
    """Each /tf message of a bag as (seconds from the first message, its cdr.read_tf rows), read
    as they are wanted; BagError (one line) for a bag without /tf or one that cannot be read."""
    path = Path(path)
    try:
        with Reader(path) as reader:
            conns = [c for c in reader.connections if c.topic == TF_TOPIC]
            if not conns:
                raise BagError(f"{path}: no {TF_TOPIC} topic")
            first = None
            for _, log_ns, raw in reader.messages(connections=conns):
                first = log_ns if first is None else first
                yield (log_ns - first) * 1e-9, cdr.read_tf(raw)
    except BagError:
        raise
    except Exception as err:  # noqa: BLE001 - rosbags' and the decoder's errors: a bag we cannot read
        raise BagError(f"{path}: cannot be read as a rosbag2 ({err})") from None


def read_tf_messages(path: Path) -> list[tuple[float, list]]:
    """Every /tf message of a bag as (seconds from the first message, its transforms as
    cdr.read_tf rows (parent, child, stamp, (tx, ty, tz, qx, qy, qz, qw)))): what the tracker
    bridge replays, read as the live node and read_tracker_stream read /tf."""
    out = list(_tf_messages(path))
    if not out:  # a loop over nothing would spin a core
        raise BagError(f"{path}: no {TF_TOPIC} messages to play")
    return out


def tf_frames(path: Path, wanted: set[str] | None = None, seconds: float | None = None) -> set[str]:
    """The child frames /tf moves in a bag: all of them, or read until every frame of `wanted`
    was seen, or for the first `seconds` of the bag (whichever ends first)."""
    found: set[str] = set()
    messages = _tf_messages(path)
    for at, rows in messages:
        if seconds is not None and at > seconds:
            break
        found.update(child for _, child, _, _ in rows)
        if wanted is not None and wanted <= found:
            break
    messages.close()  # (the bag closed now, not when the generator is collected)
    return found


def read_tracker_stream(
    path: Path,
    config: SensorConfig,
    stale_after: float = 0.1,
    refused: dict | None = None,
    guards: TfGuards | None = None,
) -> TrackerStream:
    """The trackers at each input frame of a bag (tracker_chunks, whole)."""
    chunks = list(tracker_chunks(path, config, stale_after, refused, guards))
    return TrackerStream(
        config.site_names,
        np.concatenate([c.times for c in chunks]),
        np.concatenate([c.positions for c in chunks]),
        np.concatenate([c.orientations for c in chunks]),
        np.concatenate([c.valid for c in chunks]),
    )


CHUNK_FRAMES = 512  # frames a chunk of a streamed recording: 8.5 s at 60 Hz, 0.6 MB of poses and trackers


def tracker_frame_count(path: Path) -> int | None:
    """How many /tf messages a bag holds, from its metadata (an upper bound on its frames), or
    None where it does not say."""
    try:
        with Reader(Path(path)) as reader:
            return sum(c.msgcount for c in reader.connections if c.topic == TF_TOPIC) or None
    except Exception:  # noqa: BLE001 - reading it properly says what is wrong, later
        return None


def tracker_chunks(
    path: Path,
    config: SensorConfig,
    stale_after: float = 0.1,
    refused: dict | None = None,
    guards: TfGuards | None = None,
    size: int | None = None,
) -> Generator[TrackerStream, None, None]:
    """The trackers at each input frame of a bag, `size` (CHUNK_FRAMES) frames a chunk, read as they are
    needed (a recording of any length in bounded memory): every /tf message that moves a
    tracker frame is one frame, sampled at the newest tracker stamp held. The messages go
    through the same TfCache ingest as the live node's (read by io/cdr.py's read_tf, as the
    live node reads them), with the bag's receive time as the clock: a tracker whose sample in
    that message was refused is invalid in that frame, and every refusal is counted in
    `refused` (reason -> count) when a dict is given, once the bag is read."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such bag")
    cache = TfCache({s.frame_id for s in config.sites}, guards)
    times: list[float] = []
    frames: list = []
    last_stamp, count = None, 0
    size = size or CHUNK_FRAMES

    def chunk() -> TrackerStream:
        out = TrackerStream(
            config.site_names,
            np.array(times),
            np.stack([f.positions for f in frames]),
            np.stack([f.orientations for f in frames]),
            np.stack([f.valid for f in frames]),
        )
        times.clear()
        frames.clear()
        return out

    try:
        with Reader(path) as reader:
            conns = [c for c in reader.connections if c.topic in (TF_TOPIC, TF_STATIC_TOPIC)]
            if not any(c.topic == TF_TOPIC for c in conns):
                raise BagError(
                    f"{path}: no {TF_TOPIC} topic (topics: {', '.join(sorted({c.topic for c in reader.connections}))})"
                )
            for conn in conns:
                if conn.msgtype != TF_TYPE:
                    raise BagError(f"{path}: {conn.topic} holds {conn.msgtype}, not {TF_TYPE}")
            for conn, log_ns, raw in reader.messages(connections=conns):
                got = cache.ingest_rows(cdr.read_tf(raw), conn.topic == TF_STATIC_TOPIC, log_ns * 1e-9)
                cache.jumped_back = False  # the estimator starts over where the stamps go back (process)
                if not got.moved:
                    continue
                if np.isfinite(got.newest):  # the newest held (a tracker in another message may be newer)
                    stamp = cache.newest_tracker_stamp()
                else:  # every sample refused: the frame keeps its own stamp if it has one
                    stamp = got.refused_stamp if np.isfinite(got.refused_stamp) else (last_stamp or 0.0)
                frame, _ = cache.sample(config, stamp, stale_after)
                for s, site in enumerate(config.sites):
                    if site.frame_id in got.refused:
                        frame.valid[s] = False
                times.append(stamp)
                frames.append(frame)
                last_stamp, count = stamp, count + 1
                if len(frames) == size:
                    yield chunk()
    except BagError:
        raise
    except Exception as err:  # noqa: BLE001 - rosbags raises many kinds for a broken file
        raise BagError(f"{path}: cannot be read as a rosbag2 ({err})") from None
    if refused is not None:
        for reason, n in cache.refused.items():
            if n:
                refused[reason.value] = refused.get(reason.value, 0) + n
    if not count:
        raise BagError(f"{path}: no transforms of the tracker frames {', '.join(sorted(cache.trackers))}")
    if frames:
        yield chunk()


def read_topic(path: Path, topic: str) -> list:
    """Every message of a topic, deserialised (for tests and tools)."""
    store = typestore()
    with Reader(Path(path)) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [store.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages(connections=conns)]
