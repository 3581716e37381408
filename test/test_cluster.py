"""`sparse-body process --cluster`: bags as tasks on a real Ray cluster (issue 29). A head and a
second worker node start on this machine, as `ray start` starts them on a lab's machines; a
worker is killed in the middle of a bag; every output bag is complete, equal to the one a
single process writes, and the summary says which bag was sent again and why."""

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from rosbags.rosbag2 import Reader

pytest.importorskip("ray", reason="ray is not installed (run the setup command)")

from sparse_body.apps.batch import SUMMARY, Settings, process_many  # noqa: E402
from sparse_body.apps.offline import make_bag  # noqa: E402
from sparse_body.core.calibration import person_body  # noqa: E402
from sparse_body.core.sensors import load_sensor_config  # noqa: E402
from sparse_body.data.synthetic import synthetic_walk  # noqa: E402
from sparse_body.io.tf_guards import TfGuards  # noqa: E402

LIMIT = 300.0  # s: a busy machine starts Ray and processes a bag many times slower than a quiet one
RAY = str(Path(sys.executable).with_name("ray"))


def free_ports(n: int) -> list[int]:
    sockets = [socket.socket() for _ in range(n)]
    try:
        for s in sockets:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in sockets]
    finally:
        for s in sockets:
            s.close()


@pytest.fixture
def env(tmp_path):
    """The environment with a home folder of the test's own: a ~/.ray/auth_token of the user's
    (a plain ray.init() leaves one) made every connection fail with InvalidAuthToken."""
    (tmp_path / "home").mkdir()
    return {**os.environ, "HOME": str(tmp_path / "home")}


def start_ray(args: list[str], log: Path, env: dict) -> subprocess.Popen:
    """`ray start ... --block` in a session of its own (stopped as one: `ray stop` would stop
    every Ray on the machine, another test run's too)."""
    with open(log, "w") as out:
        return subprocess.Popen(
            [RAY, "start", "--block", "--num-cpus=1", "--disable-usage-stats", "--object-store-memory=80000000", *args],
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            env=env,
        )


def in_sessions(sessions: set[int], title: bytes = b"") -> list[int]:
    """The processes of these sessions (a node's `ray start` and everything it started: Ray
    gives each worker a process group of its own, not a session), whose title starts so."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if os.getsid(int(entry.name)) in sessions and (entry / "cmdline").read_bytes().startswith(title):
                found.append(int(entry.name))
        except (OSError, ProcessLookupError):
            continue
    return found


def stop_sessions(sessions: set[int]) -> None:
    """Every process of our nodes: SIGTERM, then SIGKILL for what is left after 5 s."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in in_sessions(sessions):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, sig)
        end = time.monotonic() + 5.0
        while in_sessions(sessions) and time.monotonic() < end:
            time.sleep(0.2)


def process_on(tmp_path: Path, address: str) -> list[str]:
    """The command: the bags in tmp_path/in into tmp_path/out on the cluster at address."""
    command = str(Path(sys.executable).with_name("sparse-body"))
    return [command, "process", str(tmp_path / "in"), str(tmp_path / "out"), "--cluster", address, "--quiet"]


def messages(bag: Path) -> list[tuple[str, int, bytes]]:
    with Reader(bag) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


