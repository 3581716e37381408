"""DragPoser's model card: the paper's Table 2 setups with the Table 3 ablation and the IK
baseline, and the refinement of other estimators. Its evaluations are written to measured
JSON (models/dragposer.eval.json), then rendered with the training reports into
models/dragposer.md."""

from __future__ import annotations

import json
from pathlib import Path

from ...train.model_card import (
    FIELD_PROTOCOL,
    NOISE_HEADING,
    augmentation_table,
    measure_card,
    measured_results,
    noise_jobs,
    noise_table,
    render_card,
    split_sizes,
)
from ...train.model_card import runtime_choices_table as choices_table

RUNTIME_METRICS = ("MPJPE [cm]", "MPJVE [cm/s]", "Jitter [100m/s3]", "Toe PE [cm]")
RUNTIME_COMMAND = (
    "sparse-body eval --sensors four_point --split validation --no-compare "
    "--output models/dragposer.runtime.json --estimator dragposer:OPTIONS ..."
)
ROOT_PRIOR_COMMAND = (
    "sparse-body eval --split validation --no-compare --sensors three_point --estimator dragposer "
    "--estimator dragposer:root_prior=0 --estimator dragposer:root_prior=0.1 "
    "--estimator dragposer:root_prior=1 --output models/dragposer.root_prior.json"
)
TRACKER_PRIOR_COMMAND = (
    "sparse-body eval --split validation --no-compare --sensors {sensors} "
    "--estimator dragposer:tracker_prior=0 --estimator dragposer:tracker_prior=0.001 ... "
    "(each row's spec) --output models/dragposer.tracker_prior_{sensors}.json"
)
TRACKER_PRIOR_VALIDATION = {
    "mse": "val latent MSE",
    "pe": "val decoded PE [cm]",
    "lower_pe": "val decoded lower PE [cm]",
}
VAE_VALIDATION = {"position_error_cm": "val position [cm]", "rotation_error_deg": "val rotation [deg]"}
TEMPORAL_VALIDATION = {"mse": "val MSE", "mse_next": "val MSE, next step", "hold_mse": "holding: MSE"}


DRAGPOSER_SETUPS = [
    ("six_point", 0.0),
    ("four_point", 0.0),
    ("three_point", 0.0),
    ("hip_hands", 0.0),
    ("six_point", 1.0),
]
ABLATION_SETUPS = set(DRAGPOSER_SETUPS)  # every setup also runs without the temporal predictor
REFINED_BASES = ["ik", "lobstr"]  # refined on four-point


NOISE_SENSORS = ("six_point", "four_point")


def setup_key(sensors_name: str, faulty: float) -> str:
    """A setup's key in the measured JSON."""
    return f"{sensors_name}, faulty {faulty:g} %" if faulty else sensors_name


def evaluate_dragposer(onnx_path: Path, mocap_root: Path, limit: int | None = None, workers: int = 2) -> Path:
    """Run the card's evaluations (test split) `workers` processes at a time and write them to
    dragposer.eval.json beside onnx_path (the models' folder): {setup: [sparse-body eval JSON
    of each run]} for the setups (field protocol, the lab's beside it), "refined" ([base,
    refined base, ...] on four-point) and "noise" ({sensors: noise_jobs()' setups})."""
    from ...data.field_protocol import FIELD, Protocol

    out_dir = Path(onnx_path).parent
    mine = {"model_path": str(out_dir.resolve())}
    jobs = []
    for setup in DRAGPOSER_SETUPS:
        sensors_name, faulty = setup
        key = setup_key(sensors_name, faulty)
        # the paper's faulty sensors on the field without other failures: its protocol, compared with its figures
        field = Protocol.named("calibrated", "vr", faulty) if faulty else FIELD
        lab = Protocol.named("oracle", "none", faulty)
        specs = ["dragposer"] + (["dragposer:temporal_weight=0"] if setup in ABLATION_SETUPS else [])
        jobs += [(key, spec, sensors_name, field, mocap_root, limit, mine) for spec in specs]
        jobs.append((key, "ik", sensors_name, field, mocap_root, limit, {}))
        jobs += [
            (key, "dragposer", sensors_name, lab, mocap_root, limit, mine),
            (key, "ik", sensors_name, lab, mocap_root, limit, {}),
        ]
    for base in REFINED_BASES:  # the refinement's other estimators come from the package (lobstr.onnx)
        jobs += [
            ("refined", base, "four_point", FIELD, mocap_root, limit, {}),
            ("refined", f"refined:base={base}", "four_point", FIELD, mocap_root, limit, mine),
        ]
    noise = {name: noise_jobs([("dragposer", mine), ("ik", {})], name, mocap_root, limit) for name in NOISE_SENSORS}
    return measure_card(out_dir / "dragposer.eval.json", jobs, noise, workers)


