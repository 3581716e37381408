"""DTP's model card: its evaluations on the test split, written to measured JSON
(models/dtp.eval.json), then rendered with the training reports into models/dtp.md."""

from __future__ import annotations

import json
from pathlib import Path

from ...train.model_card import (
    FIELD_PROTOCOL,
    augmentation_table,
    evaluate_jobs,
    measured_results,
    render_card,
    results_table,
    runtime_choices_table,
    split_sizes,
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
    cfg = report["config"]

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
    text = render_card(
        Path(__file__).with_name("card.md"),
        {
            "model_file": f"{onnx_path.name}",
            "pretrained_model_file": f"{pretrained_path(onnx_path).name}",
            "cfg_past": f"{cfg['past']}",
            "lookahead_future": f"{(lookahead['config']['future'] if lookahead else 5)}",
            "cfg_fps": f"{cfg['fps']:.0f}",
            **split_sizes(),
            "report_train_clips": f"{report['train_clips']}",
            "cfg_augment": f"{cfg['augment']}",
            "cfg_variants": f"{cfg['variants']}",
            "report_train_frames": f"{report['train_frames']}",
            "report_validation_frames": f"{report['validation_frames']}",
            "occluded_percent": f"{cfg['occluded_share'] * 100:.0f}",
            "report_command": f"{report.get('command', 'sparse-body train dtp')}",
            "cfg_d_model": f"{cfg['d_model']}",
            "cfg_heads": f"{cfg['heads']}",
            "cfg_layers": f"{cfg['layers']}",
            "cfg_feedforward": f"{cfg['feedforward']}",
            "cfg_dropout": f"{cfg['dropout']}",
            "cfg_lr": f"{cfg['lr']}",
            "cfg_lr_half_every": f"{cfg['lr_half_every']}",
            "cfg_batch": f"{cfg['batch']}",
            "cfg_w_end_effector": f"{cfg['w_end_effector']}",
            "cfg_w_foot_velocity": f"{cfg['w_foot_velocity']}",
            "report_minutes": f"{report['minutes']:.1f}",
            "report_hardware": f"{report['hardware']}",
            "report_torch": f"{report['torch']}",
            "stages": f"{stage_lines(report)}",
            "lookahead_text": f"{lookahead_text}",
            "curve": f"{curve(report)}",
            "augmentation": f"{augmentation_table(onnx_path.with_suffix('.train.json'), VALIDATION)}",
            "field_protocol": f"{FIELD_PROTOCOL}",
            "field_table": f"{results_table(measured['field'])}",
            "lab_table": f"{results_table(measured['lab'])}",
            "occlusion_percent": f"{OCCLUSION_PERCENT:g}",
            "occluded_table": f"{results_table(measured['occluded'])}",
            "runtime_table": f"{runtime_choices_table(onnx_path.with_name('dtp.runtime.json'), RUNTIME_COMMAND, RUNTIME_METRICS)}",
            "runtime_occluded_table": f"{runtime_choices_table(onnx_path.with_name('dtp.runtime_occluded.json'), RUNTIME_COMMAND, RUNTIME_METRICS)}",
        },
    )
    path = onnx_path.with_suffix(".md")
    path.write_text(text)
    return path


def card(out: Path, mocap, limit: int | None, evaluate: bool = True) -> Path:
    """The record's card step (methods/record.Training.card)."""
    # one card: online, lookahead, pre-trained
    return write_dtp_card(out.with_name("dtp.onnx"), mocap, limit=limit, evaluate=evaluate)
