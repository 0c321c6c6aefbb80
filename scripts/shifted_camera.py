"""Would the camera's observations moved inward by the gap the touches measure carry the cover's shape onto the body
better than the paper's labels, and can the touches themselves say when? On finished runs' final data
(docs/method-notes.md section 22).

For each visual-tactile log of a study: the run's own final model (``base``) against the same final data with every
camera observation (seen, free and inside points alike) moved inward along the seen cover's normal by the median
depth of the run's contacts under it (``shifted``): the gap that the simple baseline ``vision-shrunk-all`` shrinks
the camera's surface by (:mod:`torch_gpioius.baselines`: the camera's GPIS alone, its converged surface, each
contact's distance from it), the normal of the nearest vertex of that surface. The labels stay the paper's: a cover
that stands off by ``g`` becomes, moved by ``g``, a surface the inner one lies on, and K_t relates two shapes that
coincide instead of two a gap apart. K_t is re-learned (multi-start); the kernel and sigma^2 are the run's.

Each model's fit to the touches is scored without the truth: the sum of the inner task's leave-one-out log predictive
densities (:func:`inner_loo`, exact, from the dense Gram matrix at the learned hyperparameters). ``picked`` keeps the
model whose score is higher. Prints a row per run (the final Chamfer distance of each, the best simple baseline of the
study's ``runs.csv``, the scores) and the paired medians.

    python scripts/shifted_camera.py outputs/pl62/primitives-wide/logs/*visual-tactile*
"""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from worst_errors import final_arrays, offline_parser  # noqa: E402  (scripts/ is not a package)


def inner_loo(model) -> np.ndarray:
    """The leave-one-out log predictive density of each inner-task observation of a GPIOIS (or GPIS) ``model`` at its
    current hyperparameters, `(k,)` in the order of its inner rows.

    Dense and exact: with ``K`` the Gram matrix with sigma^2 on its diagonal and ``r`` the labels less their task's
    prior mean, observation ``i`` left out has predictive mean residual ``[K^-1 r]_i / [K^-1]_ii`` and variance
    ``1 / [K^-1]_ii`` (the Gaussian process's closed form; no refit). Written here because GPyTorch has the
    leave-one-out likelihood only as a training objective of its own models (``LeaveOneOutPseudoLikelihood``), not
    for a model whose labels carry a per-task mean as this one's do.
    """
    x = model.train_inputs[0].detach()
    y = model.train_targets.detach()
    task = model.train_task.detach().reshape(-1) if hasattr(model, "train_task") else torch.zeros(len(y), dtype=int)
    gram = model.covar_module.value(x, x).detach()
    if hasattr(model, "task_covariance"):
        kt = model.task_covariance.detach()
        gram = gram * kt[task][:, task]
    gram = gram + float(model.noise) * torch.eye(len(y), dtype=gram.dtype)
    outer_mean = getattr(model, "outer_mean", 1.0)
    residual = y - torch.where(task == 0, torch.ones_like(y), torch.full_like(y, outer_mean))
    inverse = torch.cholesky_inverse(torch.linalg.cholesky(gram))
    precision = inverse.diagonal()
    mean = (inverse @ residual) / precision
    density = -0.5 * torch.log(2 * math.pi / precision) - 0.5 * mean * mean * precision
    return density[task == 0].numpy()