def write_dragposer_card(out_dir: Path, mocap_root: Path, limit: int | None = None, evaluate: bool = True) -> Path:
    """Evaluate (unless evaluate=False and dragposer.eval.json exists: the pose VAE + temporal
    predictor + optimiser on the test split for the paper's Table 2 setups, with the Table 3
    ablation and the IK baseline, and the refinement of other estimators) and write
    dragposer.md."""
    from ...core.results import EvalResult, format_table
    from ...methods import paper_figures

    out_dir = Path(out_dir)
    vae = json.loads((out_dir / "dragposer.train.json").read_text())
    temporal = json.loads((out_dir / "dragposer_temporal.train.json").read_text())
    tracker = json.loads((out_dir / "dragposer_tracker_prior.train.json").read_text())
    from ...methods.dragposer.options import TRACKER_PRIOR_WEIGHT

    measured = measured_results(out_dir / "dragposer.onnx", evaluate_dragposer, mocap_root, limit, evaluate)
    refined = [EvalResult.from_json(r) for r in measured["refined"]]
    noise_tables = [noise_table(measured["noise"][name]) for name in NOISE_SENSORS]
    text_tables = []
    for sensors_name, faulty in DRAGPOSER_SETUPS:
        title = setup_key(sensors_name, faulty)
        results = [EvalResult.from_json(r) for r in measured[title]]
        text_tables.append(
            f"### {title}\n\n```\n{format_table(results, paper_figures('dragposer', sensors_name, faulty))}\n```\n"
        )
    cfg, val = vae["config"], vae["validation"]
    tcfg, tval = temporal["config"], temporal["validation"]
    vae_augmentation = augmentation_table(out_dir / "dragposer.train.json", VAE_VALIDATION)
    runtime_table = choices_table(out_dir / "dragposer.runtime.json", RUNTIME_COMMAND, RUNTIME_METRICS)
    pelvis_tables = "\n\n".join(
        choices_table(
            out_dir / f"dragposer.pelvis_{name}.json",
            f"sparse-body eval --split validation --no-compare --sensors {name} --estimator dragposer "
            f"--estimator dragposer:pelvis_orientation=false --output models/dragposer.pelvis_{name}.json",
            ("MPJPE [cm]", "MPJRE [deg]", "Lower PE [cm]", "MPJVE [cm/s]", "Jitter [100m/s3]"),
        )
        for name in ("six_point", "four_point")
    )
    root_prior_table = choices_table(
        out_dir / "dragposer.root_prior.json",
        ROOT_PRIOR_COMMAND,
        ("MPJPE [cm]", "MPJRE [deg]", "Lower PE [cm]", "Root PE [cm]", "MPJVE [cm/s]", "Jitter [100m/s3]"),
    )
    temporal_augmentation = augmentation_table(out_dir / "dragposer_temporal.train.json", TEMPORAL_VALIDATION)
    tracker_tables = "\n\n".join(
        choices_table(
            out_dir / f"dragposer.tracker_prior_{name}.json",
            TRACKER_PRIOR_COMMAND.format(sensors=name),
            ("MPJPE [cm]", "MPJRE [deg]", "Lower PE [cm]", "MPJVE [cm/s]", "Jitter [100m/s3]", "Ground [cm]"),
        )
        for name in ("six_point", "four_point", "three_point")
    )
    tracker_augmentation = augmentation_table(out_dir / "dragposer_tracker_prior.train.json", TRACKER_PRIOR_VALIDATION)
    pcfg, pval = tracker["config"], tracker["validation"]

    def mpjpe(setup: str, run: int = 0) -> str:  # a field run's MPJPE: 0 DragPoser, 1 without the predictor
        return f"{measured[setup][run]['summary']['MPJPE [cm]']:.2f}"

    def curve(history, columns):
        rows = history[:: max(1, len(history) // 12)]
        return "\n".join(
            "| " + " | ".join(f"{h[c]:.4f}" if isinstance(h[c], float) else str(h[c]) for c in columns) + " |"
            for h in rows
        )

    extrapolated = (
        f"; carrying on half the last step's change: {tval['extrapolate_mse_next']:.4f} for the next step"
        if "extrapolate_mse_next" in tval
        else ""
    )
    text = render_card(
        Path(__file__).with_name("card.md"),
        {
            **split_sizes(),
            "vae_train_frames": f"{vae['train_frames']}",
            "vae_command": f"{vae.get('command', 'sparse-body train dragposer')}",
            "cfg_hidden": f"{cfg['hidden']}",
            "cfg_latent": f"{cfg['latent']}",
            "cfg_lr": f"{cfg['lr']}",
            "cfg_weight_decay": f"{cfg['weight_decay']}",
            "cfg_batch": f"{cfg['batch']}",
            "cfg_w_fk": f"{cfg['w_fk']:g}",
            "cfg_w_kld": f"{cfg['w_kld']:g}",
            "cfg_w_continuity": f"{cfg['w_continuity']:g}",
            "vae_steps": f"{vae['steps']}",
            "vae_minutes": f"{vae['minutes']:.1f}",
            "vae_hardware": f"{vae['hardware']}",
            "vae_torch": f"{vae['torch']}",
            "vae_curve": f"{curve(vae.get('history', []), ['step', 'minutes', 'total', 'position_error_cm', 'rotation_error_deg'])}",
            "val_position_error_cm": f"{val['position_error_cm']:.2f}",
            "val_rotation_error_deg": f"{val['rotation_error_deg']:.2f}",
            "cfg_augment": f"{cfg.get('augment', 'none')}",
            "cfg_variants": f"{cfg.get('variants', 0)}",
            "vae_augmentation": f"{vae_augmentation}",
            "temporal_command": f"{temporal.get('command', 'sparse-body train dragposer --part temporal')}",
            "tcfg_every": f"{tcfg['every']}",
            "tcfg_width": f"{tcfg['width']}",
            "tcfg_heads": f"{tcfg['heads']}",
            "tcfg_layers": f"{tcfg['layers']}",
            "tcfg_feedforward": f"{tcfg['feedforward']}",
            "tcfg_past": f"{tcfg['past']}",
            "tcfg_future": f"{tcfg['future']}",
            "temporal_parameters": f"{temporal['parameters']}",
            "tcfg_lr": f"{tcfg['lr']}",
            "tcfg_batch": f"{tcfg['batch']}",
            "tcfg_limb_noise": f"{tcfg['limb_noise']}",
            "tcfg_limb_noise_deg": f"{tcfg['limb_noise_deg']:g}",
            "temporal_steps": f"{temporal['steps']}",
            "temporal_minutes": f"{temporal['minutes']:.1f}",
            "temporal_hardware": f"{temporal['hardware']}",
            "temporal_curve": f"{curve(temporal.get('history', []), ['step', 'minutes', 'loss', 'mse', 'mse_next'])}",
            "tval_mse": f"{tval['mse']:.4f}",
            "tval_mse_next": f"{tval['mse_next']:.4f}",
            "tval_hold_mse": f"{tval['hold_mse']:.4f}",
            "tval_hold_mse_next": f"{tval['hold_mse_next']:.4f}",
            "extrapolated": f"{extrapolated}",
            "tcfg_augment": f"{tcfg.get('augment', 'none')}",
            "tcfg_variants": f"{tcfg.get('variants', 0)}",
            "temporal_augmentation": f"{temporal_augmentation}",
            "tracker_command": f"{tracker.get('command', 'sparse-body train dragposer --part tracker_prior')}",
            "pcfg_hidden": f"{pcfg['hidden']}",
            "pcfg_layers": f"{pcfg['layers']}",
            "pcfg_dropout": f"{pcfg['dropout']:g}",
            "tracker_parameters": f"{tracker['parameters']}",
            "pcfg_chunk": f"{pcfg['chunk']}",
            "tracker_position_noise_cm": f"{pcfg['position_noise'] * 100:g}",
            "pcfg_rotation_noise_deg": f"{pcfg['rotation_noise_deg']:g}",
            "pcfg_noise_copies": f"{pcfg['noise_copies']}",
            "pcfg_lr": f"{pcfg['lr']}",
            "pcfg_weight_decay": f"{pcfg['weight_decay']:g}",
            "pcfg_batch": f"{pcfg['batch']}",
            "tracker_steps": f"{tracker['steps']}",
            "tracker_minutes": f"{tracker['minutes']:.1f}",
            "tracker_hardware": f"{tracker['hardware']}",
            "tracker_curve": f"{curve(tracker.get('history', []), ['step', 'minutes', 'loss', 'mse', 'pe', 'lower_pe'])}",
            "pval_mse_three_point": f"{pval['mse_three_point']:.3f}",
            "pval_mse_four_point": f"{pval['mse_four_point']:.3f}",
            "pval_mse_six_point": f"{pval['mse_six_point']:.3f}",
            "pval_zero_mse": f"{pval['zero_mse']:.3f}",
            "pval_pe_three_point": f"{pval['pe_three_point']:.1f}",
            "pval_pe_four_point": f"{pval['pe_four_point']:.1f}",
            "pval_pe_six_point": f"{pval['pe_six_point']:.1f}",
            "pval_lower_pe_three_point": f"{pval['lower_pe_three_point']:.1f}",
            "pval_lower_pe_four_point": f"{pval['lower_pe_four_point']:.1f}",
            "pval_lower_pe_six_point": f"{pval['lower_pe_six_point']:.1f}",
            "pcfg_augment": f"{pcfg.get('augment', 'none')}",
            "pcfg_variants": f"{pcfg.get('variants', 0)}",
            "tracker_augmentation": f"{tracker_augmentation}",
            "tracker_tables": f"{tracker_tables}",
            "tracker_prior_weight": f"{TRACKER_PRIOR_WEIGHT:g}",
            "runtime_table": f"{runtime_table}",
            "pelvis_tables": f"{pelvis_tables}",
            "root_prior_table": f"{root_prior_table}",
            "three_point_mpjpe": f"{mpjpe('three_point')}",
            "three_point_mpjpe_without_predictor": f"{mpjpe('three_point', 1)}",
            "four_point_mpjpe": f"{mpjpe('four_point')}",
            "four_point_mpjpe_without_predictor": f"{mpjpe('four_point', 1)}",
            "field_protocol_in_a_sentence": f"{FIELD_PROTOCOL[0].lower() + FIELD_PROTOCOL[1:]}",
            "field_tables": f"{chr(10).join(text_tables)}",
            "noise_heading": f"{NOISE_HEADING}",
            "noise_tables": f"{(chr(10) * 2).join(noise_tables)}",
            "refined_table": f"{format_table(refined)}",
        },
    )
    path = out_dir / "dragposer.md"
    path.write_text(text)
    return path


def card(out: Path, mocap, limit: int | None, evaluate: bool = True) -> Path:
    """The record's card step (methods/record.Training.card)."""
    return write_dragposer_card(out, mocap, limit=limit, evaluate=evaluate)
