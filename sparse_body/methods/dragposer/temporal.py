"""DragPoser's temporal predictor at runtime (ONNX Runtime): every n frames it reads the
optimiser's own past latents and predicts the latent n frames ahead, which becomes the
optimiser's prior until the next prediction (the paper's Algorithm 1).

With `ramp` (the default; ours, not the paper's) the prior walks in a straight line from the
latent solved at the prediction's tick to the predicted one over the n frames, instead of
holding the prediction for all n. The paper takes one small gradient step a frame, so its
latent drifts towards the prediction; our Gauss-Newton step reaches a held target at once,
and the unconstrained limbs then jump every n frames (jitter; model card).

Every `ahead` predictions (the paper's W_f) the encoder gets a fresh past window and the
decoder restarts from the newest solved latent; in between, the decoder is fed its own
predictions, so with a large `ahead` it carries a motion (a walking cycle) through
ambiguity instead of copying the solved pose back. Until W_p steps of history exist (W_p x n
frames, about a second) there is no prediction and the caller falls back to its own prior.

The prediction (a transformer pass: 0.3 ms alone, 0.7 ms amid a frame's other work, most of
DragPoser's p99) runs in a worker thread and is taken up one frame later than it could be:
the frame after the tick still holds the previous prediction, and the ramp to the new one
starts at the second frame, at the share it would have had there. Live, that frame is 16 ms
of the worker's time; offline, the worker runs beside the next frame's search. The outcome
depends only on the frame count, never on the threads' timing (issue 52).
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ...estimators.onnx_model import load_model
from .pose import LATENT, temporal_context

FILE = "dragposer_temporal.onnx"


class TemporalPrior:
    def __init__(self, model_dir: str | Path, ahead: int = 1, threads: int = 1, ramp: bool = True) -> None:
        self.session, meta = load_model(
            Path(model_dir) / FILE,
            ("part", "temporal_predictor"),
            {"past_latents": LATENT, "past_context": None, "future_latents": LATENT},
            "train one with `sparse-body train dragposer --part temporal`, or set temporal_weight to 0",
            threads,
        )
        config = meta["config"]
        self.past, self.window, self.every = config["past"], config["future"], config["every"]
        if not 1 <= ahead <= self.window:
            raise ValueError(f"ahead must be between 1 and {self.window} (the model's W_f), got {ahead}")
        self.ahead, self.ramp = ahead, ramp
        self._worker = ThreadPoolExecutor(1, thread_name_prefix="dragposer_temporal")
        # the tick's run: (its future, which output step answers, the latent solved at the tick)
        self._pending: tuple[Future, int, np.ndarray] | None = None
        self._pending_age = 0  # frames observed since that tick
        self.prediction: np.ndarray | None = None
        self._anchor: np.ndarray | None = None  # the latent solved at the tick
        self.reset()

    def _settle(self) -> None:
        """Take up the prediction of the last tick (waiting for its run if it is not done)."""
        if self._pending is not None:
            future, step, anchor = self._pending
            self._pending = None
            self.prediction = future.result()[0][0, step].astype(np.float64)
            self._anchor, self._since = anchor, self._pending_age

    def reset(self) -> None:
        if self._pending is not None:  # a run under way ends before its inputs are forgotten
            self._pending[0].result()
            self._pending = None
        self._history: deque = deque(maxlen=self.past + 1)  # (z, root, yaw, heights), every n frames
        self._frames = 0
        self._past: tuple[np.ndarray, np.ndarray] | None = None  # the encoder's window
        self._decoder: list[np.ndarray] = []
        self.prediction = None
        self._anchor = None
        self._since = 0  # frames observed since the tick

    def target(self) -> np.ndarray | None:
        """The prior for the next frame: None until there is a prediction."""
        if self._pending is not None and self._pending_age >= 1:
            self._settle()
        if self.prediction is None or not self.ramp:
            return self.prediction
        share = min(self._since + 1, self.every) / self.every
        return self._anchor + share * (self.prediction - self._anchor)

    def observe(self, z: np.ndarray, root: np.ndarray, yaw: float, heights: np.ndarray) -> None:
        """The solved frame (root and heights in canonical-body units). Call once per frame."""
        tick = self._frames % self.every == 0
        self._frames += 1
        self._since += 1
        self._pending_age += 1
        if not tick:
            return
        self._settle()  # the last tick's, if no frame asked for it (every = 1)
        self._history.append(
            (np.asarray(z, np.float32), np.asarray(root, float), float(yaw), np.asarray(heights, float))
        )
        if len(self._history) <= self.past:
            return
        if self._past is None or len(self._decoder) >= self.ahead:
            steps = list(self._history)
            context = temporal_context(
                np.array([s[1] for s in steps]), np.array([s[2] for s in steps]), np.array([s[3] for s in steps])
            )[:-1]
            self._past = (np.stack([s[0] for s in steps[:-1]])[None], context[None].astype(np.float32))
            self._decoder = [steps[-1][0]]
        elif self.prediction is not None:
            self._decoder.append(self.prediction.astype(np.float32))
        future = np.zeros((1, self.window, LATENT), np.float32)
        future[0, : len(self._decoder)] = self._decoder
        feeds = {"past_latents": self._past[0], "past_context": self._past[1], "future_latents": future}
        run = self._worker.submit(self.session.run, None, feeds)
        self._pending, self._pending_age = (run, len(self._decoder) - 1, np.asarray(z, np.float64)), 0
