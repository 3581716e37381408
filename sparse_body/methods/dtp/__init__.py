"""DTP / Deep Tracker Poser (a transformer over a window of six trackers, fine-tuned for
occluded feet), online or with future frames (lookahead, offline)."""

from __future__ import annotations

from ..record import Method, Training, TrainPart

METHOD = Method(
    "dtp",
    "sparse_body.methods.dtp.estimator:DtpEstimator",
    "sparse_body.methods.dtp.options:DtpOptions",
    compare_with=("dtp:model=pretrained", "dtp:model=lookahead", "dragposer", "lobstr", "ik"),
    # Table 2 (online, TotalCapture): mean joint position error, global rotation error, jerk
    paper_figures={
        "six_point": {"DTP paper": {"MPJPE [cm]": 1.04, "MPJRE-global [deg]": 4.22, "Jitter [100m/s3]": 2.31}}
    },
    training=Training(
        parts=(
            TrainPart(
                "dtp",
                "sparse_body.train.dtp.model:DtpConfig",
                "sparse_body.train.dtp.train:train",
                lambda out: out.with_suffix(".train.json"),
            ),
        ),
        output=lambda config: "dtp_lookahead.onnx" if config().future else "dtp.onnx",
        card="sparse_body.train.dtp.card:card",
        config_help="small (pre-training and occlusion fine-tuning in under an hour on 2 CPU cores), "
        "lookahead (small with 5 future frames: models/dtp_lookahead.onnx), paper or tiny",
        out_help="the .onnx file",
    ),
    step_goal=("21-frame window, transformer, polish", 1.0),
    eval_sensors="six_point",
)
