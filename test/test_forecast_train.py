"""The learned root forecast's trainer (train/forecast.py, `make train-forecast`) on real
clips: a short run exports an ONNX model the runtime loads, its report and its card."""

import json

import numpy as np
import pytest


@pytest.mark.train
def test_a_short_training_exports_a_model_the_runtime_loads_with_its_report_and_card(tmp_path, train_mocap):
    from sparse_body.data.catalog import split_clips
    from sparse_body.estimators.forecast_model import RootForecastModel
    from sparse_body.train.forecast import main

    out = tmp_path / "forecast_root.onnx"
    assert main(["--config", "tiny", "--limit", "2", "--out", str(out), "--mocap", str(train_mocap)]) == 0
    model = RootForecastModel(out)
    move = model(np.tile([1.0, 0.0, 0.0], (model.lags, 1)), 0.1)
    assert move.shape == (3,) and np.isfinite(move).all()
    report = json.loads((tmp_path / "forecast_root.train.json").read_text())
    assert report["steps"] == 200 and report["validation"]["root_cm"] > 0
    names = {"present", "faded", "constant velocity", "learned root"}
    validation = [c.clip_id for c in split_clips(train_mocap, "validation", 2)]  # two, or the fixtures' one
    assert names <= set(report["forecasts"]["table"][0]) and len(report["forecasts"]["clips"]) == len(validation)
    card = (tmp_path / "forecast_root.md").read_text()
    assert "| all | 100 |" in card and "The test split is not read" in card


@pytest.mark.train
def test_the_mirrored_samples_mirror_the_moves():
    from sparse_body.train.forecast import samples

    frames = 20
    quats = np.tile([0.0, 0.0, 0.0, 1.0], (frames, 22, 1))
    clip = {
        "root": np.stack([np.arange(frames) * 0.02, np.arange(frames) * 0.01, np.ones(frames)], 1),
        "quats": quats,
        "valid": np.ones(frames, bool),
        "fps": 60.0,
    }
    plain, mirrored = samples(clip, 3, [6]), samples(clip, 3, [6], mirror=True)
    np.testing.assert_allclose(plain.move[:, 1], -mirrored.move[:, 1])
    np.testing.assert_allclose(plain.velocities[..., 0], mirrored.velocities[..., 0])
    np.testing.assert_allclose(plain.move[0], [0.12, 0.06, 0.0], atol=1e-9)
