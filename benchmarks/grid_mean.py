"""Meshing the estimate: the metrics grid with the posterior variance (``predict``) vs the mean alone
(``predict_mean``).

A study measures the estimate every few steps on a grid over the exploration range (2 cm nodes over the range
grown by 5 cm: ~20,000-40,000 nodes on the torsos). Marching cubes needs only the mean. With the structured engine
the variance at a node needs its kernel row rotated into the outer eigenbasis, ``O(N_o r)`` per node, while the
mean needs one dot product with the outer weights ``U alpha_rot``, ``O(N_o)``. Both sides run on the same model
(the data of ``planning_step.py``: outer points on two ellipsoids, 300 inner points) and grid, in one process:

    OMP_NUM_THREADS=1 python benchmarks/grid_mean.py --outer 2000 7300 --spacing 0.02
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from planning_step import NOISE, THETA, make_data  # noqa: E402

import torch_gpioius as tg  # noqa: E402
from torch_gpioius.kernels import InverseMultiquadricKernel as IMQ  # noqa: E402
from torch_gpioius.geometry.surfaces import evaluate_grid  # noqa: E402


def one(n_outer: int, n_inner: int, spacing: float, device: str) -> dict:
    xo, yo, xi, yi = make_data(n_outer, n_inner)
    model = tg.GPIOIS(torch.cat([xi, xo]), torch.cat([yi, yo]),
                      torch.cat([torch.zeros(n_inner, dtype=torch.long), torch.ones(n_outer, dtype=torch.long)]),
                      kernel=IMQ(THETA), noise=NOISE, inference="structured", device=device).fit()
    box = np.array([[-0.3, -0.23, -0.35], [0.3, 0.23, 0.35]])     # the inner ellipsoid's box grown by 5 cm
    t0 = time.perf_counter()
    mean_only = evaluate_grid(model, box, spacing, 0, variance=False)
    t_mean = time.perf_counter() - t0
    t0 = time.perf_counter()
    full = evaluate_grid(model, box, spacing, 0)
    t_full = time.perf_counter() - t0
    return {"nodes": mean_only.mean.size, "mean_s": t_mean, "full_s": t_full,
            "diff": float(np.abs(mean_only.mean - full.mean).max())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--outer", type=int, nargs="+", default=[2000, 7300])
    parser.add_argument("--inner", type=int, default=300)
    parser.add_argument("--spacing", type=float, default=0.02, help="grid spacing [m]")
    parser.add_argument("--device", default="cpu", help="cpu or cuda (float64 either way)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"{platform.processor() or platform.machine()}, torch {torch.__version__}, 1 thread, {args.device}")
    print("| N_outer | grid nodes | mean and variance [s] | mean only [s] | ratio | max |mean difference| |")
    print("|---|---|---|---|---|---|")
    for n in args.outer:
        r = one(n, args.inner, args.spacing, args.device)
        print(f"| {n} | {r['nodes']} | {r['full_s']:.2f} | {r['mean_s']:.3f} | {r['full_s'] / r['mean_s']:.0f}x | "
              f"{r['diff']:.1e} |", flush=True)


if __name__ == "__main__":
    main()
