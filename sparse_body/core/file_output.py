"""Every single-file output a command writes (the viewer's page, eval's results file, a
calibration) goes through `write_file`, so that none can destroy what a user owns:

- the data is written to a temporary file made with O_EXCL under a random name in the target's
  folder (mkstemp): no name can be planted in advance to redirect the write through a link;
- it takes the target's name with one rename, which replaces a link itself, never what it
  points to; the target is checked before the work and again just before the rename;
- an existing target is replaced only when it is a regular file (not a link, folder, FIFO or
  device) whose own content proves this package wrote it (`ours`: a marker it carries), and
  only when the caller allows it (`overwrite`);
- on any error (a full disk, Ctrl-C, SIGTERM) the temporary file is removed.

Bags are folders and have their own writer (io/bagio.py's bag_writer), with the same rules.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import stat
from collections.abc import Callable, Iterable
from pathlib import Path


class OutputError(ValueError):
    """An output path refused: it would replace an input, a user's file, folder or device."""


# how much of an existing file is read to find its marker
HEAD_BYTES = 64 * 1024


def read_head(path: Path) -> bytes:
    """The first bytes of a regular file, opened without following a link or blocking on a FIFO."""
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # swapped for something else since lstat
            return b""
        return os.read(fd, HEAD_BYTES)
    finally:
        os.close(fd)


def check_target(path: Path, ours: Callable[[Path], bool], overwrite: bool, what: str) -> Path:
    """Refuse (OutputError) a target that exists and may not be replaced, or whose folder is
    missing. `ours(path)` is asked only of a regular file; `what` names the kind of file in
    messages ("page", "results file")."""
    path = Path(path)
    try:
        info = os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):  # (its parent a file: refused below, as every output's)
        info = None
    if info is not None:
        if stat.S_ISLNK(info.st_mode):
            raise OutputError(f"{path}: exists and is a link; it is never replaced, choose another output")
        if not stat.S_ISREG(info.st_mode):
            kind = "a folder" if stat.S_ISDIR(info.st_mode) else "a device or special file"
            raise OutputError(f"{path}: exists and is {kind}; it is never replaced, choose another output")
        try:
            mine = ours(path)
        except OSError:
            mine = False
        if not mine:
            raise OutputError(
                f"{path}: exists and is not a {what} sparse_body wrote; it is never replaced, choose another output"
            )
        if not overwrite:
            raise OutputError(f"{path}: already exists (choose another name, or --overwrite to replace this {what})")
    parent = path.absolute().parent
    if not parent.is_dir():
        raise OutputError(f"{path}: {parent} is not an existing folder")
    return path


def write_file(
    path: Path,
    data: bytes | str | Iterable[bytes | str],
    ours: Callable[[Path], bool],
    overwrite: bool = False,
    what: str = "file",
) -> Path:
    """`data` (or its parts, written one after the other as they come: a page of many
    megabytes need not be held whole) written to `path` as described above; returns the path."""
    path = check_target(path, ours, overwrite, what)
    parts = [data] if isinstance(data, (bytes, str)) else data
    # named before it is made, so that an interrupt right after it is made removes it too (one
    # landing between mkstemp's return and the cleanup's try left it: CI's Ctrl-C test)
    tmp = path.absolute().parent / f".{path.name}.{secrets.token_hex(6)}.partial"
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)  # umask applies
        with os.fdopen(fd, "wb") as f:
            for part in parts:
                f.write(part.encode("utf-8") if isinstance(part, str) else part)
        check_target(path, ours, overwrite, what)  # nothing else may have appeared meanwhile
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path


def marker_in_head(marker: bytes) -> Callable[[Path], bool]:
    """An `ours` test: the marker is among the file's first bytes."""
    return lambda path: marker in read_head(path)
