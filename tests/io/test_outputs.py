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


def test_an_output_file_is_claimed_from_the_start_and_its_lock_removed_at_the_end(tmp_path):
    """Issue 60, items 3 and 19: two `fit --mesh same.ply` started together both said "wrote"; a fit left `.lock`
    behind. A claim is held from the check to the write: a second claim is refused at once by the holder's pid; a
    file another program wrote meanwhile is never replaced without --force; the lock files go with their holders."""
    from torch_gpioius.io.outputs import FileClaim

    target = tmp_path / "est.ply"
    with FileClaim(target, what="--mesh") as first:
        with pytest.raises(RuntimeError, match=rf"est.ply: another command \(pid {os.getpid()}\) is writing"):
            FileClaim(target, what="--mesh").acquire()
        first.write(b"first")
    assert target.read_bytes() == b"first" and sorted(p.name for p in tmp_path.iterdir()) == ["est.ply"]
    with pytest.raises(FileExistsError, match="pass --force"):
        FileClaim(target)
    with FileClaim(tmp_path / "late.ply") as claim:
        (tmp_path / "late.ply").write_bytes(b"someone else's")          # written while the command ran
        with pytest.raises(FileExistsError, match="written by another program while this command ran"):
            claim.write(b"ours")
    assert (tmp_path / "late.ply").read_bytes() == b"someone else's"
    with FileClaim(target, force=True) as claim:
        claim.write(b"second")
    assert target.read_bytes() == b"second" and not list(tmp_path.glob(".*"))
    with FolderLock(tmp_path / "out"):
        assert (tmp_path / "out" / ".lock").exists()
    assert not (tmp_path / "out" / ".lock").exists()


def test_a_lock_file_removed_while_a_writer_waited_is_taken_again_where_it_now_is(tmp_path):
    """The lock's file goes with its holder: a writer that opened the old file before it was removed must not hold a
    lock on a file nobody else can see (two writers would then both write)."""
    import fcntl

    from torch_gpioius.io.outputs import _Lock

    path = tmp_path / ".lock"
    stale = os.open(path, os.O_RDWR | os.O_CREAT)          # what a waiter opened just before the holder left
    os.unlink(path)
    lock = _Lock(path, "busy {pid}")
    real_open = lock._open
    calls = []

    def opened_stale_first():
        calls.append(1)
        return stale if len(calls) == 1 else real_open()

    lock._open = opened_stale_first
    with lock:
        assert len(calls) == 2 and os.fstat(lock._fd).st_ino == os.stat(path).st_ino
        fd = os.open(path, os.O_RDWR)
        with pytest.raises(OSError):
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)       # the file there now is the one held
        os.close(fd)


def test_inputs_are_never_outputs_and_a_refused_command_leaves_no_folder(tmp_path):
    from torch_gpioius.io.outputs import check_not_inputs, claimed_folder

    (tmp_path / "data").mkdir()
    cloud = tmp_path / "data" / "cloud.ply"
    cloud.write_text("ply")
    os.symlink(cloud, tmp_path / "alias.ply")
    for target, match in ((cloud, "is the input"), (tmp_path / "alias.ply", "is the input"),
                          (tmp_path / "data" / ".." / "data" / "cloud.ply", "is the input"),
                          (tmp_path / "data" / "est.ply", "inside the input")):
        with pytest.raises(ValueError, match=f"--mesh: .* {match} .*--force never replaces an input"):
            check_not_inputs({"--mesh": target}, [cloud if "inside" not in match else tmp_path / "data"])
    check_not_inputs({"--mesh": tmp_path / "est.ply", "--outer-mesh": None}, [cloud, None])
    with pytest.raises(KeyError):
        with claimed_folder(tmp_path / "new", "fit"):
            raise KeyError("the scene cannot be built")
    assert not (tmp_path / "new").exists()
    (tmp_path / "empty").mkdir()
    with pytest.raises(KeyError):
        with claimed_folder(tmp_path / "empty", "fit"):
            raise KeyError
    assert (tmp_path / "empty").is_dir() and not list((tmp_path / "empty").iterdir())
    with claimed_folder(tmp_path / "kept", "fit"):
        pass
    assert (tmp_path / "kept" / ".gpioius-output.json").exists()


def test_fit_never_writes_over_its_inputs_and_refuses_a_bad_mesh_before_the_fit(tmp_path, capsys, monkeypatch):
    """Issue 60, items 2, 12 and 19: `fit ... --cloud left.ply --mesh left.ply --force` replaced the cloud with the
    estimate; `--mesh /proc/x.ply` and a bad ending were refused only after the fit (naming a temporary file)."""
    import torch_gpioius.fitting as offline
    from tests.userfiles import EYES, sphere_files

    csv, (left, right) = sphere_files(tmp_path, contacts=12, cover=400)
    before = left.read_bytes()
    base = ["fit", str(csv), "--cloud", str(left), "--camera-origin", " ".join(map(str, EYES[0]))]
    assert main([*base, "--mesh", str(left), "--force"]) == 2
    assert "--mesh: " in capsys.readouterr().err and left.read_bytes() == before

    def no_fit(*a, **k):
        raise AssertionError("the fit ran before the output was checked")

    monkeypatch.setattr(offline, "_fit", no_fit)
    for mesh, match in (("/proc/x.ply", "/proc: cannot write there"),
                        (str(tmp_path / "x.xyz"), "a 3-D estimate is a mesh"),
                        (str(tmp_path / "nofolder" / "x.ply"), "does not exist")):
        assert main([*base, "--mesh", mesh, "--out", str(tmp_path / "refused")]) == 2
        assert match in capsys.readouterr().err
        assert not (tmp_path / "refused").exists()
