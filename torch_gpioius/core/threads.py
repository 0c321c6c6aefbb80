"""Torch's thread count for one run: one thread by default in the CLI, the studies and every parallel worker.

Measured on this project's 2-core machines (docs/performance.md, ``python benchmarks/threads.py``): a planning
step's matrices are small (hundreds of rows), so a second intra-op thread buys little, and under load (another
run, a study worker, the test suite) two torch threads per process oversubscribe the cores and make a run 2-3x
slower with identical results.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Iterator

import torch

__all__ = ["torch_threads", "max_threads"]


def max_threads() -> int:
    """The most threads a run may ask for: the cores this process may use (``--threads 100000`` crashed libgomp
    and then segfaulted; more threads than cores only oversubscribe them)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):       # pragma: no cover - platforms without affinity
        return max(1, os.cpu_count() or 1)


@contextmanager
def torch_threads(n: int | None) -> Iterator[None]:
    """Run the body with ``torch.set_num_threads(n)`` and restore the previous count after (``None``: unchanged).

    Raises:
        ValueError: ``n`` is not a positive integer, or more than this machine's cores (:func:`max_threads`).
    """
    if n is None:
        yield
        return
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"threads: must be a positive integer, got {n!r}")
    if n > max_threads():
        raise ValueError(f"threads: {n} is more than the {max_threads()} cores this process may use; give at most "
                         f"{max_threads()} (1 is fastest for one run, docs/performance.md)")
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)