def shifted_camera(outer_x: np.ndarray, outer_y: np.ndarray, contacts: np.ndarray, kernel, noise: float,
                   bounds: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The camera's observations `(n, 3)` [m] moved inward by the gap ``contacts`` `(k, 3)` measure, and that gap
    [m]; None where the camera's GPIS alone has no surface in ``bounds`` `(2, 3)` [m].

    The gap is the median of the contacts' depths under the camera's converged surface (as the baselines measure
    it: :func:`torch_gpioius.baselines.contact_depths`); each observation moves along the outward normal (the camera
    GPIS's gradient) of the surface's vertex nearest to it."""
    from scipy.spatial import cKDTree

    from torch_gpioius.baselines import BaselineData, contact_depths, vision_surface

    found = vision_surface(BaselineData(outer_x, outer_y, contacts, kernel, noise, bounds, 0.01))
    if found is None or not len(contacts):
        return None
    camera, mesh = found
    gap = float(np.median(contact_depths(camera, mesh, contacts)))
    gradients = np.asarray(mesh.metadata["gradients"], dtype=np.float64)
    normals = gradients / np.maximum(np.linalg.norm(gradients, axis=1, keepdims=True), 1e-300)
    _, nearest = cKDTree(np.asarray(mesh.vertices)).query(outer_x)
    return outer_x - gap * normals[nearest], gap


def best_baseline(log: Path) -> float:
    """The smallest final Chamfer distance [m] of the shrunk camera surfaces the study scored beside ``log``'s run
    (its ``runs.csv``); NaN where none is recorded."""
    table = log.parent.parent / "runs.csv"
    if not table.is_file():
        return math.nan
    name, seed = log.stem.split("_")[0], log.stem.rsplit("_", 1)[-1]
    for row in csv.DictReader(table.open()):
        if row.get("object") == name and row.get("mode") == "visual-tactile" and row.get("seed", seed) == seed:
            values = [float(v) for k, v in row.items() if k.startswith("baseline_vision-shrunk")
                      and k.endswith("_chamfer") and v not in ("", "nan")]
            return min(values) if values else math.nan
    return math.nan


def _chamfer(measured) -> float:
    return measured.shape["chamfer"] if measured.estimate else math.inf


def main() -> None:
    parser = offline_parser(__doc__)
    parser.add_argument("--first", type=int, default=0, help="the gap from the first this many contacts (0: all)")
    args = parser.parse_args()
    from torch_gpioius.models.gpiois import GPIOIS

    rows = []
    for log, run, world, model, x, y, task, contacts in final_arrays(args):
        outer = task == 1
        bounds = np.stack([x[outer].min(0) - 0.1, x[outer].max(0) + 0.1])
        moved = shifted_camera(x[outer], y[outer], contacts[:args.first] if args.first else contacts, run.kernel(),
                               float(model.noise), bounds)
        if moved is None:
            continue
        shifted = GPIOIS(np.r_[x[~outer], moved[0]], np.r_[y[~outer], y[outer]],
                         np.r_[task[~outer], task[outer]], noise=float(model.noise), kernel=run.kernel())
        shifted.fit(multi_start=True)
        base, other = _chamfer(world.measure(model, contacts)), _chamfer(world.measure(shifted, contacts))
        score_base, score_shifted = float(inner_loo(model).sum()), float(inner_loo(shifted).sum())
        picked = other if score_shifted > score_base else base
        rows.append((base, other, picked, best_baseline(log)))
        print(f"{log.stem}: base {base * 100:.2f} cm (correlation {model.correlation:.2f}) | gap {moved[1] * 100:.1f} "
              f"cm, shifted {other * 100:.2f} cm ({shifted.correlation:.2f}) | leave-one-out {score_base:.1f} / "
              f"{score_shifted:.1f}: {'shifted' if picked is other else 'base'} | best baseline "
              f"{rows[-1][3] * 100:.2f} cm", flush=True)
    if rows:
        base, other, picked, baseline = (np.array(c) * 100 for c in zip(*rows))
        print(f"{len(rows)} runs, median Chamfer [cm]: base {np.median(base):.2f}, shifted {np.median(other):.2f} "
              f"(closer on {(other < base).sum()}, paired {np.median(other - base):+.2f}), picked "
              f"{np.median(picked):.2f}, best baseline {np.median(baseline):.2f}; ahead of the best baseline: base "
              f"{(base < baseline).sum()}, shifted {(other < baseline).sum()}, picked {(picked < baseline).sum()}")


if __name__ == "__main__":
    main()
