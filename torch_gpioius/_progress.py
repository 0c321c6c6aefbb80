"""Progress reporting that suits where the output goes: tqdm bars on a terminal, a few plain lines in a pipe or
a log file (nested tqdm bars wrote ~1,000 lines of escape codes there)."""

from __future__ import annotations

import sys
import time

from tqdm.auto import tqdm

__all__ = ["progress"]


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
