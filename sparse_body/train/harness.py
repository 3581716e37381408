"""What every trainer shares: the step loop under a step and time budget with periodic
validation and the best weights kept, a resumable checkpoint without pickle, ONNX metadata,
and the facts a model card reports about the machine.

A trainer is train(config, run): its configuration (a method's dataclass) and a TrainRun
(where the motion capture is, where the model goes, the seed, the checkpoint), the same for
all. It supplies its own step (a batch -> its loss terms), its validation (-> figures) and the
figure that picks the checkpoint; fit() does the rest in the same order for all of them.
"""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from ..data.catalog import SELECTION
from .model_card import beside  # noqa: F401 (the trainers' and the command's name for it)


@dataclass(frozen=True)
class TrainRun:
    """One training run's where and how, beside the method's configuration."""

    mocap_root: Path  # the motion capture (catalog.find_mocap_root)
    out: Path  # the .onnx file, or the folder of a method that writes several
    seed: int = 0  # torch's and the data's random draws
    limit: int | None = None  # only the first clips of each split (tests)
    log: Callable[[str], None] = print
    checkpoint: Path | None = None  # a .npz written at every check, to resume from
    resume: bool = False  # start from the checkpoint when it is there

    def start(self) -> np.random.Generator:
        """Seed torch; the run's numpy generator."""
        torch.manual_seed(self.seed)
        return np.random.default_rng(self.seed)


# the splits whose figures may keep a trainer's best weights (a configuration's select_on):
# the validation people's clips, or the selection, those of kinds of motion no train clip has
SELECT_ON = ("validation", SELECTION)


def use_threads(count: int) -> None:
    """Train on `count` CPU threads (torch's intra-op pool)."""
    torch.set_num_threads(count)


def held_out_split(select_on: str) -> str:
    """A configuration's select_on, refused before any data is read when it is not one of
    SELECT_ON (the test split never picks weights)."""
    if select_on not in SELECT_ON:
        raise ValueError(f"select_on must be {' or '.join(SELECT_ON)}, got {select_on!r}")
    return select_on


@dataclass
class Fitted:
    steps: int
    minutes: float
    validation: dict[str, float]  # of the weights kept
    history: list[dict] = field(default_factory=list)

    def report(self, config, run: TrainRun, **extra) -> dict:
        """What a model card reads of a training: the configuration, the budget spent, the kept
        weights' validation and the history, the train clips, then extra and the machine."""
        from ..data.catalog import split_clips

        return {
            "config": config.to_dict(),
            "steps": self.steps,
            "minutes": self.minutes,
            "validation": self.validation,
            "history": self.history,
            "train_clips": len(split_clips(run.mocap_root, "train", run.limit)),
            "augment": config.augment,
            **extra,
            **machine(),
        }


def fit(
    model: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    step: Callable[[], tuple[torch.Tensor, dict[str, float]]],
    validate: Callable[[], dict[str, float]],
    score: Callable[[dict[str, float]], float],
    *,
    steps: int,
    minutes: float,
    check_every: int,
    schedule: torch.optim.lr_scheduler.LRScheduler | None = None,
    rng: np.random.Generator | None = None,
    run: TrainRun,
) -> Fitted:
    """Train model until `steps` steps or `minutes` minutes (0: no time limit); every
    check_every steps (and at the last) validate, keep the weights with the lowest score, and
    log. step() runs the model on a batch and returns (loss, figures for the history);
    schedule (a learning-rate schedule) steps before each validation. The kept weights are
    loaded into model, which is left in eval mode.

    run.checkpoint: a .npz written at every check: the weights now and the best so far, the
    step, the history, the optimiser's moments and learning rates, the schedule's place and the
    random generators' states (rng: the one step() draws its batches from; torch's). run.resume
    starts from it, with `steps` counting from the start of the first run and `minutes` from this
    one, and goes on as the uninterrupted run would have: the same batches, the same learning
    rates, the same weights (a session that ends mid-run loses nothing but time)."""
    best, best_state, history = float("inf"), None, []
    start, done = time.perf_counter(), 0
    checkpoint, log = run.checkpoint, run.log
    if run.resume and checkpoint is not None and Path(checkpoint).is_file():
        done, best, best_state, history, whole = _restore(model, Path(checkpoint), optimizer, schedule, rng)
        # a checkpoint of the first format holds the weights alone: the optimiser starts afresh
        log(
            f"resumed from {checkpoint} at step {done}"
            + ("" if whole else " (weights only: the optimiser starts afresh)")
        )
    while done < steps and not (minutes and time.perf_counter() - start > 60 * minutes):
        model.train()
        loss, figures = step()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        done += 1
        if done % check_every == 0 or done == steps:
            if schedule is not None:
                schedule.step()
            model.eval()
            val = validate()
            history.append({"step": done, "minutes": (time.perf_counter() - start) / 60, **figures, **val})
            if score(val) < best:
                best, best_state = score(val), {k: v.clone() for k, v in model.state_dict().items()}
            log(
                f"step {done} ({history[-1]['minutes']:.1f} min) "
                + " ".join(f"{k} {v:.4g}" for k, v in figures.items())
                + " | val "
                + " ".join(f"{k} {v:.4g}" for k, v in val.items())
            )
            if checkpoint is not None:
                _save_checkpoint(Path(checkpoint), model, best_state, done, best, history, optimizer, schedule, rng)
    model.load_state_dict(best_state or model.state_dict())
    model.eval()
    return Fitted(done, (time.perf_counter() - start) / 60, validate(), history)


