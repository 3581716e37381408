"""`sparse-body view RESULTS.json --clip NAME`: one clip of an evaluation, estimated again and drawn.

A results file keeps each clip's metrics, not its poses (those of every CMU clip would be
gigabytes). The page is made by running the same estimator on the same clip under the same
protocol and seed, which also checks the stored figure: the page's title and the command say
the clip's MPJPE now beside the one the file holds."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.results import EvalResult
from ..core.sensors import load_sensor_config
from ..data.catalog import DEFAULT_FPS
from ..data.field_protocol import Protocol
from ..data.motion_inputs import find_inputs
from ..estimators.base import parse_estimator_spec
from ..evaluation import Estimated, EvalItem, estimate_motion, file_items, score, split_items
from .viewer import ViewError, stream_trackers

METRIC = "MPJPE [cm]"
# what `view` can take from a result's settings (contact_labels: which labels its skate and contact
# figures used; the estimate does not depend on it)
RERUN_SETTINGS = {"fps", "per_joint", "contact_labels"}


@dataclass
class ClipView:
    """One clip of a results file, estimated again."""

    result: EvalResult
    run: Estimated
    stored: float  # the clip's METRIC in the file
    now: float  # and in this run

    @property
    def title(self) -> str:
        r = self.result
        return (
            f"{r.estimator} / {r.sensors} / {self.run.motion.name}: {METRIC} {self.now:.2f} (stored {self.stored:.2f})"
        )

    def parts(self) -> dict[str, np.ndarray]:
        """write_body_page's estimate, truth and trackers (NaN where a tracker had no position)."""
        return {
            "estimate": self.run.positions,
            "truth": self.run.motion.positions,
            "trackers": stream_trackers(self.run.view.stream, self.run.view.sensors),
        }


def find_clip(results: list[EvalResult], clip: str, estimator: str | None) -> tuple[EvalResult, int]:
    """The result and index of CLIP (a clip's name or key); with several estimators, the one named."""
    found = [
        (r, r.clips.index(clip) if clip in r.clips else r.keys.index(clip)) for r in results if clip in r.clips + r.keys
    ]
    if not found:
        names = sorted({c for r in results for c in r.clips})
        listed = ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else "")
        raise ViewError(f"no clip {clip!r} in the results; they hold {listed or 'no clips'}")
    if estimator is not None:
        found = [(r, k) for r, k in found if r.estimator == estimator]
        if not found:
            raise ViewError(f"clip {clip!r} has no result of estimator {estimator!r}")
    if len(found) > 1:
        choices = ", ".join(f"{r.estimator} ({r.sensors})" for r, _ in found)
        raise ViewError(f"clip {clip!r} has {len(found)} results: {choices}; choose one with --estimator")
    return found[0]


def _item(result: EvalResult, k: int, fps: float, mocap_root: Path | None) -> EvalItem:
    """The clip as the evaluation read it: the same file, its seed, its content."""
    key = result.keys[k]
    if result.split == "files":
        path, _, skeleton = result.sources[k].partition(" with ")
        spec = f"{path}={skeleton.rsplit(' (', 1)[0]}" if skeleton else path
        items = file_items(find_inputs([spec]), fps)
    else:
        if mocap_root is None:
            raise ViewError(f"the clip is of the CMU split {result.split!r}: give the motion capture folder (--mocap)")
        items = split_items(mocap_root, result.split, fps)
    item = next((i for i in items if i.key == key), None)
    if item is None:
        raise ViewError(f"{result.sources[k] or key}: not found as evaluated (moved, or its content changed since)")
    return item


def view_clip(results_path: Path, clip: str, estimator: str | None = None, mocap_root: Path | None = None) -> ClipView:
    """CLIP of the results file estimated again, as `eval` did (the file says how)."""
    results = [EvalResult.from_json(d) for d in json.loads(Path(results_path).read_text())]
    result, k = find_clip(results, clip, estimator)
    if not result.protocol_spec:
        raise ViewError(f"{results_path} was written before results said their protocol: run the eval again")
    if extra := sorted(set(result.settings) - RERUN_SETTINGS):
        raise ViewError(f"the result was made with options `view` cannot take again: {', '.join(extra)}")
    fps = float(result.settings.get("fps", DEFAULT_FPS))
    item = _item(result, k, fps, mocap_root)
    name, options = parse_estimator_spec(result.estimator)
    sensors = load_sensor_config(result.sensors)
    protocol = Protocol.from_json(result.protocol_spec)
    run = estimate_motion(item.load(), name, sensors, protocol, item.seed, **options)
    return ClipView(result, run, float(result.per_clip[k].get(METRIC, np.nan)), score(run)[METRIC])
