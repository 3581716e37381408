"""The reading and writing ends of `sparse-body process`, beside the estimation (issue 55).

A recording flows in chunks of frames (bagio.CHUNK_FRAMES): the tracker bag is read a chunk at
a time, the estimator steps through it, and each chunk's poses are encoded and written before
the next is read, so memory stays flat however long the recording. Where this process may fork
(Linux, and no other thread running: a thread holding a lock at the fork would leave it held
in the child), the reader and the writer each run in a forked child, so reading, estimating and
writing overlap on separate cores instead of taking turns: the estimation bounds the run, not
the disk. Elsewhere (a Ray worker, which runs threads) the same chunks take turns in this
process, with the same bytes written.

The children talk to this process through one pipe each; a pipe's buffer holds less than a
chunk, so neither end can run more than a chunk ahead (flat memory again). They ignore SIGINT
and SIGTERM: this process decides, and on any error or signal it kills them before the bag's
temporary folder is removed (bagio.bag_folder). A child whose parent was killed (SIGKILL) finds
its pipe closed and ends; the hidden partial folder stays beside the output, as a killed
writer's always did (a batch run removes those of its own outputs: bagio.remove_leftovers).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import queue
import signal
import threading
import time
from collections.abc import Iterator
from multiprocessing.connection import Connection
from pathlib import Path

from ..core.types import BodyPoses, TrackerStream
from ..io.bagio import BagError, open_writer, tracker_chunks
from ..io.estimate_bag import EstimateBagWriter

NICER = 10  # the children's niceness above this process's


def can_fork() -> bool:
    """Whether the reader and writer may run in forked children here."""
    return "fork" in multiprocessing.get_all_start_methods() and threading.active_count() == 1


class Reader:
    """The tracker bag's chunks, read in this process; `busy` seconds spent reading, `refused`
    samples by reason once the bag is read."""

    def __init__(self, path: Path, sensors, stale_after: float, guards) -> None:
        self.busy = 0.0
        self.refused: dict[str, int] = {}
        self._chunks = tracker_chunks(path, sensors, stale_after, self.refused, guards)

    def __iter__(self) -> Iterator[TrackerStream]:
        while True:
            clock = time.perf_counter()
            chunk = next(self._chunks, None)
            self.busy += time.perf_counter() - clock
            if chunk is None:
                return
            yield chunk

    def __enter__(self) -> Reader:
        return self

    def __exit__(self, *_) -> None:
        self._chunks.close()


class Writer:
    """The estimate bag written in this process, at bagio.bag_folder's temporary path."""

    def __init__(self, tmp: Path, made_with: str, compression: str, **bag) -> None:
        self.busy = 0.0
        self._open = open_writer(tmp, made_with, compression)
        self._out = EstimateBagWriter(self._open.__enter__(), **bag)

    def write(self, poses: BodyPoses, trackers: TrackerStream) -> None:
        clock = time.perf_counter()
        self._out.write(poses, trackers)
        self.busy += time.perf_counter() - clock

    def finish(self) -> None:
        """Close the bag (its summary and metadata); it is whole after this returns."""
        clock = time.perf_counter()
        self._open.__exit__(None, None, None)
        self.busy += time.perf_counter() - clock

    def __enter__(self) -> Writer:
        return self

    def __exit__(self, kind, error, trace) -> None:
        if kind is not None:  # the folder goes; the writer need not finish its file
            self._open.__exit__(kind, error, trace)


