"""AvatarJLM's model card: its evaluations on the test split written to measured JSON
(models/avatarjlm.eval.json), then rendered with the training reports into models/avatarjlm.md."""

from __future__ import annotations

import json
from pathlib import Path

from ...train.model_card import (
    FIELD_PROTOCOL,
    LOSS_COLUMNS,
    augmentation_table,
    evaluate_jobs,
    measured_results,
    render_card,
    results_table,
    runtime_choices_table,
    split_sizes,
)

COLUMNS = (
    "MPJPE [cm]",
    "MPJRE [deg]",
    "MPJVE [cm/s]",
    "Jitter [100m/s3]",
    "Hand PE [cm]",
    "Lower PE [cm]",
    "Toe PE [cm]",
    *LOSS_COLUMNS,
)
VALIDATION = {
    "mpjpe_cm": "val MPJPE [cm]",
    "lower_pe_cm": "val lower PE [cm]",
    "hand_pe_cm": "val hands [cm]",
    "mpjre_deg": "val MPJRE [deg]",
}
RUNTIME_METRICS = ("MPJPE [cm]", "MPJRE [deg]", "Lower PE [cm]", "MPJVE [cm/s]", "Jitter [100m/s3]", "Toe PE [cm]")
RUNTIME_COMMAND = (
    "sparse-body eval --sensors three_point --split validation --no-compare "
    "--output models/avatarjlm.runtime.json --estimator avatarjlm:OPTIONS ..."
)
# (sensors, protocol) -> the estimator specs measured there
SETUPS = {
    ("three_point", "field"): ("avatarjlm", "avatarjlm:polish=false", "dragposer", "ik"),
    ("three_point", "lab"): ("avatarjlm", "avatarjlm:polish=false", "dragposer", "ik"),
    ("four_point", "field"): (
        "avatarjlm",
        "avatarjlm:polish=false",
        "avatarjlm:model=three_point",
        "dragposer",
        "lobstr",
        "ik",
    ),
    ("four_point", "lab"): ("avatarjlm", "avatarjlm:polish=false", "dragposer", "ik"),
}


def four_point_path(onnx_path: Path) -> Path:
    return Path(onnx_path).with_name(Path(onnx_path).stem + "_four_point.onnx")


def _model_options(spec: str, sensors: str, onnx_path: Path) -> dict:
    """The model files beside onnx_path, not the package's, for the AvatarJLM specs."""
    if not spec.startswith("avatarjlm"):
        return {}
    path = onnx_path if sensors == "three_point" or "model=three_point" in spec else four_point_path(onnx_path)
    return {"model_path": str(path.resolve())}


def evaluate_avatarjlm(onnx_path: Path, mocap_root: Path, limit: int | None = None, workers: int = 2) -> Path:
    """Run the card's evaluations two processes at a time and write <model>.eval.json:
    {"sensors/protocol": [sparse-body eval JSON of each run]}."""
    from ...data.field_protocol import FIELD, LAB

    onnx_path = Path(onnx_path)
    protocols = {"field": FIELD, "lab": LAB}
    jobs = [
        (
            f"{sensors}/{protocol}",
            spec,
            sensors,
            protocols[protocol],
            mocap_root,
            limit,
            _model_options(spec, sensors, onnx_path),
        )
        for (sensors, protocol), specs in SETUPS.items()
        for spec in specs
    ]
    results = evaluate_jobs(jobs, workers)
    measured: dict[str, list[dict]] = {}
    for job, result in zip(jobs, results, strict=True):
        measured.setdefault(job[0], []).append(result.to_json())
    path = onnx_path.with_suffix(".eval.json")
    path.write_text(json.dumps(measured, indent=1))
    return path


def _training(report: dict | None, name: str) -> str:
    if report is None:
        return f"- `{name}`: not trained (`sparse-body train avatarjlm --config four_point` writes it)"
    v, c = report["validation"], report["config"]
    earlier = report.get("earlier_runs", [])
    runs = "".join(f"`{r['command']}` ({r['steps']} steps, {r['minutes']:.1f} minutes), then " for r in earlier)
    minutes = report["minutes"] + sum(r["minutes"] for r in earlier)
    resumed = f" (resumed from its last checkpoint: {report['minutes']:.1f} minutes more)" if earlier else ""
    return (
        f"- `{name}` ({c['sensors']}): {runs}`{report.get('command', 'sparse-body train avatarjlm')}`{resumed}; "
        f"{report['steps']} steps in {minutes:.1f} minutes on {report['hardware']} "
        f"(torch {report['torch']}); validation (last frame of fixed sequences, clean trackers, canonical "
        f"body, before the polish): MPJPE {v['mpjpe_cm']:.2f} cm, hands {v['hand_pe_cm']:.2f} cm, lower body "
        f"{v['lower_pe_cm']:.2f} cm, rotation {v['mpjre_deg']:.2f} deg"
    )


