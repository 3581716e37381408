"""The shared training loop (train/harness.py) through the real LoBSTr trainer on real clips:
checkpoints without pickle, resuming, the best weights kept."""

import json
from dataclasses import replace

import numpy as np
import onnxruntime as ort
import pytest

from sparse_body.methods.lobstr.model import LobstrConfig
from sparse_body.methods.lobstr.train import train


def quiet(*_):
    pass


@pytest.fixture(scope="module")
def tiny():
    return replace(LobstrConfig.named("tiny"), steps=4, steps_per_epoch=2)


def test_an_interrupted_training_resumes_from_its_checkpoint(tmp_path, mocap_root, tiny):
    checkpoint = tmp_path / "lobstr.checkpoint.npz"
    first = train(tiny, mocap_root, tmp_path / "a.onnx", limit=2, log=quiet, checkpoint=checkpoint)
    assert [h["step"] for h in first["history"]] == [2, 4]
    with np.load(checkpoint, allow_pickle=False) as saved:  # plain arrays and a JSON state, no pickle
        state = json.loads(str(saved["state"]))
        assert state["step"] == 4 and any(k.startswith("best.") for k in saved.files)
    lines = []
    second = train(
        replace(tiny, steps=8),
        mocap_root,
        tmp_path / "b.onnx",
        limit=2,
        log=lines.append,
        checkpoint=checkpoint,
        resume=True,
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


def test_without_resume_a_checkpoint_is_overwritten_not_read(tmp_path, mocap_root, tiny):
    checkpoint = tmp_path / "lobstr.checkpoint.npz"
    train(tiny, mocap_root, tmp_path / "a.onnx", limit=2, log=quiet, checkpoint=checkpoint)
    again = train(tiny, mocap_root, tmp_path / "b.onnx", limit=2, log=quiet, checkpoint=checkpoint)
    assert [h["step"] for h in again["history"]] == [2, 4]


def test_a_checkpoint_of_another_configuration_is_refused_by_name(tmp_path, mocap_root, tiny):
    checkpoint = tmp_path / "lobstr.checkpoint.npz"
    train(tiny, mocap_root, tmp_path / "a.onnx", limit=2, log=quiet, checkpoint=checkpoint)
    with pytest.raises(ValueError, match="lobstr.checkpoint.npz: the checkpoint does not fit"):
        train(
            replace(tiny, hidden=24),
            mocap_root,
            tmp_path / "b.onnx",
            limit=2,
            log=quiet,
            checkpoint=checkpoint,
            resume=True,
        )


def test_the_dragposer_card_renders_its_runtime_choices_from_the_measured_file(tmp_path):
    from sparse_body.core.resources import models_dir
    from sparse_body.train.model_card import RUNTIME_METRICS, runtime_choices_table

    measured = json.loads((models_dir() / "dragposer.runtime.json").read_text())
    table = runtime_choices_table(models_dir() / "dragposer.runtime.json")
    assert table.count("\n| `dragposer") == len(measured) >= 2
    default = next(r for r in measured if r["estimator"] == "dragposer")
    assert f"| `dragposer` | {len(default['clips'])} | {default['summary'][RUNTIME_METRICS[0]]:.2f} |" in table
    assert "validation split" in table
    assert "missing" in runtime_choices_table(tmp_path / "dragposer.runtime.json")
