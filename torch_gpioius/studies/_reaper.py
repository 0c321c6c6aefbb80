"""A watcher that ends a study's Ray processes when the study's process dies without shutting Ray down.

``kill -9`` of ``gpioius study`` left Ray's ``DashboardAgent`` and ``RuntimeEnvAgent`` running (they ignore SIGTERM
and outlive their raylet). Ray has no setting that ties them to the driver, so the study starts this watcher first
(:class:`RayReaper`): a process of its own that notes every descendant of the study's process while the study runs,
and kills those still alive once the study's end of a pipe closes without the word that it shut Ray down itself.
Snapshots alone miss a process started since the last one (Ray's agents start last, and a process whose parent died
is re-parented out of the study's tree), so the study also marks its environment with a token every process it starts
inherits, and the watcher ends, at the end, every process it saw, every process that carries the token, and the
descendants of all, found before the first is killed. The token alone is not enough either: Ray's agents set their
process title, which can overwrite the environment ``/proc`` shows (one of two agents of a cluster here lost the
token so), and the raylet above them dies with the study (Ray ties it to its driver), leaving them adopted
elsewhere; they keep their logs open in the Ray session directory, which Ray names after the driver's pid, and the
watcher ends every process holding a file there (:func:`in_session`).

Linux only (it reads ``/proc``); elsewhere :class:`RayReaper` does nothing and ``ray stop --force`` is the remedy.

Run as ``python -m torch_gpioius.studies._reaper PID TOKEN``: watches process PID, reading its pipe on standard
input; TOKEN is the value of :data:`TOKEN_VAR` in the environment of the processes the study started.
"""

from __future__ import annotations

import os
import re
import secrets
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["RayReaper", "descendants", "marked", "in_session", "running", "DONE", "TOKEN_VAR"]

#: What the study writes to the pipe when it shut Ray down itself (the watcher then leaves everything alone).
DONE = b"done\n"
#: Seconds between snapshots of the study's descendants.
POLL = 0.2
#: The environment variable that marks every process a study started (its value is the study's own token).
TOKEN_VAR = "GPIOIUS_STUDY_TOKEN"


