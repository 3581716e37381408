"""The estimator a user gets when they name none (`--estimator auto`, the default of every
command and of the node's `estimator` parameter): one per sensor configuration, chosen by
the worst kind of motion rather than the average (docs/methods.md, "The default estimator").

A default must hold on every kind a user brings. The learned regressors (LoBSTr, AvatarJLM)
do best on upright motion like CMU's training, and break where the body leaves it (another
lab's lying on the floor: LoBSTr 1.57x IK's leg error, AvatarJLM 1.38x); DragPoser's search
over its pose prior meets the trackers whatever the pose, and held 0.65x IK there (the
filer's figures, issue 73). Which estimator each configuration gets, and the per-kind table
behind it, is in docs/methods.md; a configuration not named here (a user's YAML) gets
DragPoser, which takes any subset of the six trackers.
"""

from __future__ import annotations

AUTO = "auto"
# sensor configuration -> estimator spec
RECOMMENDED = {
    "three_point": "dragposer",
    "four_point": "dragposer",
    "six_point": "ik",
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
