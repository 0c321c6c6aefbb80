"""torch_gpioius.io.outputs: the folder lock, staged files, and links that are never written through."""

import os

import pytest

from torch_gpioius.cli import main
from torch_gpioius.io.outputs import FolderLock


def test_a_link_planted_at_the_lock_is_refused_and_its_target_untouched(tmp_path, capsys):
    """Issue 51, item 3: `ln -s victim lk/.lock; gpioius fit ... --out lk` wrote the pid into the victim."""
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "lk"
    out.mkdir()
    os.symlink(victim, out / ".lock")
    with pytest.raises(RuntimeError, match=r"\.lock: is a symbolic link"):
        FolderLock(out).acquire()
    assert victim.read_text() == "precious"
    assert main(["fit", "data/example_2d.gpioius", "--out", str(out)]) == 2
    assert "is a symbolic link" in capsys.readouterr().err
    assert victim.read_text() == "precious"


def test_a_dangling_link_at_the_lock_creates_nothing_through_it(tmp_path):
    out = tmp_path / "lk"
    out.mkdir()
    os.symlink(tmp_path / "created-through-the-link", out / ".lock")
    with pytest.raises(RuntimeError, match="symbolic link"):
        FolderLock(out).acquire()
    assert not (tmp_path / "created-through-the-link").exists()


def test_the_lock_is_still_exclusive_and_released(tmp_path):
    with FolderLock(tmp_path, "gpioius fit"):
        with pytest.raises(RuntimeError, match=r"another writer \(pid \d+\) is writing there"):
            FolderLock(tmp_path).acquire()
    with FolderLock(tmp_path):
        pass


def _dead_pid() -> int:
    """A process id that ran and has ended (a child waited for)."""
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_staged_files_move_subfolders_in_together(tmp_path):
    from torch_gpioius.io.outputs import StagedFiles

    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "a.gpioius").write_text("old")
    (tmp_path / "summary.md").write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with StagedFiles(tmp_path) as staged:
            (staged.path / "logs").mkdir()
            (staged.path / "logs" / "a.gpioius").write_text("new, partial")
            raise KeyboardInterrupt
    assert (tmp_path / "logs" / "a.gpioius").read_text() == "old" and (tmp_path / "summary.md").read_text() == "old"
    with StagedFiles(tmp_path) as staged:
        (staged.path / "logs" / "deeper").mkdir(parents=True)
        (staged.path / "logs" / "a.gpioius").write_text("new")
        (staged.path / "logs" / "deeper" / "b.txt").write_text("b")
        (staged.path / "summary.md").write_text("new")
    assert (tmp_path / "logs" / "a.gpioius").read_text() == "new" and (tmp_path / "summary.md").read_text() == "new"
    assert (tmp_path / "logs" / "deeper" / "b.txt").read_text() == "b"
    assert not list(tmp_path.glob(".staging.*"))


def test_a_killed_writers_staging_folder_is_removed_by_the_next_fit(tmp_path):
    """Issue 51, item 10: a SIGKILLed `fit` left `.staging.<pid>.*` with a partial model.pt for good."""
    out = tmp_path / "fit"
    assert main(["fit", "data/example_2d.gpioius", "--out", str(out)]) == 0
    stale = out / f".staging.{_dead_pid()}.0badcafe"
    stale.mkdir()
    (stale / "model.pt").write_bytes(b"partial")
    alive = out / f".staging.{os.getppid()}.0000beef"            # a process that still runs: its folder stays
    alive.mkdir()
    assert main(["fit", "data/example_2d.gpioius", "--out", str(out)]) == 0
    assert not stale.exists() and alive.exists()
