"""Many recordings at once: `sparse-body process IN... OUT_FOLDER --jobs N`.

Each input bag becomes OUT_FOLDER/<its name>, written as one bag is (process_bag: under a
temporary name, moved into place when complete), by one of N worker processes. A bag that
fails is reported with its error and the others go on; a bag whose output is already there
(a complete bag of ours: nothing else is ever left under that name) is skipped, so a run
that was stopped resumes where it was. Every run writes a summary (each bag: frames,
invalid estimates, refused samples, seconds, error) beside the outputs.

With `--cluster ADDRESS` the bags go to a Ray cluster instead (one task a bag; its nodes see
the same storage): Ray is the engine this field uses to spread work over machines, and it
keeps workers, scheduling and node failures out of this file. A task whose worker or node
died is sent again (at most RETRIES times), which the summary records; its half-written bag
never takes the output's name (bagio.bag_writer), and its leftover is removed here. A stopped
run tells its tasks through a file in the output folder (STOP_FILE), which every node sees:
each running task removes its half-written bag and returns, a queued one returns at once.
Ray's own way (ray.cancel) made its driver abort now and then on a task cancelled as it
started ("Tried to complete task that was not pending"), so it is not used."""

from __future__ import annotations

import contextlib
import json
import logging
import multiprocessing
import os
import signal
import socket
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from ..core.causes import cause_of_kind
from ..core.file_output import check_target, write_file
from ..core.sensors import SensorConfig
from ..core.skeleton import Skeleton
from ..io.bagio import (
    ESTIMATE_TOPICS,
    BagError,
    OutputError,
    joint_state_count,
    made_with,
    remove_leftovers,
    written_by_us,
)
from ..io.tf_guards import TfGuards

SUMMARY = "sparse_body_summary.json"  # beside the outputs; replaced only when it is ours
SUMMARY_KEY = "sparse_body.process"


@dataclass(frozen=True)
class Settings:
    """What every bag of a run is processed with (sent to each worker)."""

    estimator: str
    options: dict
    sensors: SensorConfig
    skeleton: Skeleton
    fps: float
    guards: TfGuards
    overwrite: bool = False
    topics: tuple[str, ...] = ESTIMATE_TOPICS  # what each output bag holds
    compression: str = "zstd"  # its chunks' (io/bagio.COMPRESSIONS)
    axis_links: bool = False  # the URDF's massless links on /tf too
    robot: tuple[str, str] | None = None  # (mapping YAML, URDF or ""): the humanoid robot's joints too


@dataclass
class BagResult:
    """One line of the summary."""

    input: str
    output: str
    status: str  # done, skipped (finished before), failed
    frames: int = 0
    invalid: int = 0
    refused: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    error: str = ""
    retried: list[str] = field(default_factory=list)  # why each earlier attempt ended (a cluster's)


RETRIES = 3  # a bag whose worker died is sent again at most this many times (--cluster)
CONNECT_TIMEOUT = 10.0  # s for the cluster's head to answer
STOP_FILE = ".sparse_body_stop"  # in the output folder while a stopped cluster run waits for its tasks
STOP_WORDS = "sparse-body process --cluster: stop\n"  # what STOP_FILE holds (a leftover one is ours)
STOP_POLL = 0.2  # s between a cluster task's looks for STOP_FILE
STOP_WAIT = 60.0  # s a stopped run waits for its workers or tasks to remove their half-written bags


def is_bag(path: Path) -> bool:
    """A rosbag2 directory (metadata.yaml in it) or a single MCAP file."""
    return (path.is_dir() and (path / "metadata.yaml").is_file()) or (path.is_file() and path.suffix == ".mcap")


