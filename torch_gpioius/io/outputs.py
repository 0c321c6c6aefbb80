"""Where commands write: one rule for existing files, atomic writes, output folders a command owns, and a lock.

**The rule.** No command replaces something that already exists unless it is told to (``--force``, or
``force=True`` / ``overwrite=True`` in Python):

* a single output file (``export --mesh``, ``import-bag --out``, ``export --mcap``) must not exist yet;
* an output folder (``simulate``, ``simulate3d``, ``study``, ``fit --out``, ``replay --out``) must be new, empty, or
  one that the same command wrote before (it records itself in :data:`MARKER`), so ``make demo`` can run twice
  while someone else's folder of results is never overwritten;
* two outputs of one command may not name the same file.

**Atomic writes.** Files are written to a temporary file beside the target whose name is unique to the process
and call, flushed, fsynced and renamed over the target: a crash leaves the old file or the new one, two writers
never share a temporary file, and a symbolic link at the target is replaced, never followed (the rename replaces
the link itself).

**Staged files.** A command whose files describe one result together (``fit --out``: model.pt, fit.png and
fit.json) writes them into a private staging folder inside the output folder and moves them in only when all are
written (:class:`StagedFiles`): a failure leaves the earlier result whole, never a mix of two.

**The lock.** :class:`FolderLock` holds an exclusive ``flock`` on a file in an output folder for as long as a
writer works there; a second writer is refused at once with the holder's process id. The kernel releases the lock
when its holder dies, so a killed run never leaves a stale lock behind, and a writer that ends removes the lock's
file (a lock whose file was removed or replaced after it was opened is taken again on the file now there, so two
writers never hold locks on two files of one name).

**Output files are claimed.** :class:`FileClaim` checks a single output file when a command starts (it does not
exist, unless ``force``; its folder exists and can be written) and holds a lock beside it (``.<name>.lock``) until
the file is written: a second command writing the same file is refused at once rather than both reporting success
and one result lost, and a file that cannot be written is refused before a long fit, not after it.

**Inputs are never outputs.** :func:`check_not_inputs` refuses an output that is one of the command's inputs
(``fit --cloud a.ply --mesh a.ply``), with or without ``--force``: ``--force`` replaces earlier results, never the
data they came from.
"""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path

__all__ = ["MARKER", "atomic_write", "check_new_file", "check_distinct", "check_not_inputs", "claim_folder",
           "claimed_folder", "FolderLock", "FileClaim", "StagedFiles", "remove_stale_staging", "STAGING_PREFIX"]

#: The file by which a command marks an output folder as its own (JSON: command, version, and e.g. the world).
MARKER = ".gpioius-output.json"
#: Files of ours that do not make a folder someone's output (the lock of a writer that may still be starting).
_HOUSEKEEPING = (".lock",)


