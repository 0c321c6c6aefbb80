"""What a whole exploration run spends its time on: the method, the camera, the contact and the measuring.

A visual-tactile run in the force-field world (a scene file; by default the tight bunny of
``examples/scenes/real/bunny-tight.toml``, the library's default settings, one torch thread) is timed whole, and
four parts of it are timed inside the same run by the exploration's own clock
(:class:`torch_gpioius.exploration.timing.PartClock`, which every study run records as its ``time_*`` columns):

* **camera**: the simulated depth camera's captures (``PointCloudSource.capture`` of every view; ray casting, with
  Embree where ``embreex`` is installed);
* **contact**: the fingertip's guarded motions (``ContactController.approach`` / ``slide`` / ``lift``: the force
  field, the UR5's forward and inverse kinematics, the sensor);
* **measuring**: the ground-truth metrics of the estimate against the body (``World.measure``: the converged ruler's
  mesh, its vertices moved onto mu = 0 and its facets split to 5 mm, then Chamfer, F-score, bias, Hausdorff);
* **method**: the rest, what the paper's method itself does (planning steps, labelling, the model's updates and
  K_t's re-learning, the similarity's interval, the log).

Each part is printed as seconds and as a share of the run, for two measuring schedules run one after the other on
the same scene and seed: every 5 steps (the studies' ``BUDGET_METRICS_EVERY``) and ``metrics_every="schedule"``
(10, 25 and 50 % of the travel, a stop, the end). The ratio of the two runs' wall times is what the schedule saves.
The runs differ a little in path length as the chaos of the sliding allows; the shares are what to read.

    python benchmarks/run_cost.py                      # 0.15 m of travel, about 1-2 minutes on 2 cores
    python benchmarks/run_cost.py --travel 0.6         # the studies' travel
"""

from __future__ import annotations

import argparse
import platform
from pathlib import Path

import torch

import torch_gpioius as tg
from torch_gpioius.sim.scenefile import load_scene

ROOT = Path(__file__).resolve().parents[1]


def one_run(scene_file: Path, travel: float, metrics_every) -> dict:
    """One visual-tactile run timed whole and by part: ``{"total", "camera", "contact", "measuring", "method",
    "steps", "measured"}``."""
    world = load_scene(scene_file)
    trace = tg.explore(world, "visual-tactile", max_travel=travel, metrics_every=metrics_every, interval_every=10)
    measured = int(sum(1 for h in trace.hausdorff if h == h))
    return {**trace.time_split, "steps": len(trace.hausdorff) - 1, "measured": measured}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", type=Path, default=ROOT / "examples/scenes/real/bunny-tight.toml")
    parser.add_argument("--travel", type=float, default=0.15, help="travel budget of each run [m]")
    args = parser.parse_args()
    torch.set_num_threads(1)
    try:
        import embreex  # noqa: F401
        rays = "Embree (embreex)"
    except ImportError:
        rays = "trimesh's Python ray engine (no embreex)"
    print(f"{platform.processor() or platform.machine()}, torch {torch.__version__}, 1 thread; rays: {rays}")
    print(f"scene {args.scene.name}, visual-tactile, {args.travel:g} m of travel\n")
    rows = {}
    for label, every in (("every 5 steps", 5), ("schedule", "schedule")):
        rows[label] = one_run(args.scene, args.travel, every)
    print("| measuring | steps | measured | total [s] | method | camera | contact | measuring |")
    print("|---|---|---|---|---|---|---|---|")
    for label, r in rows.items():
        shares = " | ".join(f"{r[k]:.1f} s ({100 * r[k] / r['total']:.0f} %)"
                            for k in ("method", "camera", "contact", "measuring"))
        print(f"| {label} | {r['steps']} | {r['measured']} | {r['total']:.1f} | {shares} |")
    a, b = rows["every 5 steps"], rows["schedule"]
    print(f"\nratio of wall times, every 5 steps / schedule: {a['total'] / b['total']:.2f}; the method's share "
          f"{100 * a['method'] / a['total']:.0f} % -> {100 * b['method'] / b['total']:.0f} %")


if __name__ == "__main__":
    main()
