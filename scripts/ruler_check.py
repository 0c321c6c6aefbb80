"""Whether the converged ruler has converged on a study's runs: each final estimate measured on the ruler's grid and on
one half as fine, and by marching cubes alone on a 2 cm grid (the ruler of earlier releases).

For each log of the study folders given (visual-tactile runs of the force-field world; an object of a set or a scene
file, rebuilt from its record as ``scripts/worst_errors.py`` does), prints a row per run and then, per metric, the
largest change at the halved grid (relative to the value, or absolute where the value is near zero: 0.05 mm for a
distance, 0.01 for a share) and the median change the old ruler made.

    python scripts/ruler_check.py outputs/benchmark/primitives-tight outputs/benchmark/random-tight --runs 20
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from worst_errors import world_of  # noqa: E402

#: (key, label, absolute floor below which a change is read absolutely)
KEYS = [("chamfer", "Chamfer", 5e-5), ("fscore_5mm", "F 5 mm", 0.01), ("fscore_10mm", "F 1 cm", 0.01),
        ("bias", "bias", 5e-5), ("hausdorff", "H", 5e-5), ("hausdorff_observed", "H observed", 5e-5),
        ("unseen", "unseen", 0.01), ("uncertainty", "U", 1e-3)]


def measure(model, world, grid: float) -> dict:
    from torch_gpioius.sim.forcefield import estimate_metrics_3d

    m = estimate_metrics_3d(model, world, grid)
    return {**m.shape, "hausdorff": m.hausdorff, "uncertainty": m.uncertainty} if m.estimate else {}


def old_ruler(model, world) -> dict:
    """Marching cubes alone on a 2 cm grid over the range grown by 5 cm, its facets as they are."""
    from torch_gpioius.sim.forcefield import METRICS_EDGE, score_surface
    from torch_gpioius.geometry.surfaces import evaluate_grid, zero_level_mesh

    observed = model.train_inputs[0].detach().cpu().numpy()[model.train_targets.detach().cpu().numpy() == 0]
    field = evaluate_grid(model, world.bounds(0.05), 0.02, 0, variance=False)
    scored = score_surface(world, zero_level_mesh(model, None, field=field), None, observed, METRICS_EDGE)
    return {} if scored is None else {**scored[2], "hausdorff": scored[1]}


def change(a: float, b: float, floor: float) -> float:
    """|a - b| relative to |b|, or in units of ``floor`` where |b| is below it (a share of 1 = the floor)."""
    if not (math.isfinite(a) and math.isfinite(b)):
        return math.nan
    return abs(a - b) / max(abs(b), floor)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path, help="study folders (with logs/ and runs/)")
    parser.add_argument("--runs", type=int, default=20, help="runs at most, taken evenly over the logs")
    args = parser.parse_args()
    import torch

    from torch_gpioius.io.runs import load_run
    from torch_gpioius.sim.forcefield import METRICS_GRID

    torch.set_num_threads(1)
    logs = sorted(p for f in args.folders for p in (f / "logs").glob("*_visual-tactile_*.gpioius"))
    if not logs:
        parser.error("no visual-tactile logs in the folders given")
    logs = [logs[int(i)] for i in np.unique(np.linspace(0, len(logs) - 1, min(args.runs, len(logs))).round())]
    worst = {k: (0.0, "") for k, _, _ in KEYS}
    moved = {k: [] for k, _, _ in KEYS}
    print("| run | Chamfer [cm] | halved | old ruler | H [cm] | halved | bias [mm] | halved |")
    print("|---|---|---|---|---|---|---|---|")
    for log in logs:
        run = load_run(log)
        world = world_of(log, log.parent.parent)
        model = run.model_at(run.steps[-1])
        a, b = measure(model, world, METRICS_GRID), measure(model, world, METRICS_GRID / 2)
        old = old_ruler(model, world)
        if not a or not b:
            print(f"| {log.stem} | no estimate on {'the ruler' if not a else 'the halved'} grid | | | | | | |")
            continue
        for key, _, floor in KEYS:
            c = change(a[key], b[key], floor)
            if math.isfinite(c) and c > worst[key][0]:
                worst[key] = (c, log.stem)
            if old and key in old:
                moved[key].append((old[key] - a[key]) / max(abs(a[key]), floor))
        old_chamfer = 100 * old["chamfer"] if old else math.nan
        print(f"| {log.stem} | {100 * a['chamfer']:.3f} | {100 * b['chamfer']:.3f} | {old_chamfer:.3f} | "
              f"{100 * a['hausdorff']:.2f} | {100 * b['hausdorff']:.2f} | {1000 * a['bias']:+.2f} | "
              f"{1000 * b['bias']:+.2f} |")
    print(f"\nlargest change at the halved grid ({len(logs)} runs), and the median change by the old ruler:")
    for key, label, floor in KEYS:
        c, where = worst[key]
        m = moved[key]
        old = f"{100 * np.median(m):+.1f} % (range {100 * min(m):+.0f} to {100 * max(m):+.0f} %)" if m else "-"
        print(f"  {label}: {100 * c:.2f} % ({where or '-'}); old ruler {old}")


if __name__ == "__main__":
    main()
