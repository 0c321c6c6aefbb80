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
when its holder dies, so a killed run never leaves a stale lock behind.
"""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path

__all__ = ["MARKER", "atomic_write", "check_new_file", "check_distinct", "claim_folder", "FolderLock", "StagedFiles",
           "remove_stale_staging", "STAGING_PREFIX"]

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


class FolderLock:
    """An exclusive, non-blocking ``flock`` on ``folder/.lock`` (see the module docstring); a context manager.

    Raises:
        RuntimeError: another process holds the lock (names its pid and the folder).
    """

    def __init__(self, folder: str | os.PathLike, what: str = "writer") -> None:
        self.path = Path(folder) / ".lock"
        self.what = what
        self._fd: int | None = None

    def acquire(self) -> "FolderLock":
        import fcntl

        self.path.parent.mkdir(parents=True, exist_ok=True)
        # never through a link: a link planted at .lock would have its target truncated and overwritten with our pid
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
        except OSError as e:
            if os.path.islink(self.path):
                raise RuntimeError(f"{self.path}: is a symbolic link; the lock must be a plain file (remove the link "
                                   "or choose another --out)") from None
            raise RuntimeError(f"{self.path}: cannot open the folder's lock ({e.strerror})") from None
        if not os.path.isfile(self.path) or os.path.islink(self.path):
            os.close(fd)
            raise RuntimeError(f"{self.path}: is not a plain file; the lock must be one (remove it or choose another "
                               "--out)")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            try:
                holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "unknown"
            finally:
                os.close(fd)
            raise RuntimeError(f"{self.path.parent}: another {self.what} (pid {holder}) is writing there; wait for it "
                               "to finish or choose another --out") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            import fcntl

            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "FolderLock":
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


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
