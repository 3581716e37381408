"""Reading a user's text files with a size limit, so that a wrong path (/dev/zero, a
recording named where a YAML file was meant) ends in one clear error instead of minutes of
parsing or an exhausted memory.

The limits suit every file this package ships or writes by a wide margin; a user whose files
are larger raises them with the environment variables named in each error."""

from __future__ import annotations

import gzip
import os
from pathlib import Path

MIB = 1 << 20
# kind -> (environment variable, default limit in MiB)
LIMITS = {
    "yaml": ("SPARSE_BODY_MAX_YAML_MIB", 1),  # sensor configurations, calibrations: a few kB
    "motion": ("SPARSE_BODY_MAX_MOTION_MIB", 512),  # BVH / AMC: CMU's longest take is 8 MB
}


class FileTooLarge(ValueError):
    """A file over its size limit; the message names the file, the limit and how to raise it."""


def limit_bytes(kind: str) -> int:
    variable, default = LIMITS[kind]
    text = os.environ.get(variable, "")
    try:
        mib = float(text) if text else default
    except ValueError:
        raise ValueError(f"${variable}={text!r}: expected a size in MiB") from None
    if not mib > 0:
        raise ValueError(f"${variable}={text!r}: expected a size in MiB above 0")
    return int(mib * MIB)


def read_limited(path: str | os.PathLike, kind: str) -> str:
    """The UTF-8 text of a file (gzip-compressed when it ends in .gz), refused when it holds
    more than the limit of its kind. Reads at most limit + 1 bytes, so a device or an endless
    pipe is refused as quickly as a large file. Raises OSError, UnicodeDecodeError, EOFError
    (a truncated .gz) and FileTooLarge."""
    path = Path(path)
    limit = limit_bytes(kind)
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rb") as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        variable, _ = LIMITS[kind]
        raise FileTooLarge(
            f"{path}: larger than the {limit / MIB:g} MiB allowed for a {kind} file (set {variable} to raise it)"
        )
    return data.decode("utf-8")
