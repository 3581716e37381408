"""Options are declared once, in one dataclass per method (methods/NAME/options.py) and the
filter's (core/tracker_filter.FilterConfig); the parser's errors, the nodes' parameters, the
eval record and docs/options.md are read from it. A toy method in a temporary package shows
that one folder and one registry entry put a method everywhere."""

import subprocess
import sys
from pathlib import Path

import pytest

from sparse_body import evaluation
from sparse_body.apps import option_docs
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import Skeleton
from sparse_body.core.tracker_filter import FilterConfig
from sparse_body.data.synthetic import synthetic_walk
from sparse_body.methods import METHODS, Method, load
from sparse_body.methods.factory import create_estimator
from sparse_body.ros.node_options import (
    ConstraintNodeInputOptions,
    EstimatorNodeOptions,
    RetargetOptions,
    TrackerBridgeOptions,
)

DOCS = Path(__file__).resolve().parents[1] / "docs" / "options.md"
EVERY = [(name, load(record.options)) for name, record in METHODS.items()] + [
    ("filter", FilterConfig),
    ("estimator node", EstimatorNodeOptions),
    ("constraint node", ConstraintNodeInputOptions),
    ("tracker bridge", TrackerBridgeOptions),
    ("retarget node", RetargetOptions),
]


@pytest.mark.parametrize("owner,options", EVERY, ids=[name for name, _ in EVERY])
def test_every_option_says_what_it_does_and_every_number_has_a_range(owner, options):
    for name, option in options.fields().items():
        assert option.help, f"{owner}.{name} has no help"
        if option.numeric:
            assert option.range is not None, f"{owner}.{name} is a number without a range"
            if isinstance(option.default, (int, float)):
                assert option.range.low <= option.default <= option.range.high, f"{owner}.{name}"


def test_each_estimator_reads_the_options_its_record_names():
    for name, record in METHODS.items():
        assert load(record.estimator).Options is load(record.options), name


def test_a_spec_s_options_are_checked_against_the_declaration_before_a_model_is_loaded():
    sensors, skeleton = load_sensor_config("four_point"), Skeleton.canonical()
    with pytest.raises(ValueError, match=r"estimator 'lobstr' has no option 'bogus'; its options are model_path, "):
        create_estimator("lobstr", sensors, skeleton, bogus=1, model_path="/nowhere.onnx")
    with pytest.raises(ValueError, match=r"estimator 'dtp': foot_trust must be from 0 to 5 \(metres\), got 6"):
        create_estimator("dtp", sensors, skeleton, foot_trust=6, model_path="/nowhere.onnx")
    with pytest.raises(ValueError, match=r"estimator 'dragposer': iterations takes an integer, got 2.5"):
        create_estimator("dragposer", sensors, skeleton, iterations=2.5)
    with pytest.raises(ValueError, match=r"filter: jump must be from 0 to 100 \(metres\), got -1"):
        create_estimator("ik", sensors, skeleton, filter_jump=-1)
    assert create_estimator("ik", sensors, skeleton, floor_height=0.1).options.floor_height == 0.1
    # a text with fixed values says them, before the model file (which does not exist) is looked for
    with pytest.raises(
        ValueError, match=r"estimator 'dtp': model must be one of online, lookahead, pretrained, got 'x'"
    ):
        create_estimator("dtp", sensors, skeleton, model="x", model_path="/nowhere.onnx")