def _save_checkpoint(
    path: Path, model, best_state, step: int, best: float, history: list[dict], optimizer, schedule, rng
) -> None:
    arrays = {f"now.{k}": v.detach().cpu().numpy() for k, v in model.state_dict().items()}
    arrays.update({f"best.{k}": v.cpu().numpy() for k, v in (best_state or {}).items()})
    opt = optimizer.state_dict()
    for i, slots in opt["state"].items():  # Adam's moments and step count, one array each
        arrays.update({f"opt.{i}.{k}": torch.as_tensor(v).cpu().numpy() for k, v in slots.items()})
    arrays["torch_rng"] = torch.get_rng_state().numpy()
    state = {
        "step": step,
        "best": best,
        "history": history,
        "param_groups": opt["param_groups"],  # learning rates and the optimiser's settings
        "schedule": schedule.state_dict() if schedule is not None else None,
        "rng": rng.bit_generator.state if rng is not None else None,
    }
    tmp = path.with_name(path.name + ".tmp.npz")  # a crash mid-write keeps the last one
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(tmp, state=np.array(json.dumps(state)), **arrays)
    tmp.replace(path)


def _restore(model, path: Path, optimizer=None, schedule=None, rng=None):
    """The checkpoint's step, best score, best weights and history, its weights loaded into model;
    with optimizer, schedule and rng, theirs too where the checkpoint has them (whole: it had)."""
    with np.load(path, allow_pickle=False) as saved:
        state = json.loads(str(saved["state"]))
        now = {k[4:]: torch.from_numpy(saved[k]) for k in saved.files if k.startswith("now.")}
        best = {k[5:]: torch.from_numpy(saved[k]) for k in saved.files if k.startswith("best.")} or None
        slots: dict[int, dict] = {}
        for k in saved.files:
            if k.startswith("opt."):
                _, i, name = k.split(".", 2)
                slots.setdefault(int(i), {})[name] = torch.from_numpy(saved[k])
        torch_rng = torch.from_numpy(saved["torch_rng"]) if "torch_rng" in saved.files else None
    try:
        model.load_state_dict(now)
    except RuntimeError as err:  # another configuration's weights (sizes, names)
        raise ValueError(
            f"{path}: the checkpoint does not fit this configuration "
            f"(train it afresh without --resume): {str(err).splitlines()[0]}"
        ) from None
    whole = "param_groups" in state
    if whole and optimizer is not None:
        groups = [{**g, "betas": tuple(g["betas"])} if "betas" in g else g for g in state["param_groups"]]
        optimizer.load_state_dict({"state": slots, "param_groups": groups})
    if whole and schedule is not None and state["schedule"] is not None:
        schedule.load_state_dict(state["schedule"])
    if whole and rng is not None and state["rng"] is not None:
        rng.bit_generator.state = state["rng"]
    if torch_rng is not None and optimizer is not None:
        torch.set_rng_state(torch_rng)
    return state["step"], state["best"], best, state["history"], whole


def load_best(model: torch.nn.Module, checkpoint: Path) -> None:
    """The best weights a checkpoint kept, into model (a stage already finished)."""
    _, _, best_state, _, _ = _restore(model, Path(checkpoint))
    model.load_state_dict(best_state or model.state_dict())
    model.eval()


def with_earlier_runs(report: dict, earlier: dict | None) -> dict:
    """A resumed run's report (train.json) keeps the runs before it, their command, steps and
    minutes, so that a model card can say how the model was trained from the start."""
    if earlier is not None:
        report["earlier_runs"] = earlier.get("earlier_runs", []) + [
            {k: earlier[k] for k in ("command", "steps", "minutes") if k in earlier}
        ]
    return report


def export_onnx(
    module: torch.nn.Module,
    example: tuple,
    path: Path,
    inputs: list[str],
    outputs: list[str],
    metadata: dict,
    dynamic_axes: dict | None = None,
) -> None:
    """module (in eval mode) traced on the example inputs into an ONNX file (opset 17) with the
    metadata a runtime reads its configuration from: the one way every trainer exports."""
    import warnings

    module.eval()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():  # the tracer's notes on shape checks, the legacy exporter's notice
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            module,
            example,
            str(path),
            input_names=inputs,
            output_names=outputs,
            dynamic_axes=dynamic_axes,
            opset_version=17,
            dynamo=False,
        )
    add_metadata(path, metadata)


def add_metadata(onnx_path: Path, metadata: dict) -> None:
    """Each value JSON-encoded into the ONNX file's metadata (the runtime's configuration)."""
    import onnx

    graph = onnx.load(str(onnx_path))
    for key, value in metadata.items():
        graph.metadata_props.add(key=key, value=json.dumps(value))
    onnx.save(graph, str(onnx_path))


def machine() -> dict[str, str]:
    """What a model card says the model was trained on."""
    return {
        "hardware": f"{platform.processor() or platform.machine()}, {torch.get_num_threads()} torch threads",
        "torch": torch.__version__,
    }
