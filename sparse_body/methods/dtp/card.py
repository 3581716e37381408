"""DTP's model card: its evaluations on the test split, written to measured JSON
(models/dtp.eval.json), then rendered with the training reports into models/dtp.md."""

from __future__ import annotations

import json
from pathlib import Path

from ...data.catalog import load_split
from ...train.model_card import (
    FIELD_PROTOCOL,
    augmentation_table,
    evaluate_jobs,
    measured_results,
    results_table,
    runtime_choices_table,
)
from .train import pretrained_path

RUNTIME_COMMAND = (
    "sparse-body eval --sensors six_point --split validation --no-compare [--occlusion 20] "
    "--output models/dtp.runtime[_occluded].json --estimator dtp:OPTIONS ..."
)

RUNTIME_METRICS = ("MPJPE [cm]", "MPJVE [cm/s]", "Jitter [100m/s3]", "Toe PE [cm]")

OCCLUSION_PERCENT = 20.0
VALIDATION = {
    "clean_mpjpe_cm": "val MPJPE [cm]",
    "clean_mpjre_deg": "val MPJRE [deg]",
    "occluded_mpjpe_cm": "val feet occluded: MPJPE [cm]",
    "occluded_mpjre_deg": "MPJRE [deg]",
}
# (setup, estimator spec): each DTP model, then the six-point estimators it is compared with
FIELD_RUNS = ("dtp", "dtp:polish=false", "dtp:model=lookahead", "dtp:model=pretrained", "dragposer", "lobstr", "ik")
LAB_RUNS = ("dtp", "dtp:polish=false", "ik")
OCCLUDED_RUNS = ("dtp", "dtp:polish=false", "dtp:model=pretrained", "dtp:model=lookahead", "dragposer", "lobstr", "ik")
SETUPS = {"field": FIELD_RUNS, "lab": LAB_RUNS, "occluded": OCCLUDED_RUNS}


def _model_options(spec: str, onnx_path: Path) -> dict:
    """The model files beside onnx_path, not the package's, for the DTP specs."""
    if not spec.startswith("dtp"):
        return {}
    path = {
        "dtp": onnx_path,
        "dtp:polish=false": onnx_path,
        "dtp:model=lookahead": onnx_path.with_name("dtp_lookahead.onnx"),
        "dtp:model=pretrained": pretrained_path(onnx_path),
    }[spec]
    return {"model_path": str(path.resolve())}


def evaluate_dtp(onnx_path: Path, mocap_root: Path, limit: int | None = None, workers: int = 2) -> Path:
    """Run the card's evaluations (six-point, test split) two processes at a time and write
    them to <model>.eval.json: {setup: [sparse-body eval JSON of each run]}."""
    from ...data.field_protocol import FIELD, LAB, Protocol

    onnx_path = Path(onnx_path)
    # the paper's occlusion on the field without other failures: DTP's protocol, compared with its figures
    occluded = Protocol.named(occluded_percent=OCCLUSION_PERCENT)
    protocols = {"field": FIELD, "lab": LAB, "occluded": occluded}
    jobs = [
        (setup, spec, "six_point", protocols[setup], mocap_root, limit, _model_options(spec, onnx_path))
        for setup, specs in SETUPS.items()
        for spec in specs
    ]
    results = evaluate_jobs(jobs, workers)
    measured = {setup: [r.to_json() for j, r in zip(jobs, results, strict=True) if j[0] == setup] for setup in SETUPS}
    path = onnx_path.with_suffix(".eval.json")
    path.write_text(json.dumps(measured, indent=1))
    return path


