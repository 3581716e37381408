"""Single-file outputs (the viewer's page, eval's results, a calibration) go through
core/file_output.py: a user's file, a link, a FIFO or a device is never replaced or written
through, and a failed write leaves nothing behind. Each case was a reproduction on main: `view
-o report.html` replaced any HTML page holding "plotly", followed a link planted at its fixed
temporary name, replaced a link given as -o, left its temporary file on a full disk; the
calibrate service hung on a FIFO."""

from __future__ import annotations

import errno
import os
import threading
from pathlib import Path

import pytest

from sparse_body.cli import EXIT_OS, EXIT_OUTPUT, main
from sparse_body.core.calibration import Calibration
from sparse_body.core.file_output import OutputError, write_file
from sparse_body.core.sensors import load_sensor_config
from sparse_body.core.skeleton import Skeleton
from sparse_body.data.synthetic import synthetic_walk


@pytest.fixture(scope="module")
def estimate_bag(tmp_path_factory) -> Path:
    from sparse_body.apps.offline import make_bag, process_bag

    folder = tmp_path_factory.mktemp("view")
    motion = synthetic_walk(1.0)
    config = load_sensor_config("six_point")
    make_bag(motion, config, folder / "trackers")
    process_bag(folder / "trackers", folder / "estimate", "ik", config, motion.skeleton, progress=False)
    return folder / "estimate"


def view(capsys, *argv) -> tuple[int, str]:
    with pytest.raises(SystemExit) as ended:
        main(["view", *map(str, argv)])
    return ended.value.code, capsys.readouterr().err


def listing(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


def test_a_users_html_page_is_never_replaced(estimate_bag, tmp_path, capsys):
    report = tmp_path / "report.html"
    notes = '<html><head><script src="plotly.min.js"></script></head><body>my notes</body></html>'
    report.write_text(notes)
    for extra in ([], ["--overwrite"]):
        code, err = view(capsys, estimate_bag, "-o", report, *extra)
        assert code == EXIT_OUTPUT and "never replaced" in err and err.count("\n") == 1
    assert report.read_text() == notes and listing(tmp_path) == {"report.html"}


def test_a_page_of_ours_is_replaced_only_with_overwrite(estimate_bag, tmp_path, capsys):
    page = tmp_path / "page.html"
    assert view(capsys, estimate_bag, "-o", page)[0] == 0
    first = page.stat().st_mtime_ns
    code, err = view(capsys, estimate_bag, "-o", page)
    assert code == EXIT_OUTPUT and "--overwrite" in err and page.stat().st_mtime_ns == first
    assert view(capsys, estimate_bag, "-o", page, "--overwrite")[0] == 0
    assert listing(tmp_path) == {"page.html"} and (page.stat().st_mode & 0o777) == 0o644 & ~_umask()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_links_are_never_written_through_nor_replaced(estimate_bag, tmp_path, capsys):
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    # a link at the name the viewer used as its temporary file, and a link given as -o
    (tmp_path / ".page.html.partial").symlink_to(victim)
    (tmp_path / "link.html").symlink_to(victim)
    assert view(capsys, estimate_bag, "-o", tmp_path / "page.html")[0] == 0
    assert not (tmp_path / "page.html").is_symlink() and victim.read_text() == "keep me"
    for flags in ([], ["--overwrite"]):
        code, err = view(capsys, estimate_bag, "-o", tmp_path / "link.html", *flags)
        assert code == EXIT_OUTPUT and "link" in err
    assert (tmp_path / "link.html").is_symlink() and victim.read_text() == "keep me"


def test_a_full_disk_leaves_no_temporary_file_and_exits_with_the_os_code(estimate_bag, tmp_path, capsys, monkeypatch):
    real_fdopen = os.fdopen

    class FullDisk:
        def __init__(self, f):
            self.f = f

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

        def fileno(self):
            return self.f.fileno()

        def write(self, data):
            self.f.write(data[: 1 << 20])
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fdopen", lambda fd, mode: FullDisk(real_fdopen(fd, mode)))
    code, err = view(capsys, estimate_bag, "-o", tmp_path / "page.html")
    assert code == EXIT_OS and "No space left" in err
    assert listing(tmp_path) == set()


def test_a_calibration_is_never_written_into_a_fifo_and_replaces_only_an_earlier_one(tmp_path):
    calibration = Calibration(1.7, 0.1, {}, Skeleton.canonical(1.7))
    fifo = tmp_path / "calibration.yaml"
    os.mkfifo(fifo)
    outcome: list[BaseException | None] = []

    def save():
        try:
            calibration.save(fifo)
            outcome.append(None)
        except BaseException as err:  # noqa: BLE001 - the test reads what happened
            outcome.append(err)

    worker = threading.Thread(target=save, daemon=True)
    worker.start()
    worker.join(5.0)
    assert outcome and isinstance(outcome[0], OutputError), "saving to a FIFO hung or wrote"
    saved = tmp_path / "mine.yaml"
    calibration.save(saved)
    calibration.save(saved)  # an earlier calibration: replaced
    assert Calibration.load(saved).height == pytest.approx(1.7)
    users = tmp_path / "users.yaml"
    users.write_text("height: 1.8\n")
    with pytest.raises(OutputError):
        calibration.save(users)
    assert users.read_text() == "height: 1.8\n"


def test_write_file_refuses_a_folder_a_device_and_a_missing_folder(tmp_path):
    (tmp_path / "folder").mkdir()
    for target in (tmp_path / "folder", Path("/dev/null"), tmp_path / "missing" / "x.json"):
        with pytest.raises(OutputError):
            write_file(target, "x", lambda _: True, overwrite=True)
    assert listing(tmp_path) == {"folder"}