def expand_inputs(given: list[Path]) -> list[Path]:
    """The bags named, with a folder that is not a bag standing for the bags directly in it."""
    bags: list[Path] = []
    for path in given:
        if not path.exists():
            raise BagError(f"{path}: no such bag or folder")
        if is_bag(path) or not path.is_dir():
            bags.append(path)
            continue
        # a folder named like an MCAP file is an input too: it fails, saying why, instead of
        # being left out without a word
        found = sorted(p for p in path.iterdir() if (is_bag(p) or p.suffix == ".mcap") and not p.name.startswith("."))
        if not found:
            raise BagError(f"{path}: a folder with no bags in it")
        bags.extend(found)
    names = [bag.name.removesuffix(".mcap") for bag in bags]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise BagError(f"two inputs would have the same output name: {', '.join(twice)} (rename one, or run twice)")
    return bags


def output_for(bag: Path, out_dir: Path) -> Path:
    return out_dir / bag.name.removesuffix(".mcap")


class _Stopped(BaseException):
    """SIGTERM from the parent (Ctrl-C or SIGTERM to the run): the bag being written is removed
    on the way out (bagio.bag_writer), then the worker ends. A BaseException, as
    KeyboardInterrupt is: the `except Exception` of a reader or a library must not turn it into
    an error of the bag (rosbags' errors become BagError, without their cause)."""


_writing = False  # in a worker: a bag is being processed


def _stop(signum, frame):
    if _writing:
        # Once: when another worker ends, the pool counts itself broken and sends SIGTERM to
        # every worker again (concurrent.futures' terminate_broken), and a second _Stopped
        # landing in this one's clean-up left its half-written bag (CI, stop 59)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise _Stopped
    os._exit(143)  # between bags: nothing to clean up


def _process_one(bag: Path, out: Path, settings: Settings, exit_on_stop: bool = True) -> BagResult:
    """A worker's task: one bag, every error caught and reported as its result. A stop ends
    the worker process (exit_on_stop: a pool's) or is reported as the result "stopped"."""
    from .offline import process_bag

    global _writing
    start = time.perf_counter()
    result = BagResult(str(bag), str(out), "done")
    refused: dict[str, int] = {}
    try:
        from .offline import check_bag_trackers

        _writing = True
        check_bag_trackers(bag, settings.sensors)  # each bag's trackers are there, before it is read
        processed = process_bag(
            bag,
            out,
            settings.estimator,
            settings.sensors,
            settings.skeleton,
            settings.fps,
            progress=False,
            overwrite=settings.overwrite,
            refused=refused,
            guards=settings.guards,
            topics=settings.topics,
            compression=settings.compression,
            axis_links=settings.axis_links,
            robot=settings.robot,
            **settings.options,
        )
        result.frames, result.invalid = processed.frames, processed.invalid
    except (Exception, _Stopped) as err:
        # the stop lands wherever the bag is; inside compiled code (a numba kernel) it comes
        # back as that code's SystemError, caused by _Stopped
        if _caused_by_stop(err):
            if exit_on_stop:
                os._exit(143)  # the half-written bag is gone; the pool would hand this worker another
            result.status, result.error = "stopped", "the run was stopped"
        elif isinstance(err, (ValueError, OSError, EOFError, MemoryError, RecursionError)):
            result.status, result.error = "failed", " ".join(str(err).split()) or type(err).__name__
        else:
            raise
    finally:
        _writing = False
    result.refused, result.seconds = refused, round(time.perf_counter() - start, 3)
    return result


def _caused_by_stop(err: BaseException) -> bool:
    return cause_of_kind(err, _Stopped) is not None


def _stop_task(signum, frame):
    if _writing:  # between bags a cluster task has nothing to remove: it returns on its own
        raise _Stopped


def _cluster_task(bag: Path, out: Path, settings: Settings, stop_file: Path) -> BagResult:
    """One bag as a Ray task (in its worker's main thread, where signal handlers run): a thread
    watches for stop_file and interrupts the bag with SIGUSR2, which _process_one turns into the
    removal of its half-written bag."""
    if stop_file.exists():  # queued when the run was stopped
        return BagResult(str(bag), str(out), "stopped", error="the run was stopped")
    previous = signal.signal(signal.SIGUSR2, _stop_task)
    finished = threading.Event()

    def watch() -> None:
        while not finished.wait(STOP_POLL):
            if stop_file.exists():
                os.kill(os.getpid(), signal.SIGUSR2)
                return

    watcher = threading.Thread(target=watch, name="sparse-body-stop", daemon=True)
    watcher.start()
    try:
        return _process_one(bag, out, settings, exit_on_stop=False)
    finally:
        finished.set()
        watcher.join()
        signal.signal(signal.SIGUSR2, previous)


