"""The estimator a user gets when they name none (`--estimator auto`, the default of every
command and of the node's `estimator` parameter): one per sensor configuration, chosen by
the worst kind of motion rather than the average (docs/methods.md, "The default estimator").

A default must hold on every kind a user brings. The learned models do best on upright motion
like CMU's training and break where the body leaves it: another lab's lying on the floor gave
LoBSTr 1.57x IK's leg error (issue 73), and on the floor part here (`eval --split floor`) every
learned four-point estimator was 1.7-2.8x IK's on some way of lying until `upright` stood the
body up for it. A configuration not named here (a user's YAML) gets DragPoser, which takes any
subset of the six trackers.
"""

from __future__ import annotations

AUTO = "auto"
# sensor configuration -> estimator spec, chosen by the worst kind of motion over three sets none
# trains on (docs/methods.md, "The default estimator"): the selection, cmu-extra, the floor part
RECOMMENDED = {
    # worst kind 0.91x IK's MPJPE (blend), 0.93x (avatarjlm), 1.07x (dragposer: one-leg balances)
    "three_point": "blend",
    # blend (AvatarJLM and DragPoser), stood up as the body lies down: worst kind 0.90x IK's leg
    # error (the floor part, lying on the back); blend alone 1.14x (lying on the front; 1.68x
    # before AvatarJLM trained off its feet), DragPoser 2.45x, upright:base=lobstr,fallback=ik
    # (the default before it) 1.39x
    "four_point": "upright",
    "six_point": "ik",  # the feet tracked: not measured on these sets
}
OTHERWISE = "dragposer"


def recommended(sensors_name: str) -> str:
    """The estimator spec recommended for a sensor configuration (by its name)."""
    return RECOMMENDED.get(sensors_name, OTHERWISE)


def resolve_estimator(spec: str, sensors_name: str) -> str:
    """`spec` with `auto` replaced by the recommended estimator for the sensors, options kept
    ("auto:foot_lock=false" -> "dragposer:foot_lock=false"); any other spec as it is."""
    name, colon, options = spec.partition(":")
    if name.strip() != AUTO:
        return spec
    return recommended(sensors_name) + (colon + options if options else "")
