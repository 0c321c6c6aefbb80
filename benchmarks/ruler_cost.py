"""What one measurement of an estimate costs, and how far it is from the figures of a very fine one.

A visual-tactile run of a scene file (by default the tight bunny of ``examples/scenes/real/bunny-tight.toml``, the
studies' 0.6 m, the defaults, one torch thread) gives a final estimate; it is then measured against the body

* by the converged ruler (``World.measure``: marching cubes on a 1 cm grid, the vertices moved onto mu = 0, the facets
  split to 1 cm and their chords corrected), and on a grid half as fine (its convergence);
* by marching cubes alone on the 2 cm grid (the ruler of the releases before: the facets as they are);
* by a reference ten times as fine in its facets (a 5 mm grid, facets of 2.5 mm, corrected);

each timed over ``--repeat`` calls in this one run (the medians), with its figures and their differences from the
reference's. The ratio of the converged ruler's time to the old one's is what a run pays for figures that hold.

    python benchmarks/ruler_cost.py
    python benchmarks/ruler_cost.py --scene examples/scenes/real/teddy-wide.toml --travel 0.3
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from pathlib import Path

import numpy as np
import torch

import torch_gpioius as tg
from torch_gpioius.sim.forcefield import METRICS_EDGE, METRICS_GRID, score_surface
from torch_gpioius.sim.scenefile import load_scene
from torch_gpioius.geometry.surfaces import converged_level_mesh, evaluate_grid, zero_level_mesh

ROOT = Path(__file__).resolve().parents[1]
KEYS = ("chamfer", "fscore_5mm", "fscore_10mm", "bias", "hausdorff")


def _observed(model) -> np.ndarray:
    return model.train_inputs[0].detach().cpu().numpy()[model.train_targets.detach().cpu().numpy() == 0]


def converged(model, world, grid: float, edge: float) -> dict:
    field = evaluate_grid(model, world.bounds(grid), grid, 0, variance=False)
    whole = converged_level_mesh(model, None, field=field, edge=edge, keep=world.range)

    def mean(points):
        with torch.no_grad():
            return model.predict_mean(torch.as_tensor(points), task=0).detach().cpu().numpy()

    _, h, shape = score_surface(world, whole, None, _observed(model), edge, mean=mean)
    return {**shape, "hausdorff": h}


def marching_cubes_alone(model, world, grid: float) -> dict:
    field = evaluate_grid(model, world.bounds(0.05), grid, 0, variance=False)    # the old ruler's grid box
    _, h, shape = score_surface(world, zero_level_mesh(model, None, field=field), None, _observed(model),
                                METRICS_EDGE)
    return {**shape, "hausdorff": h}


def timed(function, repeat: int) -> tuple[dict, float]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = function()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", type=Path, default=ROOT / "examples/scenes/real/bunny-tight.toml")
    parser.add_argument("--travel", type=float, default=0.6, help="the run's travel [m]")
    parser.add_argument("--repeat", type=int, default=3, help="timed calls of each ruler")
    args = parser.parse_args()
    torch.set_num_threads(1)
    world = load_scene(args.scene)
    trace = tg.explore(world, "visual-tactile", max_travel=args.travel, metrics_every="schedule", interval_every=1000)
    model = trace.model
    print(f"{platform.processor() or platform.machine()}, torch {torch.__version__}, 1 thread; {args.scene.name}, "
          f"{args.travel:g} m, {len(model.train_targets)} observations\n")
    world.measure(model, trace.contacts)                      # the body's quadrature, built once per world
    rulers = {
        f"converged ({METRICS_GRID * 100:g} cm grid, {METRICS_EDGE * 1000:g} mm facets)":
            lambda: converged(model, world, METRICS_GRID, METRICS_EDGE),
        f"converged, grid halved ({METRICS_GRID * 50:g} cm)": lambda: converged(model, world, METRICS_GRID / 2,
                                                                               METRICS_EDGE),
        "marching cubes alone (2 cm grid, the ruler before)": lambda: marching_cubes_alone(model, world, 0.02),
        "reference (5 mm grid, 2.5 mm facets)": lambda: converged(model, world, 0.005, 0.0025),
    }
    results = {name: timed(f, args.repeat if "reference" not in name else 1) for name, f in rulers.items()}
    ref = results["reference (5 mm grid, 2.5 mm facets)"][0]
    print("| ruler | time [s] | Chamfer [cm] | F 5 mm | F 1 cm | bias [mm] | H [cm] | Chamfer - reference |")
    print("|---|---|---|---|---|---|---|---|")
    for name, (fig, t) in results.items():
        d = 100 * (fig["chamfer"] - ref["chamfer"]) / ref["chamfer"]
        print(f"| {name} | {t:.3f} | {100 * fig['chamfer']:.4f} | {fig['fscore_5mm']:.4f} | {fig['fscore_10mm']:.4f} | "
              f"{1000 * fig['bias']:+.3f} | {100 * fig['hausdorff']:.3f} | {d:+.2f} % |")
    names = list(results)
    print(f"\nratio of times, converged / marching cubes alone: {results[names[0]][1] / results[names[2]][1]:.2f}")


if __name__ == "__main__":
    main()
