"""The learned root forecast of predict_ahead (core/forecast.py says what it does) run from its
ONNX file: the root's recent velocities in the heading frame and the seconds ahead in, the
root's move out. Trained by train/forecast.py (`make train-forecast`); its configuration (how
many velocities it reads, the frame rate it was trained at) is in the file's metadata."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .onnx_model import load_model

FILE = "forecast_root.onnx"
KIND = ("model", "forecast_root")


class RootForecastModel:
    """model(velocities (lags, 3), ahead) -> move (3,), as core/forecast.RootModel."""

    def __init__(self, path: str | Path | None = None) -> None:
        from ..core.resources import models_dir

        path = Path(path) if path else models_dir() / FILE
        self.session, meta = load_model(
            path, KIND, {"velocities": 3, "ahead": None}, "make train-forecast trains it, or forecast=faded"
        )
        self.lags = int(meta["lags"])

    def __call__(self, velocities: np.ndarray, ahead: float) -> np.ndarray:
        feed = {
            "velocities": np.asarray(velocities, np.float32).reshape(1, self.lags, 3),
            "ahead": np.array([ahead], np.float32),
        }
        return self.session.run(None, feed)[0][0].astype(np.float64)