def _stat(pid: int) -> tuple[int, int] | None:
    """``(parent pid, start time in clock ticks)`` of a process, or None when it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()      # the name may hold spaces and parentheses
    return int(fields[1]), int(fields[19])


def descendants(root: int) -> dict[int, int]:
    """``{pid: start time}`` of every process below ``root`` in the process tree (Linux's ``/proc``)."""
    children: dict[int, list[int]] = {}
    starts: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            info = _stat(int(entry))
            if info is not None:
                children.setdefault(info[0], []).append(int(entry))
                starts[int(entry)] = info[1]
    out, todo = {}, list(children.get(root, ()))
    while todo:
        pid = todo.pop()
        if pid in starts and pid not in out:
            out[pid] = starts[pid]
            todo.extend(children.get(pid, ()))
    return out


def marked(token: str) -> dict[int, int]:
    """``{pid: start time}`` of every process (of this user: others' environments are unreadable) whose environment
    holds ``TOKEN_VAR=token``."""
    mark = f"{TOKEN_VAR}={token}".encode()
    out = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                env = Path(f"/proc/{entry}/environ").read_bytes()
            except OSError:
                continue
            if mark in env.split(b"\0"):
                info = _stat(int(entry))
                if info is not None:
                    out[int(entry)] = info[1]
    return out


def running(pid: int, start: int) -> bool:
    """Whether process ``pid`` that started at ``start`` (clock ticks) still runs: it exists with that start time (a
    pid reused since is another process) and has not exited (a zombie, killed and waiting for whoever adopted it to
    collect its status, has: it holds nothing but its pid, and is not Ray left behind)."""
    info = _stat(pid)
    if info is None or info[1] != start:
        return False
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return text[text.rindex(")") + 2:][:1] not in ("Z", "X")


def in_session(study: int) -> dict[int, int]:
    """``{pid: start time}`` of every process (of this user) that holds a file open under the Ray session directory of
    the driver ``study`` (``.../session_<date>_<time>_<study>/``: Ray names it after the driver's pid; its processes
    keep their logs there): a Ray process of that study wherever it sits in the process tree and whatever its
    title or environment say."""
    mark = re.compile(rf"/session_[^/]*_{int(study)}(/|$)")
    out = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            links = [os.readlink(f"/proc/{entry}/fd/{fd}") for fd in os.listdir(f"/proc/{entry}/fd")]
        except OSError:
            continue
        if any(mark.search(link) for link in links):
            info = _stat(int(entry))
            if info is not None:
                out[int(entry)] = info[1]
    return out


def _alive(seen: dict[int, int]) -> dict[int, int]:
    """The processes of ``seen`` still running (:func:`running`)."""
    return {pid: start for pid, start in seen.items() if running(pid, start)}


def _kill(seen: dict[int, int], token: str | None = None, rounds: int = 5, study: int | None = None) -> None:
    """SIGKILL each process of ``seen`` still alive, every process marked with ``token``, every process holding files
    in the Ray session of the driver ``study`` (:func:`in_session`) and the descendants of all of them; again (up to
    ``rounds`` times) while a round finds a process the previous ones did not."""
    me = os.getpid()
    done: set[int] = set()
    for _ in range(rounds):
        todo = _alive(seen)
        if token:
            todo.update(marked(token))
        if study is not None:
            todo.update(in_session(study))
        # every descendant found before any is killed: a process that renames itself (Ray's agents set their title,
        # which can overwrite the environment /proc shows, token and all) is found below its parent (the raylet,
        # marked), and would be out of reach once that parent is killed and it is adopted elsewhere
        for pid in list(todo):
            todo.update(descendants(pid))
        todo.pop(me, None)
        fresh = {pid: start for pid, start in todo.items() if pid not in done}
        if not fresh:
            return
        for pid in fresh:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        done.update(fresh)
        seen = {**seen, **fresh}
        time.sleep(0.1)


def watch(study: int, pipe, token: str | None = None) -> int:
    """Note the descendants of ``study`` until ``pipe`` closes; kill them then (with their descendants and every
    process marked with ``token``) unless :data:`DONE` came first."""
    seen: dict[int, int] = {}
    said = b""
    fd = pipe.fileno()
    while True:
        seen.update(descendants(study))
        readable, _, _ = select.select([fd], [], [], POLL)
        if readable:
            chunk = os.read(fd, 64)
            if not chunk:
                break
            said += chunk
    if DONE not in said:
        _kill(seen, token, study=study)
    return 0


class RayReaper:
    """The watcher of this process's Ray processes (see the module docstring); a context manager around a study's
    use of Ray: started before ``ray.init``, told at a clean exit that Ray was shut down (the watcher then exits
    without killing anything)."""

    def __init__(self) -> None:
        self._proc: subprocess.Popen | None = None
        self._before: str | None = None

    def __enter__(self) -> "RayReaper":
        if sys.platform.startswith("linux") and os.path.isdir("/proc"):
            token = f"{os.getpid()}-{secrets.token_hex(8)}"
            self._proc = subprocess.Popen([sys.executable, "-m", "torch_gpioius.studies._reaper", str(os.getpid()),
                                           token],
                                          stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                          start_new_session=True)      # not killed with the study's group
            self._before = os.environ.get(TOKEN_VAR)
            os.environ[TOKEN_VAR] = token          # inherited by every process Ray starts from here
        return self

    def __exit__(self, *exc: object) -> None:
        if self._proc is not None:
            if self._before is None:
                os.environ.pop(TOKEN_VAR, None)
            else:
                os.environ[TOKEN_VAR] = self._before
            try:
                self._proc.stdin.write(DONE)
                self._proc.stdin.close()
            except OSError:
                pass
            try:
                self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:      # pragma: no cover - a watcher that hangs
                self._proc.kill()


if __name__ == "__main__":          # pragma: no cover - run in its own process (tests/studies/test_sweep.py)
    sys.exit(watch(int(sys.argv[1]), sys.stdin.buffer, sys.argv[2] if len(sys.argv) > 2 else None))
