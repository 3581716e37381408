"""Where the package's data files (config/) are, in a checkout, a pip install or a ROS install."""

from __future__ import annotations

import os
import sys
from pathlib import Path


def share_dir() -> Path:
    """The directory holding config/ and launch/ (share/sparse_body when installed)."""
    env = os.environ.get("SPARSE_BODY_SHARE")
    if env:
        return Path(env)
    checkout = Path(__file__).resolve().parents[2]  # sparse_body/core/resources.py -> the checkout
    if (checkout / "config" / "sensors").is_dir():
        return checkout
    try:  # a colcon / apt install
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory("sparse_body"))
    except Exception:  # noqa: BLE001 - not installed with ament, or no ament at all
        pass
    return Path(sys.prefix) / "share" / "sparse_body"  # pip install (data-files)


def config_dir() -> Path:
    return share_dir() / "config"


def shipped_or_path(name_or_path: str | Path, folder: str, error: type[Exception], what: str) -> Path:
    """A file given by name (config/FOLDER/NAME.yaml, what the package ships) or by path (it
    has a suffix): an unknown name is `error`, naming the shipped ones."""
    path = Path(name_or_path)
    if path.suffix:
        return path
    path = config_dir() / folder / f"{name_or_path}.yaml"
    if not path.is_file():
        known = sorted(p.stem for p in (config_dir() / folder).glob("*.yaml"))
        raise error(f"no {what} {str(name_or_path)!r}; shipped ones are {', '.join(known)}")
    return path


def models_dir() -> Path:
    """The shipped ONNX models and their model cards."""
    return share_dir() / "models"
