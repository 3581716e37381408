"""The method registry (sparse_body/methods): every record's import paths load, its presets
and figures are well formed, and the commands hold no per-method branches."""

import re
from pathlib import Path

import pytest

from sparse_body.core.sensors import load_sensor_config
from sparse_body.estimators.base import Estimator, parse_estimator_spec
from sparse_body.methods import METHODS, TRAINABLE, load, paper_figures

ROOT = Path(__file__).resolve().parents[1] / "sparse_body"


@pytest.mark.parametrize("name", sorted(METHODS))
def test_each_record_names_an_estimator_and_baselines_that_exist(name):
    method = METHODS[name]
    assert issubclass(load(method.estimator), Estimator) and load(method.estimator).name == name
    for spec in method.compare_with:
        assert parse_estimator_spec(spec)[0] in METHODS
    for key, figures in method.paper_figures.items():
        sensors = key if isinstance(key, str) else key[0]
        load_sensor_config(sensors)  # a shipped sensor set
        assert all(isinstance(v, float) for table in figures.values() for v in table.values())


@pytest.mark.train  # the configurations live beside the torch models
@pytest.mark.parametrize("name", TRAINABLE)
def test_each_trainable_method_has_presets_for_tests_and_for_a_small_machine(name):
    training = METHODS[name].training
    for part in training.parts:
        config_class = load(part.config)
        assert {"tiny", "small"} <= set(config_class.PRESETS), part.config
        for preset in config_class.PRESETS:
            config_class.named(preset)  # every preset makes a configuration (fields exist)
        assert callable(load(part.train))
        with pytest.raises(ValueError, match="unknown .* configuration 'nope'"):
            config_class.named("nope")
    assert training.output(lambda: load(training.parts[0].config).named("small")) in ("", *[f"{name}.onnx"])


def test_paper_figures_are_looked_up_by_sensors_and_faulty_share():
    assert "DragPoser paper" in paper_figures("dragposer", "six_point")
    assert paper_figures("dragposer", "six_point", 1.0)["DragPoser paper"]["End-effector PE [cm]"] == 10.2
    assert paper_figures("ik", "six_point") == {} and paper_figures("dtp", "six_point", occluded_percent=10) == {}


def test_the_commands_and_the_evaluation_hold_no_per_method_branches():
    names = "|".join(TRAINABLE)
    # a comparison with a method's name, or a flag named after one (`bench --dragposer` was)
    branch = re.compile(rf"(==|!=|\bin\b)\s*\(?\s*\"({names})\"|\"({names})\"\s*(==|!=)|args\.({names})\b")
    for path in [
        ROOT / "cli.py",
        ROOT / "apps" / "commands",
        ROOT / "evaluation.py",
        ROOT / "train",
        ROOT / "ros",
    ]:
        for file in [path] if path.is_file() else sorted(path.glob("*.py")):
            found = [line for line in file.read_text().splitlines() if branch.search(line)]
            assert not found, (file.name, found)


def test_runtime_benches_are_registered_and_load():
    from sparse_body.cli import build_parser

    benched = sorted(name for name, m in METHODS.items() if m.runtime_bench)
    assert benched == ["dragposer", "lobstr"]
    assert all(callable(load(METHODS[name].runtime_bench)) for name in benched)
    assert build_parser().parse_args(["bench", "--runtime", "lobstr"]).runtime == "lobstr"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench", "--runtime", "ik"])  # no runtime of its own to time


@pytest.mark.parametrize("name", sorted(METHODS))
def test_a_methods_code_lives_in_its_own_folder(name):
    """Its runtime in methods/NAME/, its training side (torch) in train/NAME/."""
    method = METHODS[name]
    assert method.estimator.startswith(f"sparse_body.methods.{name}."), method.estimator
    parts = method.training.parts if method.training else ()
    paths = [path for part in parts for path in (part.config, part.train)]
    assert all(path.startswith(f"sparse_body.train.{name}.") for path in paths), paths
    # nothing outside the folders is named after the method (the layout before the folders)
    for folder in ("estimators", "train"):
        assert not sorted((ROOT / folder).glob(f"{name}*.py"))


def test_listing_the_methods_imports_no_methods_code():
    import subprocess
    import sys

    code = (
        "import sys, sparse_body.methods as m; assert len(m.METHODS) == 9; "
        "print(sorted(k for k in sys.modules if k.startswith('sparse_body.methods.') and '.' in k[20:]) "
        "+ [k for k in ('torch', 'onnxruntime') if k in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out


def test_a_start_that_compiles_the_kernels_says_so_and_how_long_it_took(monkeypatch):
    """A cold first start of the node compiled for about a minute with nothing logged."""
    from sparse_body.methods import kernels

    assert kernels.kernels_cached()  # the setup compiled them: a start only loads
    lines: list[str] = []
    kernels.compile_kernels(("ik",), say=lines.append)
    assert lines == []  # cached: nothing to say
    monkeypatch.setattr(kernels, "kernels_cached", lambda: False)
    kernels.compile_kernels(("ik",), say=lines.append)
    assert len(lines) == 2 and lines[0].startswith("compiling the per-frame kernels once"), lines
    assert lines[1].startswith("compiled the per-frame kernels in "), lines


def test_auto_is_the_estimator_recommended_for_the_sensors_everywhere_one_is_named(tmp_path, capsys):
    """Every command and the node take the recommended estimator when none is named, and say
    which; its options pass to it."""
    from sparse_body.apps.offline import make_bag
    from sparse_body.cli import main
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.core.skeleton import Skeleton
    from sparse_body.data.synthetic import synthetic_walk
    from sparse_body.methods.factory import create_estimator
    from sparse_body.methods.recommended import RECOMMENDED, resolve_estimator

    assert resolve_estimator("auto:foot_lock=false", "four_point") == f"{RECOMMENDED['four_point']}:foot_lock=false"
    assert resolve_estimator("lobstr", "four_point") == "lobstr"
    sensors = load_sensor_config("four_point")
    estimator = create_estimator("auto", sensors, Skeleton.canonical(), foot_lock=False)
    assert estimator.name == RECOMMENDED["four_point"].partition(":")[0]
    make_bag(synthetic_walk(0.5), load_sensor_config("six_point"), tmp_path / "bag")
    with pytest.raises(SystemExit) as ended:
        main(["process", str(tmp_path / "bag"), str(tmp_path / "out"), "--quiet"])
    assert ended.value.code == 0
    assert f"estimator: {RECOMMENDED['six_point']}, recommended for six_point" in capsys.readouterr().out
