from pathlib import Path

import numpy as np
import pytest

from sparse_body.data.catalog import find_mocap_root, read_index

NO_MOCAP = (
    "no motion capture indexed: download CMU's ASF/AMC files (allasfamc.zip on mocap.cs.cmu.edu), "
    "run `sparse-body import-mocap FOLDER --out DIR`, then SPARSE_BODY_MOCAP=DIR make test"
)


@pytest.fixture(scope="session")
def mocap_root() -> Path:
    root = find_mocap_root()
    if root is None:
        pytest.skip(NO_MOCAP)
    return root


@pytest.fixture(scope="session")
def clip_index(mocap_root):
    return {c.clip_id: c for c in read_index(mocap_root)}


# the first seconds of four CMU clips, indexed with a split of their own (fixtures/cmu/README.md)
FIXTURE_MOCAP = Path(__file__).resolve().parent / "fixtures" / "cmu"


@pytest.fixture(scope="session")
def train_mocap() -> Path:
    """What the trainers' tests train on: the motion capture where it is installed, else the
    repository's fixtures, so that every trainer, resume and export test runs for anyone."""
    return find_mocap_root() or FIXTURE_MOCAP


@pytest.fixture(scope="session")
def train_clip_index(train_mocap):
    """The clips of train_mocap by id (02_01, 02_05, 05_02 and 16_17 in either)."""
    return {c.clip_id: c for c in read_index(train_mocap)}


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def random_rotations(rng, shape):
    from scipy.spatial.transform import Rotation

    n = int(np.prod(shape))
    return Rotation.random(n, random_state=rng).as_matrix().reshape(tuple(shape) + (3, 3))


def pytest_configure(config):
    """DDS discovery on this machine only, for every node a test starts (a ROS program on
    another machine of the network never hears the suite, nor the suite it)."""
    import os

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


@pytest.fixture
def ros_env(monkeypatch):
    """rclpy initialised on a DDS domain of this test's own; yields the environment for
    node processes started by the test."""
    import os

    from ros_helpers import isolated_domain

    rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (run the setup command)")
    monkeypatch.setenv("ROS_DOMAIN_ID", isolated_domain())
    rclpy.init()
    yield dict(os.environ)
    rclpy.shutdown()


def shipped_model(name: str) -> tuple[Path, dict]:
    """A model of models/ and its training report: what the inference tests run (they need
    no torch; the trainers are tested by the tests marked `train`)."""
    import json

    from sparse_body.core.resources import models_dir

    return models_dir() / f"{name}.onnx", json.loads((models_dir() / f"{name}.train.json").read_text())


def pytest_collection_modifyitems(config, items):
    """Tests marked `mocap` skip, saying why, when the motion capture is absent (the marker
    alone skips nothing); tests marked `train` skip when torch is not installed."""
    import importlib.util

    if importlib.util.find_spec("torch") is None:
        no_torch = pytest.mark.skip(reason="needs the training tools (make test-train installs them)")
        for item in items:
            if item.get_closest_marker("train") is not None:
                item.add_marker(no_torch)
    if find_mocap_root() is not None:
        return
    skip = pytest.mark.skip(reason=NO_MOCAP)
    for item in items:
        if "mocap" in item.keywords:
            item.add_marker(skip)
