"""The shared training loop (train/harness.py) through the real LoBSTr trainer on real clips:
checkpoints without pickle, resuming, the best weights kept."""

import json
from dataclasses import replace

import numpy as np
import onnxruntime as ort
import pytest


def quiet(*_):
    pass


@pytest.fixture(scope="module")
def tiny():
    from sparse_body.train.lobstr.model import LobstrConfig

    return replace(LobstrConfig.named("tiny"), steps=4, steps_per_epoch=2)


@pytest.mark.train
@pytest.mark.parametrize("method", ["lobstr", "avatarjlm", "dtp"])
def test_only_validation_or_the_selection_may_pick_the_weights(tmp_path, train_mocap, method, capsys):
    from sparse_body.cli import main

    out = tmp_path / "m.onnx"
    args = [
        "train",
        method,
        "--config",
        "tiny",
        "--limit",
        "1",
        "--out",
        str(out),
        "--no-card",
        "--mocap",
        str(train_mocap),
    ]
    with pytest.raises(SystemExit) as done:
        main([*args, "--set", "select_on=test"])
    assert done.value.code != 0 and not out.exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "select_on must be validation or selection, got 'test'" in err[0]


@pytest.mark.train
def test_an_interrupted_training_resumes_from_its_checkpoint(tmp_path, train_mocap, tiny):
    from sparse_body.train.harness import TrainRun
    from sparse_body.train.lobstr.train import train

    checkpoint = tmp_path / "lobstr.checkpoint.npz"
    first = train(tiny, TrainRun(train_mocap, tmp_path / "a.onnx", limit=2, log=quiet, checkpoint=checkpoint))
    assert [h["step"] for h in first["history"]] == [2, 4]
    with np.load(checkpoint, allow_pickle=False) as saved:  # plain arrays and a JSON state, no pickle
        state = json.loads(str(saved["state"]))
        assert state["step"] == 4 and any(k.startswith("best.") for k in saved.files)
    lines = []
    second = train(
        replace(tiny, steps=8),
        TrainRun(train_mocap, tmp_path / "b.onnx", limit=2, log=lines.append, checkpoint=checkpoint, resume=True),
    )
    assert any("resumed" in line and "step 4" in line for line in lines)
    assert second["steps"] == 8
    assert [h["step"] for h in second["history"]] == [2, 4, 6, 8]
    assert second["history"][:2] == first["history"]
    # the exported model is the best of all four checks, and says how it scored
    score = [h["lower_rot_error_deg"] / 10 + h["toe_error_cm"] / 10 for h in second["history"]]
    best = second["history"][int(np.argmin(score))]
    assert second["validation"]["toe_error_cm"] == pytest.approx(best["toe_error_cm"], rel=1e-5)
    meta = ort.InferenceSession(str(tmp_path / "b.onnx"), providers=["CPUExecutionProvider"]).get_modelmeta()
    assert json.loads(meta.custom_metadata_map["trained_steps"]) == 8


class Killed(Exception):
    """A run stopped mid-way, as a session's end stops one."""


def _weights(path):
    import onnx
    from onnx import numpy_helper

    return {i.name: numpy_helper.to_array(i) for i in onnx.load(str(path)).graph.initializer}


