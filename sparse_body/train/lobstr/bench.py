"""`sparse-body bench --runtime lobstr`: the network step, torch against ONNX Runtime (the record's runtime_bench)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np


def percentiles(times) -> str:
    ms = np.asarray(times) * 1000
    return f"p50 {np.percentile(ms, 50):6.3f} ms   p99 {np.percentile(ms, 99):6.3f} ms"


def bench_network(frames: int = 3000) -> None:
    """LoBSTr's per-frame network step on one core: torch against ONNX Runtime, for the small
    and the paper's sizes (random weights: the cost does not depend on their values), and the
    shipped model. One GRU step with the state carried, batch 1, as the estimator runs it."""
    import tempfile

    import torch

    from ...methods.lobstr.estimator import LobstrModel, default_model_path
    from ...methods.lobstr.features import feature_count
    from .model import LobstrConfig, LobstrNet, LobstrStep
    from .train import export_onnx

    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(frames, feature_count(True))).astype(np.float32)  # a model reads its first columns
    print(f"LoBSTr network step, {frames} frames, 1 thread (torch {torch.__version__})")

    def time_ort(model: LobstrModel):
        state, times = model.initial_state(), []
        for row in x[:, : model.features]:
            t0 = time.perf_counter()
            _, _, state = model.step(row, state)
            times.append(time.perf_counter() - t0)
        return times[100:]

    for name in ("small", "paper"):
        config = LobstrConfig.named(name)
        net = LobstrNet(config).eval()
        step = LobstrStep(net)
        state, times = torch.zeros(1, 1, config.hidden), []
        with torch.inference_mode():
            for row in torch.from_numpy(x[:, : feature_count(config.learned_upper)]):
                t0 = time.perf_counter()
                _, _, state = step(row[None], state)
                times.append(time.perf_counter() - t0)
        print(f"  {name:<6} hidden {config.hidden:<5} torch        {percentiles(times[100:])}")
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "lobstr.onnx"
            export_onnx(net, path, {"method": "lobstr", "config": config.to_dict()})
            print(f"  {name:<6} hidden {config.hidden:<5} onnxruntime  {percentiles(time_ort(LobstrModel(path)))}")
    if default_model_path().is_file():
        model = LobstrModel()
        shipped = f"shipped {default_model_path().name} (hidden {model.hidden})"
        print(f"  {shipped} onnxruntime  {percentiles(time_ort(model))}")
