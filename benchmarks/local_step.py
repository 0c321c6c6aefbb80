"""Cost of the local model: one planning step of LocalGPIOIS (R regions) against GPIOIS, in one run.

A planning step = ingest one contact + 4 free-space points, re-learn the task parameters (K_t for GPIOIS; a', c
and the R region coefficients for LocalGPIOIS) warm-started, and plan the next sliding direction (eq. 19). Both
models use their structured exact engines (the fixed outer set is factorised once); the data are those of
``planning_step.py`` (3-D ellipsoids, theta 0.15, sigma^2 0.08). The two sides alternate step by step so that load
on the machine hits both alike; prints medians and the ratio.

    python benchmarks/local_step.py                          # 2000 outer + 300 inner, R = 1, 2, 4, 8
    python benchmarks/local_step.py --outer 500 --inner 50 --regions 4 --steps 3
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import torch_gpioius as tg  # noqa: E402
from planning_step import NOISE, STEP, THETA, make_data  # noqa: E402
from torch_gpioius.models.local import LocalGPIOIS  # noqa: E402
from torch_gpioius.exploration.planning import plan_direction  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--outer", type=int, default=2000)
    parser.add_argument("--inner", type=int, default=300)
    parser.add_argument("--regions", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--steps", type=int, default=7)
    args = parser.parse_args()
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, torch {torch.__version__} "
          f"({torch.get_num_threads()} threads), float64, {args.outer} outer + {args.inner} inner points")
    print("| regions R | GPIOIS step [ms] | LocalGPIOIS step [ms] | ratio | local setup [s] |")
    print("|---|---|---|---|---|")
    xo, yo, xi, yi = make_data(args.outer, args.inner + 5 * (args.steps + 1))
    to = torch.ones(args.outer, dtype=torch.long)
    x0 = torch.cat([xi[:args.inner], xo])
    y0 = torch.cat([yi[:args.inner], yo])
    t0 = torch.cat([torch.zeros(args.inner, dtype=torch.long), to])
    for R in args.regions:
        g = tg.GPIOIS(x0, y0, t0, theta=THETA, noise=NOISE, inference="structured").fit()
        s = time.perf_counter()
        loc = LocalGPIOIS(x0, y0, t0, regions=R, theta=THETA, noise=NOISE, inference="structured").fit()
        setup = time.perf_counter() - s
        times = {"g": [], "l": []}
        for k in range(args.steps):
            lo = args.inner + 5 * k
            nx, ny = xi[lo:lo + 5], yi[lo:lo + 5]
            for key, m in (("g", g), ("l", loc)):
                s = time.perf_counter()
                m.add_observations(nx, ny, 0)
                m.fit(multi_start=False)
                plan_direction(m, nx[0], step=STEP)
                times[key].append(time.perf_counter() - s)
        tg_ms, tl_ms = (1e3 * statistics.median(times[k]) for k in ("g", "l"))
        print(f"| {R} | {tg_ms:.1f} | {tl_ms:.1f} | {tl_ms / tg_ms:.2f}x | {setup:.2f} |", flush=True)


if __name__ == "__main__":
    main()