def _worker_init() -> None:
    # the parent says when to stop: the terminal's SIGINT reaches every worker too, and the
    # pool takes a worker that raised for one that may start the next bag
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _stop)


def process_many(
    inputs: list[Path],
    out_dir: Path,
    settings: Settings,
    jobs: int,
    progress: bool = True,
    cluster: str | None = None,
) -> list[BagResult]:
    """Process every input bag into out_dir with `jobs` worker processes, or as tasks on the Ray
    cluster at `cluster` ("auto": the one this machine is part of); returns one result a bag,
    in input order, and writes them to out_dir / SUMMARY."""
    from .offline import settings_record

    bags = expand_inputs(inputs)
    target = out_dir.resolve()
    for given in inputs:  # the outputs would land among (or inside) the inputs
        if target == given.resolve() or given.resolve() in target.parents:
            raise OutputError(f"{out_dir}: is (or is inside) the input {given}; choose another output folder")
    record_of_run = settings_record(
        settings.estimator,
        settings.options,
        settings.sensors,
        settings.skeleton,
        settings.fps,
        settings.topics,
        settings.axis_links,
        settings.robot,
    )
    results: dict[int, BagResult] = {}
    todo, other = [], []
    for i, bag in enumerate(bags):
        out = output_for(bag, out_dir)
        if written_by_us(out) and not settings.overwrite:
            results[i] = BagResult(str(bag), str(out), "skipped", error="finished before (--overwrite redoes it)")
            if made_with(out) != record_of_run:
                other.append(out)
        else:
            todo.append(i)
    if other:  # resuming would mix estimates of two settings in one folder
        theirs = made_with(other[0])
        said = json.loads(theirs)["estimator"] if theirs else "an earlier version"
        raise OutputError(
            f"{out_dir}: {len(other)} finished bag(s) there were made with other settings ({other[0].name}: "
            f"{said}); choose another output folder, or --overwrite to redo them"
        )
    connection = _connect(cluster) if cluster is not None else None  # before anything is made
    created = not out_dir.exists()
    out_dir.mkdir(exist_ok=True)
    try:
        summary = out_dir / SUMMARY
        check_target(summary, _is_our_summary, True, "summary")  # the rules _write_summary writes by
        if cluster is not None:  # one left by a run killed while it stopped would stop this one
            check_target(out_dir / STOP_FILE, _is_our_stop_file, True, "stop file")
            (out_dir / STOP_FILE).unlink(missing_ok=True)
    except BaseException:
        if created:
            out_dir.rmdir()
        if connection is not None:
            connection.shutdown()
        raise
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(bags), initial=len(results), desc=f"{settings.estimator} bags", unit="bag")

    def record(i: int, result: BagResult) -> None:
        results[i] = result
        if bar is not None:
            bar.update(1)
            bar.set_postfix(frames=sum(r.frames for r in results.values()))
        _write_summary(summary, bags, results, record_of_run)

    tasks = [(i, bags[i], output_for(bags[i], out_dir)) for i in todo]
    before = {i: _identity(out) for i, _, out in tasks}  # what each output was when the run began
    try:
        if cluster is None:
            _run_here(tasks, settings, jobs, record)
        else:
            _run_on_cluster(tasks, settings, connection, record, out_dir / STOP_FILE)
    except BaseException:
        # a stop can end a worker after its bag took the output's name but before its result
        # came back: the bag is complete and kept, so the summary must list it as well
        for i, bag, out in tasks:
            if i not in results and written_by_us(out) and _identity(out) != before[i]:
                result = BagResult(str(bag), str(out), "done", error=FINISHED_AT_STOP)
                with contextlib.suppress(OSError, ValueError):  # the count is only for the summary
                    result.frames = joint_state_count(out)
                record(i, result)
        raise
    finally:
        if bar is not None:
            bar.close()  # before the command's last line
    ordered = [results[i] for i in range(len(bags))]
    _write_summary(summary, bags, results, record_of_run)
    return ordered