def test_options_are_parsed_once_and_checked_together_before_anything_is_made(monkeypatch):
    """The factory parses a spec's options once and the estimator keeps that object (the issue
    found dtp.foot_trust parsed twice); options that do not go together are refused by the
    parse, before an inner estimator or a model is made (a model path that does not exist would
    have been the error otherwise)."""
    from sparse_body.core.options import Options
    from sparse_body.methods.dtp.options import DtpOptions

    sensors, skeleton = load_sensor_config("four_point"), Skeleton.canonical()
    parses: list[type] = []
    parse = Options.parse.__func__

    def counted(cls, given, owner=None):
        parses.append(cls)
        return parse(cls, given, owner)

    monkeypatch.setattr(Options, "parse", classmethod(counted))
    estimator = create_estimator("dtp", load_sensor_config("six_point"), skeleton, foot_trust=0.5)
    assert parses.count(DtpOptions) == 1 and estimator.options.foot_trust == 0.5
    import onnxruntime

    def no_model(*args, **kwargs):
        raise AssertionError("a model was loaded before the options were checked together")

    monkeypatch.setattr(onnxruntime, "InferenceSession", no_model)
    for spec, given, said in (
        ("upright", {"lying_from": 40.0}, r"lying_from \(40.0\) must be above upright_within \(45.0\)"),
        ("blend", {"disagree_from": 0.1}, r"disagree_from \(0.1\) must be above agree_within \(0.15\)"),
        ("refined", {"base": "refined"}, r"a refined estimator's base cannot be 'refined'"),
        ("blend", {"second": "bogus"}, r"blend's second: unknown estimator 'bogus'; available: auto, "),
    ):
        with pytest.raises(ValueError, match=said):
            create_estimator(spec, sensors, skeleton, **given)


def test_the_eval_record_holds_every_option_of_the_method_as_run():
    recorded = evaluation.method_options("lobstr:contact_ik=false", {"threads": 2, "filter_lag": 0.1})
    assert recorded["contact_ik"] is False and recorded["threads"] == 2
    assert set(recorded) == set(METHODS["lobstr"] and load(METHODS["lobstr"].options).fields())


def test_the_options_document_is_what_the_dataclasses_render():
    assert DOCS.read_text() == option_docs.markdown(), "docs/options.md: run `sparse-body options --markdown`"


TOY_OPTIONS = """
from dataclasses import dataclass
from sparse_body.estimators.options import EstimatorOptions, floor_height, option

@dataclass(frozen=True)
class ToyOptions(EstimatorOptions):
    gain: float = option(1.0, "how far the toy leans", 0.0, 2.0, "metres")
    floor_height: float = floor_height()
"""
TOY_ESTIMATOR = """
from sparse_body.estimators.base import Estimator
from sparse_body.methods.reference.estimator import ReferenceEstimator
from .options import ToyOptions

class ToyEstimator(ReferenceEstimator):
    name = "toy"
    Options = ToyOptions
"""


@pytest.fixture
def toy_method(tmp_path, monkeypatch):
    """A method in a package of its own, registered as the registry's line registers one."""
    package = tmp_path / "toy_method"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "options.py").write_text(TOY_OPTIONS)
    (package / "estimator.py").write_text(TOY_ESTIMATOR)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(
        METHODS, "toy", Method("toy", "toy_method.estimator:ToyEstimator", "toy_method.options:ToyOptions")
    )
    return tmp_path


def test_a_toy_method_is_everywhere_once_registered(toy_method, capsys):
    from sparse_body import cli

    sensors, skeleton = load_sensor_config("three_point"), Skeleton.canonical()
    with pytest.raises(ValueError, match=r"estimator 'toy': gain must be from 0 to 2 \(metres\), got 3"):
        create_estimator("toy", sensors, skeleton, gain=3)
    # the command line: its error, and the option listing
    with pytest.raises(SystemExit) as stopped:
        cli.main(["options", "toy"])
    assert stopped.value.code == 0 and "gain" in capsys.readouterr().out
    # the docs table
    assert (
        "## toy\n" in option_docs.markdown() and "| `gain` | a number from 0 to 2 (metres) |" in option_docs.markdown()
    )
    # the eval record, from a real run over a motion file
    walk = toy_method / "walk.npz"
    synthetic_walk(2.0).save(walk)
    result = evaluation.evaluate("toy:gain=0.5", sensors, None, motions=[walk], progress=False)
    assert result.to_json()["options"] == {"gain": 0.5, "floor_height": 0.0} and result.summary["MPJPE [cm]"] > 0


