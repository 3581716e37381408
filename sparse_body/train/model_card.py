"""Model cards: what a shipped model was trained on, how, and how well it does on the test split."""
from __future__ import annotations

from pathlib import Path

from ..core.sensors import load_sensor_config
from ..data.catalog import load_split


def write_lobstr_card(onnx_path: Path, report: dict, mocap_root: Path, limit: int | None = None) -> Path:
    """Evaluate the model on the test split (four-point, clean trackers) beside the IK baseline,
    without its contact IK and the paper's figures, and write <model>.md."""
    from ..evaluation import evaluate, format_table, paper_figures
    sensors = load_sensor_config("four_point")
    model = str(Path(onnx_path).resolve())
    results = [evaluate(spec, sensors, mocap_root, "test", limit=limit, progress=False, **options)
               for spec, options in [("lobstr", {"model_path": model}),
                                     ("lobstr:contact_ik=false", {"model_path": model}), ("ik", {})]]
    table = format_table(results, paper_figures("lobstr", "four_point"))
    split = load_split()
    cfg, val = report["config"], report["validation"]
    history = report.get("history", [])
    curve = "\n".join(f"| {h['step']} | {h['minutes']:.1f} | {h['train_loss']:.4f} | {h['contact_accuracy_pct']:.1f} "
                      f"| {h['lower_rot_error_deg']:.2f} | {h['toe_error_cm']:.2f} |"
                      for h in history[:: max(1, len(history) // 12)])
    text = f"""# LoBSTr model card: `{Path(onnx_path).name}`

LoBSTr (Yang et al., Eurographics 2021): a GRU over the velocities of pelvis, head and hands
(4 x 9 + 1 inputs per frame, in the pelvis's yaw-only reference frame) predicting the 8 leg
joints in 6D and the two feet's contact probabilities. Upper body by IK, contacts held by IK.
Runtime: ONNX Runtime, one GRU step per frame (`sparse_body/estimators/lobstr.py`).

## Data
- CMU motion capture from `../shared/mocap` (its README has the licence), retargeted onto the
  22-joint body at {cfg['fps']:.0f} fps, every clip scaled to the canonical leg length, floor at z = 0.
- Split `config/splits/cmu.yaml` (by clip): {len(split['train'])} train / {len(split['validation'])} validation /
  {len(split['test'])} test clips. Trained on {report['train_clips']} train clips ({report['train_frames']} frames),
  each clean plus {cfg['noise_copies']} copies with the paper's tracker noise (1 cm Gaussian per axis,
  rotations up to 1.5 degrees); the best validation score ({report['validation_clips']} clips) is exported.
- Contact labels: toe within 2 cm of the floor and slower than 0.3 m/s (`core/contacts.py`).

## Training
- Command: `{report.get('command', 'sparse-body train lobstr')}`
- Configuration: hidden {cfg['hidden']} (paper: 1024), latent {cfg['latent']}, chunks of {cfg['chunk']} frames
  ({cfg['burn_in']} warm-up frames without loss), batch {cfg['batch']}, Adam lr {cfg['lr']} x {cfg['lr_decay']}
  every {cfg['steps_per_epoch']} steps; losses pose + {cfg['w_fk']} FK + {cfg['w_velocity']} toe velocity +
  {cfg['w_contact']:g} contact (the paper's weights).
- {report['steps']} steps in {report['minutes']:.1f} minutes on {report['hardware']} (torch {report['torch']}).

| step | minutes | train loss | val contact [%] | val leg rot [deg] | val toe [cm] |
|---|---|---|---|---|---|
{curve}

Validation (exported weights): contact {val['contact_accuracy_pct']:.1f} %, leg rotation
{val['lower_rot_error_deg']:.2f} deg, toe position {val['toe_error_cm']:.2f} cm (toe relative to the true pelvis).

## Test split (`sparse-body eval --estimator lobstr --sensors four_point`)

```
{table}
```

Skate with contact IK: {results[0].summary['Skate [cm/s]']:.2f} cm/s; without: {results[1].summary['Skate [cm/s]']:.2f} cm/s.
The paper's figures come from its own data (PFNN, CMU and MHAD locomotion at 45 fps) and
protocol: a guide, not a like-for-like comparison.

## Limits
- Trained on CMU only ({report['train_frames'] / cfg['fps'] / 60:.0f} minutes of motion); no sitting on chairs, few
  sharp turns. Contact prediction is weakest at sharp turns and leg crossings (as the paper reports).
- The reference frame is yaw only (as in the paper): lying, rolling or crawling are out of scope.
"""
    path = Path(onnx_path).with_suffix(".md")
    path.write_text(text)
    return path


DRAGPOSER_SETUPS = [("six_point", 0.0), ("four_point", 0.0), ("three_point", 0.0), ("hip_hands", 0.0),
                    ("six_point", 1.0)]


def write_dragposer_card(out_dir: Path, report: dict, mocap_root: Path, limit: int | None = None) -> Path:
    """Evaluate the pose VAE + optimiser on the test split for the paper's Table 2 setups, beside
    the IK baseline and the paper's figures, and write dragposer.md."""
    from dataclasses import replace

    from ..data.virtual_trackers import NO_NOISE
    from ..evaluation import evaluate, format_table, paper_figures
    model_dir = str(Path(out_dir).resolve())
    tables = []
    for sensors_name, faulty in DRAGPOSER_SETUPS:
        sensors = load_sensor_config(sensors_name)
        noise = replace(NO_NOISE, fault_probability=faulty / 100)
        results = [evaluate("dragposer", sensors, mocap_root, "test", noise=noise, limit=limit, progress=False,
                            model_dir=model_dir),
                   evaluate("ik", sensors, mocap_root, "test", noise=noise, limit=limit, progress=False)]
        title = f"{sensors_name}" + (f", faulty {faulty:g} %" if faulty else "")
        tables.append(f"### {title}\n\n```\n{format_table(results, paper_figures('dragposer', sensors_name, faulty))}\n```\n")
    split = load_split()
    cfg, val = report["config"], report["validation"]
    history = report.get("history", [])
    curve = "\n".join(f"| {h['step']} | {h['minutes']:.1f} | {h['total']:.4f} | {h['position_error_cm']:.2f} "
                      f"| {h['rotation_error_deg']:.2f} |" for h in history[:: max(1, len(history) // 12)])
    text = f"""# DragPoser model card: `dragposer_encoder.onnx`, `dragposer_decoder.onnx`

DragPoser (Ponton et al. 2024): a pose VAE whose 24-D latent space a pose optimiser searches
each frame until the constraints (trackers, floor, look-at, limits) hold. These two files are
the VAE's encoder (dual quaternions in root space -> latent mean) and decoder (latent -> 22
local rotations, the root's without heading). Runtime: ONNX Runtime and a damped Gauss-Newton
step whose Jacobian comes from one batched decoder pass (`sparse_body/estimators/dragposer.py`).
The temporal predictor is not part of this release: the optimiser's prior is the previous
frame's latent.

## Data
- CMU motion capture from `../shared/mocap` (its README has the licence), retargeted onto the
  22-joint body at 60 fps; rotations on the canonical body, root height scaled by leg length.
- Split `config/splits/cmu.yaml` (by clip): {len(split['train'])} train / {len(split['validation'])} validation /
  {len(split['test'])} test clips. Trained on every frame of {report['train_clips']} train clips
  ({report['train_frames']} frames, each paired with the next for the continuity loss).

## Training
- Command: `{report.get('command', 'sparse-body train dragposer')}`
- MLP encoder and decoder, hidden {cfg['hidden']} (the paper uses skeleton-aware convolutions of
  about the same size), latent {cfg['latent']}; AdamW lr {cfg['lr']}, weight decay {cfg['weight_decay']},
  batch {cfg['batch']}; losses reconstruction + {cfg['w_fk']:g} FK + {cfg['w_kld']:g} KL + {cfg['w_continuity']:g} continuity
  (the paper's weights).
- {report['steps']} steps in {report['minutes']:.1f} minutes on {report['hardware']} (torch {report['torch']}).

| step | minutes | train loss | val position [cm] | val rotation [deg] |
|---|---|---|---|---|
{curve}

Validation encode-decode error (exported weights): {val['position_error_cm']:.2f} cm, {val['rotation_error_deg']:.2f} deg.

## Test split (`sparse-body eval --estimator dragposer --sensors S [--faulty 1]`)

Optimiser defaults: 3 Levenberg-Marquardt iterations a frame (30 on the first), position
weight 1, orientation weight 0.1, prior weights 0.001 (previous latent) and 0.0002 (latent
norm), feet above the floor.

{chr(10).join(tables)}
The paper's figures come from its own data and protocol (a guide, not a like-for-like comparison).
"""
    path = Path(out_dir) / "dragposer.md"
    path.write_text(text)
    return path