FINISHED_AT_STOP = "finished as the run was stopped: its invalid and refused counts did not come back"


def _identity(path: Path) -> tuple[int, int] | None:
    """Which directory entry `path` is (a bag moved into place is a new one), None if none."""
    try:
        stat = path.stat(follow_symlinks=False)
    except OSError:
        return None
    return stat.st_ino, stat.st_mtime_ns


Task = tuple[int, Path, Path]  # the bag's place in the run, the bag, its output


def _run_here(tasks: list[Task], settings: Settings, jobs: int, record) -> None:
    """The bags on `jobs` worker processes of this machine."""
    # fork: a worker starts with the modules loaded (spawn would import them again)
    context = multiprocessing.get_context("fork" if os.name == "posix" else "spawn")
    with ProcessPoolExecutor(
        max_workers=max(1, min(jobs, len(tasks) or 1)), mp_context=context, initializer=_worker_init
    ) as pool:
        pending: dict[Future, int] = {pool.submit(_process_one, bag, out, settings): i for i, bag, out in tasks}
        try:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    record(pending.pop(future), future.result())
        except BaseException:
            for future in pending:
                future.cancel()
            workers = multiprocessing.active_children()  # the pool's workers: this run has no others
            for process in workers:
                process.terminate()  # SIGTERM: each removes its half-written bag (bagio.bag_writer)
            for process in workers:
                process.join(timeout=STOP_WAIT)
                if process.is_alive():  # stuck: it ignores a second SIGTERM
                    process.kill()
                    process.join()
            # no worker runs now: what one could not remove (a stop landing in its clean-up, a
            # kill) goes here, never left for the next run over the folder
            for _, _, out in tasks:
                remove_leftovers(out)
            # a bag that finished as the run was stopped is on disk: the summary says so too
            wait(pending, timeout=1.0)
            for future, i in pending.items():
                finished = future.done() and not future.cancelled() and future.exception() is None
                if finished and (result := future.result()).status == "done":  # not one the stop broke off
                    record(i, result)
            raise


class ClusterError(ValueError):
    """--cluster names no Ray cluster that answers, or Ray is not installed (exit code 1)."""


def _connect(address: str):
    """The ray module, connected to the cluster at `address` (before any output is made).
    Ray's driver installs its own SIGTERM handler (a stack dump, exit 1): the command line's
    is put back, so SIGTERM still ends the run in one line with 143."""
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        import ray
    except ImportError:
        raise ClusterError("--cluster needs Ray: pip install 'ray>=2.40' (make setup installs it)") from None
    host, _, port = address.rpartition(":")
    if address != "auto":  # Ray itself retries an address nobody answers for minutes
        if not port.isdigit():
            raise ClusterError(f"--cluster {address}: not HOST:PORT (the address `ray start --head` gives) or auto")
        try:
            socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=CONNECT_TIMEOUT).close()
        except OSError as err:
            raise ClusterError(
                f"--cluster {address}: no Ray cluster there ({err}; HOST:PORT of `ray start --head`)"
            ) from None
    try:
        ray.init(address=address, logging_level=logging.ERROR, log_to_driver=False, configure_logging=False)
    except (ConnectionError, RuntimeError, ValueError) as err:
        raise ClusterError(f"--cluster {address}: no Ray cluster there ({' '.join(str(err).split())})") from None
    finally:
        for number, handler in handlers.items():
            if handler is not None:
                signal.signal(number, handler)
    return ray


