"""Torch threads on a small machine: one exploration run at 1 and 2 threads, alone and with a second run beside it.

Every CLI command pins torch to ``--threads`` (default 1) and the sweep's workers to one thread each. This script
shows why, on the machine it runs on: the same workload (a visual-tactile exploration of the 2-D object B,
``--steps`` planning steps, plus a 3-D planning-step workload at 2000 + 300 points) runs in fresh processes

* alone with 1 thread, alone with 2 threads;
* as two concurrent processes with 1 thread each, and with 2 threads each (what happens when parallel workers
  do not pin their threads).

Prints the wall time per run of each arrangement and the ratios, and the final similarity of the 2-D run: identical
for runs with the same thread count, and a rounding apart (~1e-14) between 1 and 2 threads, since a BLAS reduction
split over two threads adds in another order (the seed of the chaos that docs/results-3d.md measures over seeds).

    python benchmarks/threads.py            # about 2 minutes on 2 cores
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

WORK = r"""
import json, sys, time, torch
torch.set_num_threads(int(sys.argv[1]))
import torch_gpioius as tg
from torch_gpioius.kernels import InverseMultiquadricKernel as IMQ
t = time.perf_counter()
tr = tg.explore(tg.sim.paper_objects_2d()["B"], mode="visual-tactile", max_steps=int(sys.argv[2]), progress=False)
t2d = time.perf_counter() - t
sys.path.insert(0, "benchmarks")
from planning_step import make_data, THETA, NOISE, STEP
from torch_gpioius.exploration.planning import plan_direction
xo, yo, xi, yi = make_data(2000, 300 + 5 * 8)
m = tg.GPIOIS(torch.cat([xi[:300], xo]), torch.cat([yi[:300], yo]),
              torch.cat([torch.zeros(300, dtype=torch.long), torch.ones(2000, dtype=torch.long)]),
              kernel=IMQ(THETA), noise=NOISE).fit()
t = time.perf_counter()
for k in range(6):
    nx, ny = xi[300 + 5 * k:305 + 5 * k], yi[300 + 5 * k:305 + 5 * k]
    m.add_observations(nx, ny, 0); m.fit(); plan_direction(m, nx[0], step=STEP)
t3d = time.perf_counter() - t
print(json.dumps({"explore_2d_s": t2d, "steps_3d_s": t3d, "similarity": float(tr.similarity[-1])}))
"""


def launch(threads: int, steps: int) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": str(threads), "MKL_NUM_THREADS": str(threads)}
    return subprocess.Popen([sys.executable, "-c", WORK, str(threads), str(steps)], env=env, stdout=subprocess.PIPE,
                            text=True)


def arrangement(threads: int, copies: int, steps: int) -> list[dict]:
    procs = [launch(threads, steps) for _ in range(copies)]
    out = []
    for p in procs:
        stdout, _ = p.communicate()
        if p.returncode:
            raise SystemExit(f"worker failed with status {p.returncode}")
        out.append(json.loads(stdout.strip().splitlines()[-1]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=80, help="planning steps of the 2-D exploration")
    args = parser.parse_args()
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, python {platform.python_version()}")
    print("| arrangement | 2-D exploration per run [s] | 6 planning steps at 2000 + 300 per run [s] |")
    print("|---|---|---|")
    results = {}
    for threads, copies in ((1, 1), (2, 1), (1, 2), (2, 2)):
        time.sleep(1.0)
        r = arrangement(threads, copies, args.steps)
        e2 = sum(x["explore_2d_s"] for x in r) / len(r)
        e3 = sum(x["steps_3d_s"] for x in r) / len(r)
        results[(threads, copies)] = (e2, e3, {x["similarity"] for x in r})
        label = f"{copies} process{'es' if copies > 1 else ''} x {threads} thread{'s' if threads > 1 else ''}"
        print(f"| {label} | {e2:.2f} | {e3:.2f} |", flush=True)
    by_threads = {t: set().union(*(v[2] for (tt, _), v in results.items() if tt == t)) for t in (1, 2)}
    a, b = results[(1, 2)], results[(2, 2)]
    print(f"\nalone, 2 threads vs 1: {results[(1, 1)][0] / results[(2, 1)][0]:.2f}x (2-D), "
          f"{results[(1, 1)][1] / results[(2, 1)][1]:.2f}x (3-D) speed-up")
    print(f"two concurrent runs, 2 threads each vs 1 each: {b[0] / a[0]:.2f}x (2-D), {b[1] / a[1]:.2f}x (3-D) "
          "time per run")
    for t, sims in by_threads.items():
        print(f"final similarity, {t} thread(s): {sorted(sims)} "
              f"({'identical across arrangements' if len(sims) == 1 else 'DIFFERENT across arrangements'})")
    one, two = (next(iter(by_threads[t])) for t in (1, 2))
    print(f"1 vs 2 threads: {abs(one - two):.1e} apart (summation order)")


if __name__ == "__main__":
    main()