@pytest.mark.ros
def test_a_toy_method_s_options_are_node_parameters_with_their_ranges(toy_method):
    pytest.importorskip("rclpy")
    from sparse_body.ros.estimator_node import method_option_parameters

    declared = method_option_parameters()
    assert declared["dtp.model"].choices == ("online", "lookahead", "pretrained")  # and said in its description
    from sparse_body.ros.estimator_node import PARAMETERS

    assert PARAMETERS["dtp.model"][1].endswith("(one of online, lookahead, pretrained)")
    assert declared["toy.gain"].range is not None and (
        declared["toy.gain"].range.low,
        declared["toy.gain"].range.high,
    ) == (0.0, 2.0)


@pytest.mark.ros
def test_a_node_option_added_in_one_line_is_a_parameter_with_its_range_and_choices():
    """A node's parameters are its options dataclass (ros/node_options.py): a field added there
    is declared, described, ranged and checked with nothing else written."""
    pytest.importorskip("rclpy")
    from dataclasses import dataclass

    from sparse_body.core.options import option
    from sparse_body.ros.parameters import check_parameter, table

    @dataclass(frozen=True)
    class ToyRetargetOptions(RetargetOptions):
        stiffness: float = option(0.5, "how hard the toy holds", 0.0, 1.0)
        mode: str = option("soft", "how the toy holds", choices=("soft", "hard"))

    parameters, ranges = table(ToyRetargetOptions)
    assert parameters["stiffness"] == (0.5, "how hard the toy holds") and ranges["stiffness"] == (0.0, 1.0)
    assert parameters["mode"][1] == "how the toy holds (one of soft, hard)"
    assert check_parameter("stiffness", 1.5, 0.5, ranges) == "stiffness must be between 0 and 1, got 1.5"
    assert parameters["robot"][0] == "" and ranges["solve_budget"] == (0.001, 10.0)  # the node's own, kept


def test_the_options_command_is_one_line_for_an_unknown_method():
    done = subprocess.run(
        [sys.executable, "-m", "sparse_body.cli", "options", "bogus"], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 2 and "invalid choice: 'bogus'" in done.stderr


def test_the_command_line_is_a_dispatcher_over_one_module_a_command():
    from sparse_body import cli

    root = Path(cli.__file__).parent
    assert len((root / "cli.py").read_text().splitlines()) < 150
    for name in cli.COMMANDS:
        assert (root / "apps" / "commands" / f"{name}.py").is_file(), name
    parsed = cli.build_parser().parse_args(["options", "ik"])
    assert parsed.func.__module__ == "sparse_body.apps.commands.options"


def test_every_card_is_a_template_and_no_card_code_imports_the_commands():
    import ast

    root = Path(__file__).resolve().parents[1] / "sparse_body" / "train"
    for name, record in METHODS.items():
        if record.training is None:
            continue
        assert (root / name / "card.md").is_file(), name
        for node in ast.walk(ast.parse((root / name / "card.py").read_text())):
            if isinstance(node, ast.ImportFrom):
                assert "apps" not in (node.module or ""), (name, node.module)


def test_the_makefile_s_loops_read_the_registry():
    listed = subprocess.run(
        [sys.executable, "-m", "sparse_body.methods", "eval"], capture_output=True, text=True, timeout=120, check=True
    )
    assert listed.stdout.split("\n")[:2] == ["reference six_point", "ik six_point"]
    assert {line.split()[0] for line in listed.stdout.split("\n") if line} == {
        name for name, m in METHODS.items() if m.eval_sensors
    }


def test_an_option_given_twice_is_refused_and_a_long_value_is_quoted_short():
    """The last of `ik:predict_ahead=0.1,predict_ahead=0.2` silently won; a 100 kB value was
    echoed whole."""
    from sparse_body.estimators.base import parse_estimator_spec
    from sparse_body.methods.factory import create_estimator

    with pytest.raises(ValueError, match="'predict_ahead' is given twice"):
        parse_estimator_spec("ik:predict_ahead=0.1,predict_ahead=0.2")
    huge = "x" * 100_000
    for spec in (f"ik:floor_height={huge}", f"ik:{huge}", f"{huge}"):
        with pytest.raises(ValueError) as err:
            name, options = parse_estimator_spec(spec)
            create_estimator(name, load_sensor_config("six_point"), Skeleton.canonical(), **options)
        assert len(str(err.value)) < 400 and "characters)" in str(err.value), str(err.value)[:400]