def _curve(report: dict) -> str:
    """Every eighth check; minutes count from the first run's start (a resumed run's own
    history starts its clock at zero)."""
    h: list[dict] = []
    earlier, restarts = [r["minutes"] for r in report.get("earlier_runs", [])], 0
    for r in report["history"]:
        if h and r["minutes"] < h[-1]["minutes"] - sum(earlier[:restarts]):
            restarts += 1
        h.append({**r, "minutes": r["minutes"] + sum(earlier[:restarts])})
    rows = h[:: max(1, len(h) // 8)]
    rows += [] if rows[-1] is h[-1] else h[-1:]
    return "\n".join(
        f"| {r['step']} | {r['minutes']:.1f} | {r['total']:.3f} | {r['mpjpe_cm']:.2f} | {r['hand_pe_cm']:.2f} |"
        for r in rows
    )


def write_avatarjlm_card(onnx_path: Path, mocap_root: Path, limit: int | None = None, evaluate: bool = True) -> Path:
    """Evaluate (unless evaluate=False and <model>.eval.json exists) and write <model>.md."""
    onnx_path = Path(onnx_path)
    measured = measured_results(onnx_path, evaluate_avatarjlm, mocap_root, limit, evaluate)
    report = json.loads(onnx_path.with_suffix(".train.json").read_text())
    four_report_path = four_point_path(onnx_path).with_suffix(".train.json")
    four = json.loads(four_report_path.read_text()) if four_report_path.is_file() else None
    c = report["config"]

    def table(key: str) -> str:
        return results_table(measured[key], COLUMNS) if key in measured else "(not measured)"

    text = render_card(
        Path(__file__).with_name("card.md"),
        {
            "model_file": f"{onnx_path.name}",
            "four_point_model_file": f"{four_point_path(onnx_path).name}",
            "c_fps": f"{c['fps']:.0f}",
            **split_sizes(),
            "report_train_clips": f"{report['train_clips']}",
            "c_augment": f"{c['augment']}",
            "c_variants": f"{c['variants']}",
            "report_train_frames": f"{report['train_frames']}",
            "report_validation_frames": f"{report['validation_frames']}",
            "c_d_embed": f"{c['d_embed']}",
            "c_d_model": f"{c['d_model']}",
            "c_heads": f"{c['heads']}",
            "c_loops": f"{c['loops']}",
            "c_feedforward": f"{c['feedforward']}",
            "c_dropout": f"{c['dropout']}",
            "frames_attended": f"{c['window'] - 1}",
            "c_sequence": f"{c['sequence']}",
            "c_batch": f"{c['batch']}",
            "c_lr": f"{c['lr']}",
            "c_lr_drop_at": f"{c['lr_drop_at']:.0%}",
            "c_masked_tokens": f"{c['masked_tokens']}",
            "c_beta": f"{c['beta']:g}",
            "c_leg_weight": f"{c.get('leg_weight', 0.0):g}",
            "training_three_point": f"{_training(report, onnx_path.name)}",
            "training_four_point": f"{_training(four, four_point_path(onnx_path).name)}",
            "curve": f"{_curve(report)}",
            "augmentation": f"{augmentation_table(onnx_path.with_suffix('.train.json'), VALIDATION)}",
            "report_steps": f"{report['steps']}",
            "field_protocol": f"{FIELD_PROTOCOL}",
            "three_point_field_table": f"{table('three_point/field')}",
            "three_point_lab_table": f"{table('three_point/lab')}",
            "four_point_field_table": f"{table('four_point/field')}",
            "four_point_lab_table": f"{table('four_point/lab')}",
            "runtime_table": f"{runtime_choices_table(onnx_path.with_name('avatarjlm.runtime.json'), RUNTIME_COMMAND, RUNTIME_METRICS)}",
        },
    )
    path = onnx_path.with_suffix(".md")
    path.write_text(text)
    return path


def card(out: Path, mocap, limit: int | None, evaluate: bool = True) -> Path:
    """The record's card step (methods/record.Training.card)."""
    # one card: both models
    return write_avatarjlm_card(out.with_name("avatarjlm.onnx"), mocap, limit=limit, evaluate=evaluate)
