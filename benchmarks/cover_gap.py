"""What the check of the cover's gap costs an exploration's step: computed afresh at every step (``cover_gap`` on
all the contacts) against the run's ``CoverGap``, which computes each new contact's plane once.

A run of ``--steps`` contacts on a body of 10 cm radius, its cover seen at ``--seen`` points 8 mm off it (a tight
cover: the camera's inside points stay, so the check runs at every step); both sides are asked at every step with
one contact more, on the same data, and their values compared (they must be equal). Reported: the mean time per step
over the run and at its last 10 steps, and the ratio.

    OMP_NUM_THREADS=1 python benchmarks/cover_gap.py
    python benchmarks/cover_gap.py --steps 300 --seen 3000
"""

from __future__ import annotations

import argparse
import math
import platform
import time

import numpy as np

from torch_gpioius.exploration.observations import CoverGap, cover_gap


def _sphere(radius: float, n: int, seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return radius * v / np.linalg.norm(v, axis=1, keepdims=True)


def _run(measure, contacts: np.ndarray, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each step's time [s] and value [m] of ``measure(contacts so far, seen)``."""
    times, values = [], []
    for n in range(1, len(contacts) + 1):
        t0 = time.perf_counter()
        values.append(measure(contacts[:n], seen))
        times.append(time.perf_counter() - t0)
    return np.array(times), np.array(values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=150, help="contacts in the run")
    parser.add_argument("--seen", type=int, default=1500, help="seen outer points")
    args = parser.parse_args()
    contacts, seen = _sphere(0.10, args.steps, 1), _sphere(0.108, args.seen, 2)
    print(f"{platform.processor() or platform.machine()}; {args.steps} contacts, {args.seen} seen points")
    _run(lambda c, s: cover_gap(c, s), contacts[:20], seen)                          # warm-up
    fresh_t, fresh_v = _run(lambda c, s: cover_gap(c, s), contacts, seen)
    check = CoverGap()
    kept_t, kept_v = _run(check, contacts, seen)
    same = all(a == b or (math.isnan(a) and math.isnan(b)) for a, b in zip(fresh_v, kept_v))
    print("| side | mean per step [ms] | last 10 steps [ms] |\n|---|---|---|")
    for name, t in (("afresh (cover_gap)", fresh_t), ("kept (CoverGap)", kept_t)):
        print(f"| {name} | {1e3 * t.mean():.3f} | {1e3 * t[-10:].mean():.3f} |")
    print(f"ratio afresh / kept: {fresh_t.mean() / kept_t.mean():.1f}x over the run, "
          f"{fresh_t[-10:].mean() / kept_t[-10:].mean():.1f}x at the end; values equal at every step: {same} "
          f"(final gap {1e3 * kept_v[-1]:.1f} mm)")


if __name__ == "__main__":
    main()
