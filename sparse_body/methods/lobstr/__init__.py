"""LoBSTr (Yang et al. 2021): a GRU predicts the legs and foot contacts from four trackers;
the upper body by IK; contact IK holds the feet."""

from __future__ import annotations

from ..record import Method, Training, TrainPart

METHOD = Method(
    "lobstr",
    "sparse_body.methods.lobstr.estimator:LobstrEstimator",
    "sparse_body.methods.lobstr.options:LobstrOptions",
    compare_with=("lobstr:contact_ik=false,foot_lock=false", "ik"),
    paper_figures={
        "four_point": {"LoBSTr paper": {"Contact acc [%]": 85.77, "Lower RE [deg]": 8.53, "Toe PE [cm]": 6.63}}
    },
    training=Training(
        parts=(
            TrainPart(
                "lobstr",
                "sparse_body.train.lobstr.model:LobstrConfig",
                "sparse_body.train.lobstr.train:train",
                lambda out: out.with_suffix(".train.json"),
            ),
        ),
        output=lambda config: "lobstr.onnx",
        card="sparse_body.train.lobstr.card:card",
        config_help="paper, small (under an hour on 2 CPU cores) or tiny",
        out_help="the .onnx file",
    ),
    runtime_bench="sparse_body.train.lobstr.bench:bench_network",
    step_goal=("network, upper-body IK, contact IK", 0.25),
    ratio_goal=2.0,
    eval_sensors="four_point",
)
