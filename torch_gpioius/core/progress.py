"""Progress reporting that suits where the output goes: tqdm bars on a terminal, a few plain lines in a pipe or
a log file (nested tqdm bars wrote ~1,000 lines of escape codes there)."""

from __future__ import annotations

import sys
import time

from tqdm.auto import tqdm

__all__ = ["progress", "Heartbeat", "status"]


class _Lines:
    """A tqdm-like object that prints one plain line per ``every`` fraction of the total (and at the end), and a
    line at an update when ``quiet`` seconds passed without one (a long stretch is not silent).

    A line says what is done: ``"2-D study: 25 % done (last: object A, visual-tactile), 14 s"``; the postfix is
    what was being worked on when the line was due, i.e. what has just finished."""

    def __init__(self, total: float, desc: str, every: float = 0.25, stream=None, quiet: float = 10.0) -> None:
        self.total, self.desc, self.n, self.every = max(float(total), 1e-12), desc, 0.0, every
        self.stream = stream or sys.stderr
        self._next = every
        self._t0 = self._last = time.perf_counter()
        self.quiet = quiet
        self.postfix = ""

    def update(self, k: float = 1) -> None:
        self.n += k
        printed = False
        while self.n / self.total >= self._next - 1e-12 and self._next <= 1.0 + 1e-12:
            self._print(f"{100 * min(self._next, 1.0):.0f} % done")
            self._next += self.every
            printed = True
        if not printed and k and time.perf_counter() - self._last >= self.quiet:
            self._print(f"{100 * min(self.n / self.total, 1.0):.0f} % done")

    def set_postfix_str(self, text: str) -> None:
        self.postfix = text

    def _print(self, what: str) -> None:
        extra = f" (last: {self.postfix})" if self.postfix else ""
        self._last = time.perf_counter()
        print(f"{self.desc}: {what}{extra}, {self._last - self._t0:.0f} s", file=self.stream, flush=True)

    def close(self) -> None:
        pass

    def __iter__(self):
        raise TypeError("iterate over a list and call update()")


class _Nothing:
    n = 0

    def update(self, k: float = 1) -> None:
        pass

    def set_postfix_str(self, text: str) -> None:
        pass

    def close(self) -> None:
        pass


def progress(total: float, desc: str, enabled: bool = True, *, leave: bool = False, lines: bool = True):
    """A progress reporter with ``update(k)``, ``set_postfix_str(s)`` and ``close()``.

    A tqdm bar when enabled and stderr is a terminal; plain lines (every 25 %) when enabled in a pipe and
    ``lines``; nothing otherwise.
    """
    if not enabled:
        return _Nothing()
    if sys.stderr.isatty():
        return tqdm(total=total, desc=desc, leave=leave)
    return _Lines(total, desc) if lines else _Nothing()


#: What a long computation is doing now (:func:`status`), read by a running :class:`Heartbeat`.
_STATUS = {"text": ""}


def status(text: str) -> None:
    """Say what a long computation is doing now (``"fitting K_t on 2,870 observations"``); a running
    :class:`Heartbeat` prints it. Cheap, and nothing is printed without a heartbeat."""
    _STATUS["text"] = text


class Heartbeat:
    """A context manager that prints, on stderr, what a long computation is doing (:func:`status`) and for how long,
    every ``every`` seconds once it has run that long: a fit of minutes is never silent (``gpioius fit``).

    Args:
        desc: the line's start (``"gpioius fit"``).
        every: seconds between lines [s].
        stream: where to print (stderr).
    """

    def __init__(self, desc: str, every: float = 15.0, stream=None) -> None:
        import threading

        self.desc, self.every, self.stream = desc, float(every), stream
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, daemon=True)

    def _beat(self) -> None:
        t0 = time.perf_counter()
        while not self._stop.wait(self.every):
            text = _STATUS["text"] or "working"
            print(f"{self.desc}: {text}, {time.perf_counter() - t0:.0f} s so far", file=self.stream or sys.stderr,
                  flush=True)

    def __enter__(self) -> "Heartbeat":
        status("")
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        status("")
