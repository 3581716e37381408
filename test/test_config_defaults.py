"""The shipped parameter files say what the nodes declare: a value in config/*.yaml that
differed from the node's own default would make a launched node and a node started by hand
behave apart (issue 76)."""

from pathlib import Path

import pytest
import yaml

pytest.importorskip("rclpy", reason="rclpy is not installed (run the setup command)")

CONFIG = Path(__file__).resolve().parents[1] / "config"


@pytest.mark.parametrize(
    ("file", "node", "module"),
    [
        ("estimator.yaml", "sparse_body_estimator", "sparse_body.ros.estimator_node"),
        ("tracker_bridge.yaml", "sparse_body_tracker_bridge", "sparse_body.ros.tracker_bridge_node"),
    ],
)
def test_each_parameter_file_holds_the_nodes_own_defaults(file, node, module):
    import importlib

    declared = importlib.import_module(module).PARAMETERS
    given = yaml.safe_load((CONFIG / file).read_text())[node]["ros__parameters"]
    unknown = sorted(set(given) - set(declared))
    assert not unknown, f"{file}: {unknown} are no parameters of {node}"
    # autostart is the one value the file sets on purpose (a launched node starts itself)
    differing = {k: (v, declared[k][0]) for k, v in given.items() if k != "autostart" and v != declared[k][0]}
    assert not differing, f"{file} (value, the node's default): {differing}"