@pytest.mark.train
@pytest.mark.parametrize("method", ["lobstr", "avatarjlm"])
def test_a_resumed_training_goes_on_as_the_uninterrupted_run_would_have(tmp_path, train_mocap, method):
    """The optimiser's moments, the learning-rate schedule (LoBSTr's decay, AvatarJLM's drop at
    check 2, after the kill) and the batches' draws all go on from the checkpoint."""
    if method == "lobstr":
        from sparse_body.train.lobstr.model import LobstrConfig as Config
        from sparse_body.train.lobstr.train import train

        config = replace(Config.named("tiny"), steps=8, steps_per_epoch=2)
    else:
        from sparse_body.train.avatarjlm.model import AvatarJlmConfig as Config
        from sparse_body.train.avatarjlm.train import train

        config = replace(Config.named("tiny"), steps=8, steps_per_check=2, lr_drop_at=0.5)
    from sparse_body.train.harness import TrainRun

    whole = train(config, TrainRun(train_mocap, tmp_path / "whole.onnx", limit=1, log=quiet))

    def killed_at_step_4(line):
        if line.startswith("step 4 "):
            raise Killed  # before step 4's checkpoint: the one left is step 2's

    checkpoint = tmp_path / "m.checkpoint.npz"
    with pytest.raises(Killed):
        train(config, TrainRun(train_mocap, tmp_path / "a.onnx", limit=1, log=killed_at_step_4, checkpoint=checkpoint))
    lines = []
    resumed = train(
        config,
        TrainRun(train_mocap, tmp_path / "b.onnx", limit=1, log=lines.append, checkpoint=checkpoint, resume=True),
    )
    assert any(line.endswith("resumed from " + str(checkpoint) + " at step 2") for line in lines)

    def figures(report):
        return [{k: v for k, v in h.items() if k != "minutes"} for h in report["history"]]

    assert figures(resumed) == figures(whole)
    a, b = _weights(tmp_path / "whole.onnx"), _weights(tmp_path / "b.onnx")
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


@pytest.mark.train
def test_without_resume_a_checkpoint_is_overwritten_not_read(tmp_path, train_mocap, tiny):
    from sparse_body.train.harness import TrainRun
    from sparse_body.train.lobstr.train import train

    checkpoint = tmp_path / "lobstr.checkpoint.npz"
    train(tiny, TrainRun(train_mocap, tmp_path / "a.onnx", limit=2, log=quiet, checkpoint=checkpoint))
    again = train(tiny, TrainRun(train_mocap, tmp_path / "b.onnx", limit=2, log=quiet, checkpoint=checkpoint))
    assert [h["step"] for h in again["history"]] == [2, 4]


@pytest.mark.train
def test_a_checkpoint_of_another_configuration_is_refused_by_name(tmp_path, train_mocap, tiny):
    from sparse_body.train.harness import TrainRun
    from sparse_body.train.lobstr.train import train

    checkpoint = tmp_path / "lobstr.checkpoint.npz"
    train(tiny, TrainRun(train_mocap, tmp_path / "a.onnx", limit=2, log=quiet, checkpoint=checkpoint))
    with pytest.raises(ValueError, match="lobstr.checkpoint.npz: the checkpoint does not fit"):
        train(
            replace(tiny, hidden=24),
            TrainRun(train_mocap, tmp_path / "b.onnx", limit=2, log=quiet, checkpoint=checkpoint, resume=True),
        )


def test_the_dragposer_card_renders_its_runtime_choices_from_the_measured_file(tmp_path):
    from sparse_body.core.resources import models_dir
    from sparse_body.train.dragposer.card import RUNTIME_COMMAND, RUNTIME_METRICS
    from sparse_body.train.model_card import runtime_choices_table

    measured = json.loads((models_dir() / "dragposer.runtime.json").read_text())
    table = runtime_choices_table(models_dir() / "dragposer.runtime.json", RUNTIME_COMMAND, RUNTIME_METRICS)
    assert table.count("\n| `dragposer") == len(measured) >= 2
    default = next(r for r in measured if r["estimator"] == "dragposer")
    assert f"| `dragposer` | {len(default['clips'])} | {default['summary'][RUNTIME_METRICS[0]]:.2f} [" in table
    # each mean with its clip-bootstrap interval, which holds the mean
    cell = table.split("\n| `dragposer` | ")[1].split(" | ")[1]
    low, high = (float(x) for x in cell.split("[")[1].rstrip("]").split(", "))
    assert low <= default["summary"][RUNTIME_METRICS[0]] <= high and low < high
    assert "validation split" in table
    assert "missing" in runtime_choices_table(tmp_path / "dragposer.runtime.json", RUNTIME_COMMAND, RUNTIME_METRICS)