def _run_on_cluster(tasks: list[Task], settings: Settings, ray, record, stop_file: Path) -> None:
    """One Ray task a bag (`ray`: connected by _connect). A task that ends because its worker
    process or node died is sent again, up to RETRIES times; one that raises (a bug:
    _process_one reports every error a bag can cause) fails its bag with the error, and the
    others go on. A stop (Ctrl-C, SIGTERM) writes stop_file and waits for the tasks."""
    from ray import exceptions as ray_errors

    by_ref: dict = {}
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(_cluster_task)  # retried here, to record why
        # absolute: a worker's folder is its own (the nodes see the same storage, not the same cwd)
        stop = stop_file.absolute()
        by_ref.update(
            {remote.remote(bag.absolute(), out.absolute(), settings, stop): (i, bag, out) for i, bag, out in tasks}
        )
        retried: dict[int, list[str]] = {i: [] for i, _, _ in tasks}
        while by_ref:
            (ref,), _ = ray.wait(list(by_ref), num_returns=1)
            i, bag, out = by_ref.pop(ref)
            try:
                result = ray.get(ref)
            except ray_errors.RayTaskError as err:
                result = BagResult(str(bag), str(out), "failed", error=" ".join(str(err.cause).split()))
            except ray_errors.RayError as err:  # the worker or its node died
                retried[i].append(type(err).__name__)
                if len(retried[i]) <= RETRIES:
                    # a worker killed after its bag took the output's name leaves a complete bag of
                    # ours there: the retry replaces it (what is not ours is refused all the same)
                    again = replace(settings, overwrite=True)
                    by_ref[remote.remote(bag.absolute(), out.absolute(), again, stop)] = (i, bag, out)
                    continue
                result = BagResult(str(bag), str(out), "failed", error=f"its worker died {len(retried[i])} times")
            result.input, result.output, result.retried = str(bag), str(out), retried[i]
            if retried[i]:
                remove_leftovers(out)  # no attempt of it runs any more
            record(i, result)
    except BaseException:
        _stop_cluster_tasks(by_ref, ray, record, stop_file)
        raise
    finally:
        ray.shutdown()


def _stop_cluster_tasks(by_ref: dict, ray, record, stop_file: Path) -> None:
    """Tell every task to stop and wait (STOP_WAIT at most) until each has removed its half-written
    bag; a bag that finished meanwhile is recorded as done."""
    made = False
    try:
        # O_EXCL: a name someone put there meanwhile is not written through, and not removed
        fd = os.open(stop_file, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o644)
        made = True
        with os.fdopen(fd, "w") as file:
            file.write(STOP_WORDS)
    except OSError:
        pass  # the tasks then run to their end, and the stop still ends the run
    try:
        if made and by_ref:
            ready, _ = ray.wait(list(by_ref), num_returns=len(by_ref), timeout=STOP_WAIT)
            for ref in ready:
                with contextlib.suppress(Exception):  # a task whose worker died: nothing to record
                    result = ray.get(ref)
                    if result.status == "done":
                        i, bag, out = by_ref[ref]
                        result.input, result.output = str(bag), str(out)
                        record(i, result)
    finally:
        if made:
            stop_file.unlink(missing_ok=True)


def _is_our_stop_file(path: Path) -> bool:
    try:
        return path.is_file() and path.stat().st_size < 1024 and path.read_text() == STOP_WORDS
    except (OSError, ValueError):
        return False


def _is_our_summary(path: Path) -> bool:
    try:
        return path.is_file() and path.stat().st_size < 64 << 20 and SUMMARY_KEY in json.loads(path.read_text())
    except (OSError, ValueError):
        return False


def _write_summary(path: Path, bags: list[Path], results: dict[int, BagResult], settings_json: str) -> None:
    """The run so far, replaced as a whole (a reader never sees half a file)."""

    body = {
        SUMMARY_KEY: "one entry per input bag of the last run: done, skipped (finished before) or failed",
        "settings": json.loads(settings_json),
        "bags": [asdict(results[i]) for i in sorted(results)],
        "pending": [str(bags[i]) for i in range(len(bags)) if i not in results],
    }
    write_file(path, json.dumps(body, indent=1) + "\n", _is_our_summary, overwrite=True, what="summary")
