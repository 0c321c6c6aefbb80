"""What the MuJoCo world costs: build and settle time, real-time factor, and where an exploration step's time goes.

For each object E-H (``mujoco_objects_3d``): the time to build and settle the scene, the real-time factor of the
settled scene with the arm holding still (simulated seconds per wall second), and a short visual-tactile
exploration (``--travel`` metres) split into the GP side of a step (plan + ingest + re-learn, what the paper
needed 8 s for) and the physics side (the fingertip's motion simulated in MuJoCo), measured in the same run.

    python benchmarks/mujoco_world.py                   # about 5 minutes on 2 cores
    python benchmarks/mujoco_world.py --objects E --travel 0.1
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
import torch

import torch_gpioius as tg
from torch_gpioius.sim.mujoco.objects import mujoco_objects_3d


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", default="E,F,G,H")
    parser.add_argument("--travel", type=float, default=0.25, help="fingertip travel of the timed exploration [m]")
    args = parser.parse_args()
    import mujoco

    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, mujoco {mujoco.__version__}, "
          f"torch {torch.__version__} ({torch.get_num_threads()} threads)")
    print("| object | cover vertices | build + settle [s] | real-time factor | steps | GP per step [ms] | "
          "physics per step [s] | simulated time per step [s] |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.objects.split(","):
        t = time.perf_counter()
        scene = mujoco_objects_3d([name])[name]
        build = time.perf_counter() - t
        rtf = scene.real_time_factor(1.0)
        t = time.perf_counter()
        trace = tg.explore(scene, mode="visual-tactile", max_travel=args.travel, progress=False, metrics_every=1000)
        wall = time.perf_counter() - t
        n = trace.n_steps - 1
        gp = float(np.sum(trace.step_time[1:]))
        sim_time = float(trace.robot_time[-1] - trace.robot_time[0])
        print(f"| {name} | {len(scene.cover.vertices)} | {build:.1f} | {rtf:.2f} | {n} | "
              f"{1e3 * float(np.median(trace.step_time[1:])):.0f} | {(wall - gp) / max(n, 1):.2f} | "
              f"{sim_time / max(n, 1):.2f} |", flush=True)


if __name__ == "__main__":
    main()
