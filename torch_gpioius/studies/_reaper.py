"""A watcher that ends a study's Ray processes when the study's process dies without shutting Ray down.

``kill -9`` of ``gpioius study`` left Ray's ``DashboardAgent`` and ``RuntimeEnvAgent`` running (they ignore SIGTERM
and outlive their raylet). Ray has no setting that ties them to the driver, so the study starts this watcher first
(:class:`RayReaper`): a process of its own that notes every descendant of the study's process while the study runs,
and kills those still alive once the study's end of a pipe closes without the word that it shut Ray down itself.

Linux only (it reads ``/proc``); elsewhere :class:`RayReaper` does nothing and ``ray stop --force`` is the remedy.

Run as ``python -m torch_gpioius.studies._reaper PID``: watches process PID, reading its pipe on standard input.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
from pathlib import Path

__all__ = ["RayReaper", "descendants", "DONE"]

#: What the study writes to the pipe when it shut Ray down itself (the watcher then leaves everything alone).
DONE = b"done\n"
#: Seconds between snapshots of the study's descendants.
POLL = 0.5


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


def _kill(seen: dict[int, int]) -> None:
    """SIGKILL each process of ``seen`` still alive with the same start time (a pid reused since is left alone)."""
    for pid, start in seen.items():
        info = _stat(pid)
        if info is not None and info[1] == start:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass


def watch(study: int, pipe) -> int:
    """Note the descendants of ``study`` until ``pipe`` closes; kill them then unless :data:`DONE` came first."""
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
        seen.pop(os.getpid(), None)
        _kill(seen)
    return 0


class RayReaper:
    """The watcher of this process's Ray processes (see the module docstring); a context manager around a study's
    use of Ray: started before ``ray.init``, told at a clean exit that Ray was shut down (the watcher then exits
    without killing anything)."""

    def __init__(self) -> None:
        self._proc: subprocess.Popen | None = None

    def __enter__(self) -> "RayReaper":
        if sys.platform.startswith("linux") and os.path.isdir("/proc"):
            self._proc = subprocess.Popen([sys.executable, "-m", "torch_gpioius.studies._reaper", str(os.getpid())],
                                          stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                          start_new_session=True)      # not killed with the study's group
        return self

    def __exit__(self, *exc: object) -> None:
        if self._proc is not None:
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
    sys.exit(watch(int(sys.argv[1]), sys.stdin.buffer))