def write_dtp_card(onnx_path: Path, mocap_root: Path, limit: int | None = None, evaluate: bool = True) -> Path:
    """Evaluate (unless evaluate=False and <model>.eval.json exists) and write <model>.md."""
    onnx_path = Path(onnx_path)
    measured = measured_results(onnx_path, evaluate_dtp, mocap_root, limit, evaluate)
    report = json.loads(onnx_path.with_suffix(".train.json").read_text())
    lookahead_path = onnx_path.with_name("dtp_lookahead.train.json")
    lookahead = json.loads(lookahead_path.read_text()) if lookahead_path.is_file() else None
    cfg, split = report["config"], load_split()

    def stage_lines(r: dict) -> str:
        return "\n".join(
            f"- {stage}: {s['steps']} steps in {s['minutes']:.1f} minutes; validation (exported weights, the network "
            f"alone, joints in the pelvis frame) "
            f"clean {s['validation']['clean_mpjpe_cm']:.2f} cm / {s['validation']['clean_mpjre_deg']:.2f} deg, "
            f"feet occluded {s['validation']['occluded_mpjpe_cm']:.2f} cm / "
            f"{s['validation']['occluded_mpjre_deg']:.2f} deg"
            for stage, s in r["stages"].items()
        )

    def curve(r: dict) -> str:
        rows = []
        for stage, s in r["stages"].items():
            history = s["history"]
            rows += [
                f"| {stage} | {h['step']} | {h['minutes']:.1f} | {h['total']:.4f} | {h['clean_mpjpe_cm']:.2f} | "
                f"{h['occluded_mpjpe_cm']:.2f} |"
                for h in history[:: max(1, len(history) // 8)]
            ]
        return "\n".join(rows)

    lookahead_text = (
        "(not trained: `sparse-body train dtp --config lookahead` writes it)"
        if lookahead is None
        else f"`{lookahead.get('command', '')}`, {lookahead['minutes']:.1f} minutes:\n"
        + stage_lines(lookahead).replace("- ", "  - ")
    )
    text = f"""# DTP model card: `{onnx_path.name}` (online), `dtp_lookahead.onnx`, `{pretrained_path(onnx_path).name}`

DTP, Deep Tracker Poser (Zeng et al.): headset and five trackers (pelvis, hands, feet) -> the 21
local joint rotations, through a two-layer embedding, a transformer encoder over a window of
frames and a linear decoder; fine-tuned on occluded feet. Runtime: ONNX Runtime over the
window each frame (`sparse_body/methods/dtp/estimator.py`); no torch.

- `{onnx_path.name}`: online ({cfg["past"]} past frames and the current one), occlusion fine-tuned: the node's default.
- `dtp_lookahead.onnx`: the paper's window with {lookahead["config"]["future"] if lookahead else 5} future frames, for offline processing (`dtp:model=lookahead`).
- `{pretrained_path(onnx_path).name}`: the online model before fine-tuning, kept to measure the fine-tuning
  (`dtp:model=pretrained`).

## Data
- CMU motion capture (allasfamc.zip from mocap.cs.cmu.edu: free use, no resale; indexed with `sparse-body import-mocap`), retargeted onto the
  22-joint body at {cfg["fps"]:.0f} fps, positions scaled to the canonical leg length, floor at z = 0.
- Split `config/splits/cmu.yaml` (by subject: no validation or test person in training):
  {len(split["train"])} train / {len(split["validation"])} validation / {len(split["test"])} test clips. Trained on {report["train_clips"]} train clips
  with augmented variants ({cfg["augment"]}: {cfg["variants"]} of each clip besides itself; {report["train_frames"]} frames
  in all), each clean and with LoBSTr's tracker noise; validated on {report["validation_frames"]} frames of the
  validation people (fixed windows, clean and with feet occluded).
- Occlusion fine-tuning (the paper's AMASS-OCC): in {cfg["occluded_share"] * 100:.0f} % of the windows one or both
  feet are occluded from a random frame on, reported as the origin with (near) identity rotation
  or as a position within a leg's length with a random rotation.

## Training
- Command: `{report.get("command", "sparse-body train dtp")}` (pre-training, then fine-tuning, one command).
- Width {cfg["d_model"]} (paper: 256), {cfg["heads"]} heads, {cfg["layers"]} layers, feed-forward {cfg["feedforward"]},
  dropout {cfg["dropout"]}; Adam lr {cfg["lr"]} halved every {cfg["lr_half_every"]} steps (paper: 1e-4 every
  10,000), batch {cfg["batch"]} windows, the loss on every frame of a window (causal attention);
  losses rotation + {cfg["w_end_effector"]} end effector + {cfg["w_foot_velocity"]} foot velocity (the paper's weights).
- {report["minutes"]:.1f} minutes on {report["hardware"]} (torch {report["torch"]}):
{stage_lines(report)}
- Lookahead model: {lookahead_text}

| stage | step | minutes | train loss | val clean [cm] | val feet occluded [cm] |
|---|---|---|---|---|---|
{curve(report)}

## Augmentation (the network alone, per-window errors in the pelvis frame)

{augmentation_table(onnx_path.with_suffix(".train.json"), VALIDATION)}

Shorter runs than the shipped model's (the steps column: pre-training and fine-tuning
together), so they show the early effect; read small differences with care.

## Test split, six-point (`sparse-body eval --estimator dtp --sensors six_point`)

{FIELD_PROTOCOL}:

{results_table(measured["field"])}

`dtp:polish=false` is the paper's method as it is (the network's rotations, no IK after it).
Lab protocol (`--protocol lab`, the papers' setting; the DTP paper reports
1.04 cm position error with the root aligned, 4.22 deg global rotation error, jitter 2.31
(100 m/s^3) on TotalCapture, trained on most of AMASS: a guide, not a like-for-like comparison):

{results_table(measured["lab"])}

## Feet occluded (`--protocol field-exact --occlusion {OCCLUSION_PERCENT:g}`: the paper's occlusion alone)

In about {OCCLUSION_PERCENT:g} % of the frames one or both foot trackers lose sight for half a second and
report the origin with the identity rotation or noise within a leg's length (both ways, equal
chances). Every estimator gets the same corrupted streams:

{results_table(measured["occluded"])}

## The polish, chosen on the validation people

The network's pose, then (ours, not the paper's) the closed-form IK brings head, hands and
the feet whose trackers agree with the network onto their trackers, and they take their
trackers' orientation. Its options were chosen
on the validation split, clean and with feet occluded (the test people were not looked at):

{runtime_choices_table(onnx_path.with_name("dtp.runtime.json"), RUNTIME_COMMAND, RUNTIME_METRICS)}

{runtime_choices_table(onnx_path.with_name("dtp.runtime_occluded.json"), RUNTIME_COMMAND, RUNTIME_METRICS)}

## Limits
- Trained on CMU only; the pelvis tracker must be there (it carries the root).
- The lookahead model needs frames at its rate (60 fps) offline; live it sees no future.
"""
    path = onnx_path.with_suffix(".md")
    path.write_text(text)
    return path