def atomic_write(path: str | os.PathLike, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` atomically (see the module docstring); remove the temporary file on failure.

    Returns:
        the path written.
    """
    path = Path(path)
    blob = data.encode() if isinstance(data, str) else data
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(blob)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise
    _fsync_dir(path)
    return path


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path.parent, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def check_new_file(path: str | os.PathLike, force: bool = False, what: str = "output") -> Path:
    """``path`` as a :class:`~pathlib.Path` if it may be written: it does not exist (nor does a link of that name),
    or ``force``; its folder must exist.

    Raises:
        FileExistsError: it exists and ``force`` is False (names the path and the option).
        FileNotFoundError: its folder does not exist (names the folder).
        IsADirectoryError: it is a folder.
    """
    p = Path(path)
    if p.is_dir() and not p.is_symlink():
        raise IsADirectoryError(f"{p}: is a folder; the {what} must be a file")
    if os.path.lexists(p) and not force:
        raise FileExistsError(f"{p}: exists; pass --force to replace it (or choose another {what} file)")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(f"{p}: the folder {parent} does not exist")
    return p


def check_distinct(**paths) -> None:
    """Refuse two outputs that name the same file (``--mesh X --outer X`` would lose one of them).

    Args:
        **paths: option name -> path (None entries are skipped).

    Raises:
        ValueError: naming both options.
    """
    seen: dict[str, str] = {}
    for name, p in paths.items():
        if p is None:
            continue
        key = os.path.realpath(os.path.abspath(p))
        if key in seen:
            raise ValueError(f"{name} and {seen[key]} name the same file {p}; give each output its own file")
        seen[key] = name


def claim_folder(path: str | os.PathLike, command: str, force: bool = False, *, added: tuple[str, ...] = (),
                 **identity) -> Path:
    """Make ``path`` an output folder of ``command`` (see the module docstring) and record it there.

    Args:
        path: the folder (created with its parents if missing).
        command: the command that writes it (e.g. "study").
        force: write into a non-empty folder that another command, or no command, wrote.
        **identity: JSON-able facts that must also match for a folder to be re-used (e.g. ``world="2d"`` for a
            study, whose runs and tables belong to one world).
        added: identity keys that folders written by older versions do not record; such a folder is taken as
            matching on them (and records them from now on).

    Returns:
        the folder.

    Raises:
        FileExistsError: the folder holds someone else's files (names what it holds and the option).
        NotADirectoryError: ``path`` is a file.
    """
    from .._version import __version__

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise NotADirectoryError(f"{p}: is a file; the output must be a folder")
    if p.is_dir() and any(c.name not in _HOUSEKEEPING for c in p.iterdir()) and not force:
        marker = p / MARKER
        try:
            info = json.loads(marker.read_text())
            if not isinstance(info, dict):
                raise ValueError
        except (OSError, ValueError):
            raise FileExistsError(f"{p}: exists, is not empty and was not written by `gpioius {command}`; pass "
                                  "--force to write into it (files of the same names are replaced) or choose "
                                  "another --out") from None
        want = {"command": command, **identity}
        clash = {k: info.get(k) for k, v in want.items() if info.get(k) != v and not (k in added and k not in info)}
        if clash:
            # None stands for a setting's default in older markers (touch=None: point touches); name it so
            held = ", ".join(f"{k}={_shown(k, v)!r}" for k, v in clash.items())
            asked = ", ".join(f"{k}={_shown(k, want[k])!r}" for k in clash)
            raise FileExistsError(f"{p}: holds the output of another run ({held}); this one is {asked}; pass --force "
                                  "to write into it anyway or choose another --out")
    p.mkdir(parents=True, exist_ok=True)
    atomic_write(p / MARKER, json.dumps({"command": command, **identity, "version": __version__}))
    return p


#: How a marker's None reads for the identity keys whose default is recorded as None.
_DEFAULT_NAMES = {"touch": "point", "voxel": "the world's default", "outer_tol": "exact",
                  **{k: "the world's own" for k in ("settings", "learn", "views", "kernel", "theta", "noise")}}


def _shown(key: str, value):
    return _DEFAULT_NAMES.get(key, value) if value is None else value


class _Lock:
    """An exclusive, non-blocking ``flock`` on the file ``path`` (created if missing, never through a link), removed
    when released (see the module docstring); a context manager.

    Args:
        path: the lock's file.
        busy: the message when another process holds it (``{pid}`` is replaced by the holder's process id).

    Raises:
        RuntimeError: another process holds the lock, or the lock's file cannot be opened (names the path).
    """

    def __init__(self, path: str | os.PathLike, busy: str) -> None:
        self.path = Path(path)
        self.busy = busy
        self._fd: int | None = None

    def acquire(self):
        import fcntl

        while True:
            fd = self._open()
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                try:
                    holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "unknown"
                finally:
                    os.close(fd)
                raise RuntimeError(self.busy.format(pid=holder)) from None
            try:
                same = os.fstat(fd).st_ino == os.lstat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            # the holder before us removed (or someone replaced) the file after we opened it: lock the one there now
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        self._fd = fd
        return self

    def _open(self) -> int:
        # never through a link: a link planted at the lock would have its target truncated and overwritten with a pid
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
        except OSError as e:
            if os.path.islink(self.path):
                raise RuntimeError(f"{self.path}: is a symbolic link; the lock must be a plain file (remove the link "
                                   "or choose another output)") from None
            raise RuntimeError(f"{self.path.parent}: cannot write there ({e.strerror}: cannot create the lock "
                               f"{self.path.name})") from None
        if not os.path.isfile(self.path) or os.path.islink(self.path):
            os.close(fd)
            raise RuntimeError(f"{self.path}: is not a plain file; the lock must be one (remove it or choose another "
                               "output)")
        return fd

    def release(self) -> None:
        if self._fd is not None:
            import fcntl

            try:
                if os.fstat(self._fd).st_ino == os.lstat(self.path).st_ino:
                    os.unlink(self.path)            # while held: a waiter that opened it sees it gone and retries
            except OSError:
                pass
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


class FolderLock(_Lock):
    """An exclusive, non-blocking ``flock`` on ``folder/.lock`` while a writer works in ``folder`` (see the module
    docstring); a context manager. The folder is created if missing; the lock's file is removed at release.

    Raises:
        RuntimeError: another process holds the lock (names its pid and the folder).
    """

    def __init__(self, folder: str | os.PathLike, what: str = "writer") -> None:
        super().__init__(Path(folder) / ".lock", f"{Path(folder)}: another {what} (pid {{pid}}) is writing there; wait "
                                                 "for it to finish or choose another --out")
        self.what = what

    def acquire(self) -> "FolderLock":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        return super().acquire()


class FileClaim(_Lock):
    """A single output file claimed from the start of a command to its write (see the module docstring): checked as
    :func:`check_new_file` checks it, its folder shown writable and locked for it by ``.<name>.lock`` beside it.
    Write through :meth:`write` while the claim is held; the lock's file is removed at release.

    Args:
        path: the output file.
        force: replace an existing file.
        what: the option or kind of output, for messages (``"--mesh"``).

    Raises:
        FileExistsError, FileNotFoundError, IsADirectoryError: as :func:`check_new_file`.
        RuntimeError: another command is writing the same file (names its pid), or the folder cannot be written.
    """

    def __init__(self, path: str | os.PathLike, force: bool = False, what: str = "output") -> None:
        self.target = check_new_file(path, force, what)
        self.force, self.what = force, what
        super().__init__(self.target.parent / f".{self.target.name}.lock",
                         f"{self.target}: another command (pid {{pid}}) is writing this {what} file; wait for it to "
                         "finish or choose another file")

    def acquire(self) -> "FileClaim":
        super().acquire()
        try:
            check_new_file(self.target, self.force, self.what)   # written by someone while we waited for the lock
        except BaseException:
            self.release()
            raise
        return self

    def write(self, data: bytes | str) -> Path:
        """Write ``data`` to the claimed file atomically; without ``force``, never over a file that appeared since
        the claim (another program wrote it meanwhile).

        Raises:
            FileExistsError: the file appeared meanwhile and ``force`` is False.
        """
        if self.force:
            return atomic_write(self.target, data)
        return _write_new(self.target, data, self.what)


def _write_new(path: Path, data: bytes | str, what: str) -> Path:
    """:func:`atomic_write` that never replaces: the data are written beside ``path`` and linked into place, which
    fails where ``path`` exists (no window between a check and the write)."""
    blob = data.encode() if isinstance(data, str) else data
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(blob)
            f.flush()
            os.fsync(f.fileno())
        try:
            os.link(tmp, path)
        except FileExistsError:
            raise FileExistsError(f"{path}: was written by another program while this command ran; pass --force to "
                                  f"replace it (or choose another {what} file)") from None
    finally:
        try:
            tmp.unlink()
        except OSError:
            pass
    _fsync_dir(path)
    return path


def check_not_inputs(outputs, inputs) -> None:
    """Refuse an output that is one of the inputs (the same file by its real path, links and ``..`` resolved), or a
    file inside an input folder (a bag's).

    Args:
        outputs: ``{option: path}`` of what a command will write (None entries are skipped).
        inputs: paths a command reads (None entries are skipped).

    Raises:
        ValueError: naming the option, the output and the input; ``--force`` does not lift it.
    """
    reads = [(p, os.path.realpath(p)) for p in inputs if p is not None]
    for option, target in outputs.items():
        if target is None:
            continue
        dst = os.path.realpath(target)
        for src_given, src in reads:
            inside = os.path.isdir(src) and dst.startswith(src.rstrip(os.sep) + os.sep)
            if dst == src or inside:
                raise ValueError(f"{option}: {target} is {'the input' if dst == src else 'inside the input'} "
                                 f"{src_given}; write the output elsewhere (--force never replaces an input)")


class claimed_folder:
    """:func:`claim_folder` as a context manager that undoes itself: a command refused before it wrote anything (a
    scene that cannot be built) leaves no folder behind where there was none, and no marker in an empty folder.

    Args and raises: as :func:`claim_folder`.
    """

    def __init__(self, path: str | os.PathLike, command: str, force: bool = False, *, added: tuple[str, ...] = (),
                 **identity) -> None:
        self.path = Path(path)
        self._existed = self.path.exists()
        self._empty = self._existed and self.path.is_dir() and not any(self.path.iterdir())
        self.folder = claim_folder(path, command, force, added=added, **identity)

    def __enter__(self) -> Path:
        return self.folder

    def __exit__(self, exc_type, *exc: object) -> None:
        if exc_type is None or (self._existed and not self._empty):
            return
        left = {c.name for c in self.path.iterdir()} if self.path.is_dir() else set()
        if left <= {MARKER, *_HOUSEKEEPING}:
            for name in left:
                try:
                    (self.path / name).unlink()
                except OSError:
                    pass
            if not self._existed:
                try:
                    self.path.rmdir()
                except OSError:
                    pass


class StagedFiles:
    """Files that belong together, written into a private staging folder and moved into ``folder`` at the end.

    Use as a context manager: write into :attr:`path` (subfolders too: a study's ``logs/``); on a clean exit every
    file there replaces the one of its relative path in ``folder`` (each by an atomic rename, all after the last one
    was written); on an exception nothing in ``folder`` changes and the staging folder is removed. A process killed
    with SIGKILL cannot remove its staging folder: the next :class:`StagedFiles` in that folder removes every
    staging folder whose process no longer runs (:func:`remove_stale_staging`).

    Args:
        folder: the output folder (must exist).

    Attributes:
        path: the staging folder (``folder/.staging.<pid>.<random>``), same file system as ``folder``.
        moved: the final paths, after a clean exit.
    """

    def __init__(self, folder: str | os.PathLike) -> None:
        self.folder = Path(folder)
        self.path = self.folder / f"{STAGING_PREFIX}{os.getpid()}.{secrets.token_hex(4)}"
        self.moved: list[Path] = []

    def __enter__(self) -> "StagedFiles":
        remove_stale_staging(self.folder)
        self.path.mkdir()
        return self

    def __exit__(self, exc_type, *exc: object) -> None:
        import shutil

        try:
            if exc_type is None:
                staged = sorted(p for p in self.path.rglob("*") if p.is_file() and not p.is_symlink())
                for p in staged:
                    with open(p, "rb") as f:
                        os.fsync(f.fileno())
                for p in staged:
                    target = self.folder / p.relative_to(self.path)
                    if target.parent != self.folder:
                        if target.parent.is_symlink():       # never move a result through a planted link
                            target.parent.unlink()
                        target.parent.mkdir(parents=True, exist_ok=True)
                    os.replace(p, target)
                    self.moved.append(target)
                for target in {t.parent: t for t in self.moved}.values():
                    _fsync_dir(target)
        finally:
            shutil.rmtree(self.path, ignore_errors=True)


#: The name every staging folder starts with (``.staging.<pid>.<random>``).
STAGING_PREFIX = ".staging."


def remove_stale_staging(folder: str | os.PathLike) -> list[Path]:
    """Remove the staging folders in ``folder`` whose process no longer runs (a fit or study killed with SIGKILL
    leaves its ``.staging.<pid>.*`` behind, a partial model.pt or logs in it); those of running processes stay.

    Returns:
        the folders removed.
    """
    import shutil

    removed = []
    for p in Path(folder).glob(f"{STAGING_PREFIX}*"):
        try:
            pid = int(p.name[len(STAGING_PREFIX):].split(".", 1)[0])
        except ValueError:
            continue
        if p.is_dir() and not p.is_symlink() and not _running(pid):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


def _running(pid: int) -> bool:
    """Whether a process of this id runs (one we may not signal runs too)."""
    if pid <= 0:
        return False
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
