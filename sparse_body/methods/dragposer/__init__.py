"""DragPoser (Ponton et al. 2024): a pose VAE's latent searched so the end effectors meet the
trackers, with a temporal predictor and a tracker prior in the latent space."""

from __future__ import annotations

from ..record import Method, Training, TrainPart


def _paper(mpjpe: float, mpjre: float, mpjve: float, end_effector: float) -> dict[str, float]:
    return {"MPJPE [cm]": mpjpe, "MPJRE [deg]": mpjre, "MPJVE [cm/s]": mpjve, "End-effector PE [cm]": end_effector}


METHOD = Method(
    "dragposer",
    "sparse_body.methods.dragposer.estimator:DragPoserEstimator",
    "sparse_body.methods.dragposer.options:DragPoserOptions",
    compare_with=("dragposer:temporal_weight=0", "ik"),  # the paper's Table 3 ablation, the baseline
    # Table 2: joint position, rotation, velocity and end-effector error; Table 3: no predictor
    paper_figures={
        "six_point": {
            "DragPoser paper": _paper(2.18, 7.66, 10.7, 1.02),
            "paper, no predictor": _paper(3.05, 10.5, 13.1, 1.36),
        },
        "four_point": {"DragPoser paper": _paper(7.86, 10.6, 20.0, 1.12)},
        "three_point": {"DragPoser paper": _paper(15.5, 22.0, 34.0, 16.1)},
        "hip_hands": {"DragPoser paper": _paper(9.95, 14.1, 23.1, 1.77)},
        ("six_point", 1.0): {"DragPoser paper": _paper(6.55, 12.0, 21.1, 10.2)},
    },
    training=Training(
        parts=(  # the VAE first: the other two learn in its latent space
            TrainPart(
                "vae",
                "sparse_body.train.dragposer.vae_model:VaeConfig",
                "sparse_body.train.dragposer.vae_train:train_vae",
                lambda out: out / "dragposer.train.json",
            ),
            TrainPart(
                "temporal",
                "sparse_body.train.dragposer.temporal_model:TemporalConfig",
                "sparse_body.train.dragposer.temporal_train:train_temporal",
                lambda out: out / "dragposer_temporal.train.json",
            ),
            TrainPart(
                "tracker_prior",
                "sparse_body.train.dragposer.tracker_prior_train:TrackerPriorConfig",
                "sparse_body.train.dragposer.tracker_prior_train:train_tracker_prior",
                lambda out: out / "dragposer_tracker_prior.train.json",
            ),
        ),
        output=lambda config: "",  # the models folder itself: dragposer_{encoder,decoder,temporal,tracker_prior}.onnx
        card="sparse_body.train.dragposer.card:card",
        config_help="small (30 minutes a part) or tiny, and paper for its temporal predictor",
        out_help="the folder for its encoder, decoder, temporal predictor and tracker prior",
    ),
    runtime_bench="sparse_body.train.dragposer.bench:bench_dragposer",
    step_goal=("search, predictor, polish", 1.5),
    ratio_goal=8.0,  # issue 52
    eval_sensors="six_point",
)