def test_the_lobstr_card_is_rendered_from_its_measured_file_alone(tmp_path):
    """With <model>.eval.json there, the card's tables come from it and nothing is evaluated
    (no motion capture is read): what the measured file says is what the card says."""
    import shutil

    from sparse_body.core.resources import models_dir
    from sparse_body.core.results import EvalResult
    from sparse_body.train.lobstr.card import FIELD_RUNS, LAB_RUNS, write_lobstr_card
    from sparse_body.train.model_card import NOISE_SETUPS

    def run(spec: str, scale: float, protocol: str = "field, vr noise") -> dict:
        metrics = ("MPJPE [cm]", "MPJVE [cm/s]", "Jitter [100m/s3]", "End-effector PE [cm]", "Skate [cm/s]")
        per_clip = [{m: scale * (k + 1) for k, m in enumerate(metrics)}] * 2
        return EvalResult(spec, "four_point", "test", ["a", "b"], [10, 10], per_clip, protocol=protocol).to_json()

    measured = {"field": [run(s, 1.0 + k) for k, s in enumerate(FIELD_RUNS)]}
    measured["lab"] = [run(s, 0.5, "lab") for s in LAB_RUNS]
    noise = {setup: [run("lobstr", 1.0 + k), run("ik", 2.0 + k)] for k, (setup, *_) in enumerate(NOISE_SETUPS)}
    measured["noise"] = {"four_point": noise}
    onnx = tmp_path / "lobstr.onnx"
    shutil.copy(models_dir() / "lobstr.train.json", tmp_path / "lobstr.train.json")
    (tmp_path / "lobstr.eval.json").write_text(json.dumps(measured))
    report = json.loads((tmp_path / "lobstr.train.json").read_text())
    text = write_lobstr_card(onnx, report, mocap_root=None, evaluate=False).read_text()
    # field runs 1 and 2, Skate = 5 x scale; the second holds no foot at all
    assert "Skate with contact IK: 5.00 cm/s; without it or any other hold" in text and "10.00 cm/s" in text
    assert "`lobstr:contact_ik=false,foot_lock=false`" in text
    # the shipped model kept the selection's weights, and its card says so
    assert "on the selection, the validation clips of kinds of motion no train clip has" in text
    assert "Selection (exported weights)" in text and "Contact labels (version 2" in text
    # two equal clips: each interval is the mean itself
    assert (
        "| lobstr/four_point | clean | 1.00 [1.00, 1.00] | 2.00 [2.00, 2.00] | 3.00 [3.00, 3.00] | 4.00 [4.00, 4.00] |"
        in text
    )
    assert "| | ratio | 3.00x | 3.00x | 3.00x | 3.00x |" in text  # smoothed (scale 3) over clean (1)
    assert "| ik/four_point | clean | 2.00 [2.00, 2.00] | 4.00 [4.00, 4.00] |" in text
    assert "lobstr:learned_upper=false" in text and "(lab)" in text
    assert write_lobstr_card(onnx, report, mocap_root=None, evaluate=False).read_text() == text


@pytest.mark.train  # `train --render-only` reads each method's configuration class (torch)
@pytest.mark.parametrize(
    "method, out, card",
    [
        ("lobstr", "lobstr.onnx", "lobstr.md"),
        ("dtp", "dtp.onnx", "dtp.md"),
        ("avatarjlm", "avatarjlm.onnx", "avatarjlm.md"),
        ("dragposer", "", "dragposer.md"),
    ],
)
def test_each_shipped_card_is_what_its_measured_json_renders_to(tmp_path, method, out, card):
    """`sparse-body train M --render-only` on copies of the shipped reports and measured JSON
    writes the shipped card again, character for character: every figure in a card is one in
    its <model>.eval.json (or another report beside it), and no motion capture is read."""
    import shutil

    from sparse_body.cli import build_parser
    from sparse_body.core.resources import models_dir

    for path in models_dir().glob("*.json"):
        shutil.copy(path, tmp_path / path.name)
    args = build_parser().parse_args(["train", method, "--render-only", "--out", str(tmp_path / out)])
    assert args.func(args) == 0
    assert (tmp_path / card).read_text() == (models_dir() / card).read_text()