def _in_child(*inherited: Connection) -> None:
    """A forked child's first step: the signals are the parent's to act on, and the pipe ends
    that are not its own are closed, so that each pipe closes when its far end's process
    ends."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})  # held by the fork (offline.py)
    # The estimation bounds the run: given a core whenever it can run, it never waits on the
    # reader or the writer, which share what is left (on 2 cores, the whole 10-minute ik run
    # took 5.3-5.4 s without it and 4.2-4.5 s with it)
    os.nice(NICER)
    for end in inherited:
        end.close()


def _send_error(conn: Connection, err: BaseException) -> None:
    try:
        conn.send(("error", err))
    except Exception:  # noqa: BLE001 - an error that cannot be pickled goes as its words
        conn.send(("error", RuntimeError(f"{type(err).__name__}: {err}")))


def _read_in_child(conn: Connection, inherited: tuple[Connection, ...], path, sensors, stale_after, guards) -> None:
    _in_child(*inherited)
    try:
        reader = Reader(path, sensors, stale_after, guards)
        for chunk in reader:
            conn.send(("chunk", chunk))
        conn.send(("end", reader.refused, reader.busy))
    except (BrokenPipeError, EOFError):
        return  # the parent is gone
    except BaseException as err:  # noqa: BLE001 - every error is the parent's to report
        _send_error(conn, err)


def _write_in_child(conn: Connection, inherited: tuple[Connection, ...], tmp, made_with, compression, bag) -> None:
    _in_child(*inherited)
    try:
        writer = Writer(tmp, made_with, compression, **bag)
        while (message := conn.recv())[0] == "chunk":
            writer.write(*message[1:])
        writer.finish()
        conn.send(("done", writer.busy))
    except (BrokenPipeError, EOFError):
        return  # the parent is gone
    except BaseException as err:  # noqa: BLE001 - every error is the parent's to report
        _send_error(conn, err)
        try:  # take what the parent still sends, so that it is never blocked on a full pipe
            while conn.recv()[0] == "chunk":
                pass
        except (BrokenPipeError, EOFError):
            pass


class _Child:
    """One forked child, this process's end of its pipe, and a thread of this process that
    moves chunks between the pipe and a short queue: a pipe's buffer holds less than a chunk, so
    without it each side would wait for the other at every chunk instead of running a chunk or
    two ahead (QUEUED)."""

    QUEUED = 2  # chunks waiting on each side of a pipe: memory stays a few chunks

    def __init__(self, target, args, inherited: tuple[Connection, ...] = ()) -> None:
        context = multiprocessing.get_context("fork")
        self.conn, child_end = context.Pipe()
        self.process = context.Process(target=target, args=(child_end, (self.conn, *inherited), *args), daemon=True)
        self.process.start()
        child_end.close()
        self.queue: queue.Queue = queue.Queue(self.QUEUED)
        self._stopping = threading.Event()
        self._mover: threading.Thread | None = None

    def move(self, mover) -> None:
        """Start the thread that moves chunks (after the fork of every child: a thread must not
        be running while a process forks)."""
        self._mover = threading.Thread(target=mover, name="sparse_body_pipe", daemon=True)
        self._mover.start()

    def put(self, item) -> bool:
        """Into the queue, waiting while it is full; False when the mover has ended instead."""
        while not self._stopping.is_set():
            try:
                self.queue.put(item, timeout=0.2)
                return True
            except queue.Full:
                if self._mover is not None and not self._mover.is_alive():
                    return False
        return False

    def answer(self, what: str, message):
        """A message from the child: its error raised, its end said."""
        if message[0] == "gone":
            raise BagError(f"the {what} process ended unexpectedly (exit code {self.process.exitcode})")
        if message[0] == "error":
            raise message[1]
        return message

    def stop(self) -> None:
        """The child ended at once (SIGKILL: it ignores the others) unless it has ended, and the
        mover with it."""
        self._stopping.set()
        if self.process.is_alive():
            self.process.kill()
        self.process.join()  # its pipe end is closed now: a mover in recv or send ends
        while True:  # and a mover waiting on the queue is woken
            try:
                self.queue.get_nowait()
            except queue.Empty:
                break
        with contextlib.suppress(queue.Full):  # (a reader's mover may have filled it again: it ends anyway)
            self.queue.put_nowait(None)
        if self._mover is not None:
            self._mover.join()
        self.conn.close()


class ForkedReader:
    """Reader's chunks, read in a forked child while this process estimates."""

    def __init__(self, path: Path, sensors, stale_after: float, guards) -> None:
        self.busy = 0.0
        self.refused: dict[str, int] = {}
        self._child = _Child(_read_in_child, (path, sensors, stale_after, guards))

    def start(self) -> None:
        self._child.move(self._receive)

    def _receive(self) -> None:
        while True:
            try:
                message = self._child.conn.recv()
            except (EOFError, OSError):
                message = ("gone",)
            if not self._child.put(message) or message[0] != "chunk":
                return

    def __iter__(self) -> Iterator[TrackerStream]:
        while True:
            message = self._child.answer("reading", self._child.queue.get())
            if message[0] == "end":
                self.refused.update(message[1])
                self.busy = message[2]
                return
            yield message[1]

    @property
    def conn(self) -> Connection:
        return self._child.conn

    def __enter__(self) -> ForkedReader:
        return self

    def __exit__(self, *_) -> None:
        self._child.stop()


class ForkedWriter:
    """Writer in a forked child: write() queues a chunk and returns."""

    def __init__(self, tmp: Path, made_with: str, compression: str, inherited: tuple[Connection, ...] = (), **bag):
        self.busy = 0.0
        self._child = _Child(_write_in_child, (tmp, made_with, compression, bag), inherited)

    def start(self) -> None:
        self._child.move(self._send)

    def _send(self) -> None:
        while (item := self._child.queue.get()) is not None:
            try:
                self._child.conn.send(item)
            except OSError:  # the writer has ended: finish() or write() says why
                return

    def write(self, poses: BodyPoses, trackers: TrackerStream) -> None:
        if self._child.conn.poll():  # the writer failed: say why now, not after the whole run
            self._failed()
        if not self._child.put(("chunk", poses, trackers)):
            self._failed()

    def finish(self) -> None:
        if not (self._child.put(("end",)) and self._child.put(None)):
            self._failed()
        assert self._child._mover is not None
        self._child._mover.join()
        self.busy = self._result()[1]
        self._child.process.join()

    def _result(self):
        try:
            message = self._child.conn.recv()
        except (EOFError, OSError):
            message = ("gone",)
        return self._child.answer("writing", message)

    def _failed(self) -> None:
        self._result()  # raises the writer's error
        raise BagError("the writing process stopped taking chunks")

    def __enter__(self) -> ForkedWriter:
        return self

    def __exit__(self, *_) -> None:
        self._child.stop()
