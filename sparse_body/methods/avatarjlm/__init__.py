"""AvatarJLM (Zheng et al. 2023): joint tokens from the headset and controllers (three-point)
or with the pelvis (four-point), polished by IK onto the trackers."""

from __future__ import annotations

from ..record import Method, Training, TrainPart


def _output(config) -> str:
    sensors = config().sensors
    return "avatarjlm.onnx" if sensors == "three_point" else f"avatarjlm_{sensors}.onnx"


METHOD = Method(
    "avatarjlm",
    "sparse_body.methods.avatarjlm.estimator:AvatarJlmEstimator",
    "sparse_body.methods.avatarjlm.options:AvatarJlmOptions",
    compare_with=("avatarjlm:polish=false", "dragposer", "ik"),
    # Table 1 (AMASS Protocol 1: 90 % of CMU, BMLrub, HDM05 for training)
    paper_figures={
        "three_point": {"AvatarJLM paper": {"MPJPE [cm]": 3.35, "MPJRE-AA [deg]": 2.90, "MPJVE [cm/s]": 20.79}},
        "four_point": {"AvatarJLM paper": {"MPJPE [cm]": 2.09, "MPJRE-AA [deg]": 2.40, "MPJVE [cm/s]": 17.82}},
    },
    training=Training(
        parts=(
            TrainPart(
                "avatarjlm",
                "sparse_body.train.avatarjlm.model:AvatarJlmConfig",
                "sparse_body.train.avatarjlm.train:train",
                lambda out: out.with_suffix(".train.json"),
            ),
        ),
        output=_output,
        card="sparse_body.train.avatarjlm.card:card",
        config_help="small (three-point, 88 minutes on one core), four_point (the same with the pelvis: "
        "models/avatarjlm_four_point.onnx), paper (d1 1024, d2 512, 6 loops: for a GPU) or tiny",
        out_help="the .onnx file",
    ),
    step_goal=("streaming joint tokens, polish", 2.0),
    eval_sensors="three_point",
)