def test_bags_on_a_cluster_survive_a_killed_worker_and_equal_one_process(tmp_path, env):
    config = load_sensor_config("six_point")
    walk = synthetic_walk(20.0)
    (tmp_path / "in").mkdir()
    for k in range(3):
        make_bag(walk, config, tmp_path / "in" / f"walk{k}")
    head_port, *others = free_ports(6)
    ray_dir = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # short: Ray's socket paths must fit 107 bytes
    head = start_ray(
        [
            "--head",
            f"--port={head_port}",
            f"--temp-dir={ray_dir}",
            "--include-dashboard=false",
            f"--dashboard-port={others[0]}",
            f"--dashboard-agent-listen-port={others[1]}",
            f"--dashboard-agent-grpc-port={others[2]}",
            f"--metrics-export-port={others[3]}",
            f"--runtime-env-agent-port={others[4]}",
        ],
        tmp_path / "head.log",
        env,
    )
    nodes = [head]
    driver = None
    try:
        address = f"127.0.0.1:{head_port}"
        end = time.monotonic() + LIMIT
        while "Ray runtime started" not in (tmp_path / "head.log").read_text() and time.monotonic() < end:
            assert head.poll() is None, (tmp_path / "head.log").read_text()
            time.sleep(0.5)
        nodes.append(start_ray([f"--address={address}"], tmp_path / "worker.log", env))  # a second machine's node
        with open(tmp_path / "driver.log", "w") as log:
            driver = subprocess.Popen(process_on(tmp_path, address), stdout=log, stderr=subprocess.STDOUT, env=env)
        sessions = {p.pid for p in nodes}  # Ray titles a worker running a bag ray::<function>
        while (
            not (tasks := in_sessions(sessions, b"ray::_cluster_task"))
            and driver.poll() is None
            and time.monotonic() < end
        ):
            time.sleep(0.05)
        assert tasks, "no bag ran on the cluster: " + (tmp_path / "driver.log").read_text()
        os.kill(tasks[0], signal.SIGKILL)  # a worker dies in the middle of a bag
        assert driver.wait(timeout=LIMIT) == 0, (tmp_path / "driver.log").read_text()
        # SIGTERM to a run on the cluster: the command's one line and 143 (Ray's own handler
        # printed a stack dump and exited with 1; ray.cancel made its driver abort now and then)
        command = process_on(tmp_path, address)
        command[3] = str(tmp_path / "stopped")
        stopped = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        # its output folder is made once it is connected (ray.init done, the command's handlers
        # back); a SIGTERM before that is Python's default death
        until = time.monotonic() + LIMIT
        while not (tmp_path / "stopped").exists() and stopped.poll() is None and time.monotonic() < until:
            time.sleep(0.05)
        time.sleep(1.0)  # its bags are on their way to the workers
        stopped.send_signal(signal.SIGTERM)
        _, err = stopped.communicate(timeout=LIMIT)
        assert stopped.returncode == 143 and err.strip().splitlines() == [err.strip()], err
        assert "terminated" in err
        # every task removed its half-written bag, and the word to stop is gone with the run
        assert not [p.name for p in (tmp_path / "stopped").iterdir() if p.name.startswith(".")]
    finally:
        if driver is not None and driver.poll() is None:
            driver.kill()
        stop_sessions({p.pid for p in nodes})
        for node in nodes:
            node.wait(timeout=10)
        shutil.rmtree(ray_dir, ignore_errors=True)
    said = (tmp_path / "out" / SUMMARY).read_text()
    summary = json.loads(said)["bags"]
    assert [b["status"] for b in summary] == ["done"] * 3, said
    assert any(b["retried"] for b in summary), said  # the killed attempt is on record
    assert not [p.name for p in (tmp_path / "out").iterdir() if p.name.startswith(".")]  # nothing half-written

    settings = Settings("ik", {}, config, person_body(None, 1.75), 60.0, TfGuards())  # the command's defaults
    process_many([tmp_path / "in"], tmp_path / "here", settings, jobs=1, progress=False)
    for k in range(3):
        assert messages(tmp_path / "out" / f"walk{k}") == messages(tmp_path / "here" / f"walk{k}")


def test_a_cluster_that_is_not_there_is_a_one_line_error(tmp_path, env):
    config = load_sensor_config("six_point")
    (tmp_path / "in").mkdir()
    make_bag(synthetic_walk(1.0), config, tmp_path / "in" / "walk")
    (port,) = free_ports(1)
    done = subprocess.run(
        process_on(tmp_path, f"127.0.0.1:{port}"), capture_output=True, text=True, timeout=LIMIT, env=env
    )
    assert done.returncode == 1 and "no Ray cluster there" in done.stderr, (
        done.stderr
    )  # bad input, not "output refused"
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "out").exists()  # nothing made before the cluster answered
