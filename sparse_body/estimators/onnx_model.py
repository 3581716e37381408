"""Loading a shipped ONNX model for an estimator: one place for the checks every model gets.

A model is refused with its path and the reason when the file is missing (with how to make
one), when ONNX Runtime cannot load it, when its metadata says it is some other model, or
when its inputs are not the ones the estimator feeds (names and last dimensions): a wrong
file fails at configure, not at every step."""

from __future__ import annotations

import json
from pathlib import Path


class ModelMissing(ValueError):
    """No model file where one is expected: bad input (exit code 1), not the operating system's refusal."""


def load_model(
    path: str | Path, kind: tuple[str, str], inputs: dict[str, int | None], missing_hint: str, threads: int = 1
):
    """(InferenceSession, metadata with JSON values decoded) of the model at path.

    kind: (metadata key, value) that names the model, e.g. ("method", "lobstr"); inputs:
    input name -> its last dimension (None: any)."""
    import onnxruntime as ort

    path = Path(path)
    if not path.is_file():
        raise ModelMissing(f"{path}: no model there; {missing_hint}")
    options = ort.SessionOptions()
    options.intra_op_num_threads, options.inter_op_num_threads = threads, 1
    try:
        session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    except Exception as err:  # noqa: BLE001 - onnxruntime raises its own exception types
        raise ValueError(f"{path}: not a loadable ONNX model ({err})") from None
    meta = {}
    for key, value in session.get_modelmeta().custom_metadata_map.items():
        try:
            meta[key] = json.loads(value)
        except ValueError:
            meta[key] = value
    key, value = kind
    if meta.get(key) != value:
        raise ValueError(f"{path}: not a {value} model (its metadata {key} is {meta.get(key)!r})")
    have = {i.name: i.shape for i in session.get_inputs()}
    for name, last in inputs.items():
        if name not in have:
            raise ValueError(f"{path}: a {value} model needs an input {name!r}; this one has {', '.join(have)}")
        if (
            last is not None
            and have[name]
            and have[name][-1] not in (last, None)
            and not isinstance(have[name][-1], str)
        ):
            raise ValueError(f"{path}: input {name!r} has last dimension {have[name][-1]}, a {value} model's is {last}")
    return session, meta


def shipped_model_path(method: str, models: dict[str, str], name: str, others: str = "") -> Path:
    """The package's model file for `model:=name` of a method's shipped models (name -> file);
    others: further names the estimator accepts, for the error."""
    from ..core.resources import models_dir

    if name not in models:
        raise ValueError(
            f"unknown {method} model {name!r}; shipped: {', '.join([*models, *filter(None, [others])])} "
            "(or model_path:=FILE)"
        )
    return models_dir() / models[name]
