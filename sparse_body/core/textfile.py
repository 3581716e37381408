"""Reading a user's text files with a size limit, so that a wrong path (/dev/zero, a
recording named where a YAML file was meant) ends in one clear error instead of minutes of
parsing or an exhausted memory.

The limits suit every file this package ships or writes by a wide margin; a user whose files
are larger raises them with the environment variables named in each error."""

from __future__ import annotations

import gzip
import os
import zipfile
import zlib
from pathlib import Path

import yaml

MIB = 1 << 20
# kind -> (environment variable, default limit in MiB)
LIMITS = {
    "yaml": ("SPARSE_BODY_MAX_YAML_MIB", 1),  # sensor configurations, calibrations: a few kB
    "motion": ("SPARSE_BODY_MAX_MOTION_MIB", 512),  # BVH / AMC: CMU's longest take is 8 MB
}


class InputTooLarge(ValueError):
    """An input over a limit on its size or nesting (exit code 5 on the command line)."""


class FileTooLarge(InputTooLarge):
    """A file over its size limit; the message names the file, the limit and how to raise it."""


def too_large(error: type[Exception]) -> type[Exception]:
    """A domain error type that is also an InputTooLarge: `raise too_large(SensorConfigError)(...)`
    is caught as either."""
    if issubclass(InputTooLarge, error):  # ValueError, Exception: InputTooLarge is one already
        return InputTooLarge
    if error not in _TOO_LARGE:  # one class per error type, made once
        _TOO_LARGE[error] = type(error.__name__, (error, InputTooLarge), {"__module__": error.__module__})
    return _TOO_LARGE[error]


_TOO_LARGE: dict[type[Exception], type[Exception]] = {}


# What reading an .npz's members can raise besides FileTooLarge: a member whose bytes fail their
# CRC or whose size in the directory is understated raises zipfile's or zlib's own errors, not
# OSError, when the member is read (lazily, after open_npz returned).
NPZ_ERRORS: tuple[type[Exception], ...] = (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error)


def open_npz(path: str | os.PathLike, kind: str = "motion"):
    """np.load of an .npz (no pickles) whose members, by the sizes its directory declares, hold
    at most the limit of its kind once decompressed: a few MB can declare gigabytes (a
    decompression bomb), and reading is bounded by what is declared. Raises FileTooLarge, and
    what np.load raises (OSError, ValueError); reading a member raises NPZ_ERRORS."""
    import numpy as np

    limit = limit_bytes(kind)
    try:
        with zipfile.ZipFile(path) as archive:
            declared = sum(member.file_size for member in archive.infolist())
    except zipfile.BadZipFile:
        declared = 0  # not a zip (a plain .npy, a broken file): np.load says what it is
    if declared > limit:
        variable, _ = LIMITS[kind]
        raise FileTooLarge(
            f"{path}: holds {declared / MIB:,.0f} MiB once decompressed, more than the {limit / MIB:g} MiB "
            f"allowed for a {kind} file (set {variable} to raise it)"
        )
    return np.load(path, allow_pickle=False)


# Nodes of a YAML document counted as if every alias were copied out: a sensor configuration or
# a calibration has a few hundred. Aliases share what they name, so a few hundred bytes of nested
# aliases (a "billion laughs") load at once and then grow without end wherever they are walked
# (printed in an error, checked item by item).
MAX_YAML_NODES = 20_000


def load_yaml(text: str, max_nodes: int = MAX_YAML_NODES):
    """yaml.safe_load within max_nodes expanded nodes. Raises yaml.YAMLError, InputTooLarge
    (too many nodes, an alias to itself, nesting deeper than the interpreter allows)."""
    loader = yaml.SafeLoader(text)
    try:
        try:
            node = loader.get_single_node()
        except RecursionError:
            raise InputTooLarge("nested too deeply") from None
        if node is None:
            return None
        if _expanded_nodes(node, max_nodes) > max_nodes:
            raise InputTooLarge(f"more than {max_nodes} values once its aliases are expanded")
        return loader.construct_document(node)
    finally:
        loader.dispose()


def _expanded_nodes(root, limit: int) -> int:
    """How many nodes the document has with aliases copied out, counted up to limit + 1: each
    distinct node is visited once (an alias counts its target's size again, without walking it)."""
    sizes: dict[int, int] = {}
    pending: set[int] = set()

    def size(node) -> int:
        key = id(node)
        if key in sizes:
            return sizes[key]
        if key in pending:  # an alias inside what it names: endless once expanded
            return limit + 1
        pending.add(key)
        total = 1
        if isinstance(node, yaml.SequenceNode):
            children = node.value
        elif isinstance(node, yaml.MappingNode):
            children = [part for pair in node.value for part in pair]
        else:
            children = []
        for child in children:
            total = min(limit + 1, total + size(child))
            if total > limit:
                break
        pending.discard(key)
        sizes[key] = total
        return total

    try:
        return size(root)
    except RecursionError:
        raise InputTooLarge("nested too deeply") from None


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
