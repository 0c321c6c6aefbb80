"""Torch's thread count for one run: one thread by default in the CLI, the studies and every parallel worker.

Measured on this project's 2-core machines (docs/performance.md, ``python benchmarks/threads.py``): a planning
step's matrices are small (hundreds of rows), so a second intra-op thread buys little, and under load (another
run, a study worker, the test suite) two torch threads per process oversubscribe the cores and make a run 2-3x
slower with identical results.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

import torch

__all__ = ["torch_threads"]


@contextmanager
def torch_threads(n: int | None) -> Iterator[None]:
    """Run the body with ``torch.set_num_threads(n)`` and restore the previous count after (``None``: unchanged).

    Raises:
        ValueError: ``n`` is not a positive integer.
    """
    if n is None:
        yield
        return
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"threads: must be a positive integer, got {n!r}")
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)
