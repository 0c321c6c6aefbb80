"""Is a task covariance of rank one harmful? Finished visual-tactile runs' final estimates with K_t held at other
correlations (issue 62: "K_t kept away from a rank-1 collapse or shown to be harmless there").

Under tight covers the learned correlation ``K01 / sqrt(K00 K11)`` is 1.00 on every run. With rank one the inner
field is an affine image of the outer one, ``f_in - 1 = (K01 / K11) (f_out - m_out)``, and a regression coefficient
below one puts the inner surface on a level set of the outer field inside the seen cover: the same shape standing off,
which is what a tight cover is (docs/method-notes.md, "Rank one"). Held below one, the inner task gets a part of its
own that the contacts alone inform.

For each log: the run's final data and model; K_t as learned, then at each ``--rho`` the MLL's best K_t with the
correlation fixed there (its two variances maximised out: the profile likelihood), the kernel and sigma^2 as the run
left them. Each is measured by the converged ruler. Printed: Chamfer [cm] per correlation and the drop of the log
marginal likelihood from the learned K_t.

    python scripts/rank_one.py outputs/es63/none-primitives/logs/*.gpioius --rho 0.98 0.9 0.7
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from worst_errors import visual_tactile_finals  # noqa: E402  (scripts/ is not a package)


def held_at(model, rho: float) -> tuple[torch.Tensor, float]:
    """The MLL's best K_t `(2, 2)` with the correlation fixed at ``rho``, and its log marginal likelihood."""
    from torch_gpioius.inference.interval import _correlation_map, profile_correlation

    engine = model._inference()
    x0 = model.train_inputs[0]
    kt = model.task_covariance
    start = np.array([0.5 * math.log(float(kt[0, 0])), 0.5 * math.log(float(kt[1, 1]))])
    f, x = profile_correlation(lambda k: engine.mll_derivatives(k.to(dtype=x0.dtype, device=x0.device)), rho, start)
    a, b, c = _correlation_map(rho)(x)[0]
    return torch.tensor([[a, b], [b, c]], dtype=torch.float64), float(f)


def implied_gap(model, seen: np.ndarray) -> float:
    """The gap [m] a rank-one K_t puts between the seen cover and the inner surface, to first order: the inner zero
    set is the outer field's level ``m_out - S`` (``S = K01 / K00``), so at each seen point ``x`` the gap is
    ``(mu_out(x) - m_out + S) / |grad mu_out(x)|``; the median over the `(n, 3)` seen points."""
    x = torch.as_tensor(seen, dtype=torch.float64).requires_grad_(True)
    mu = model.predict_mean(x, task=1)
    (grad,) = torch.autograd.grad(mu.sum(), x)
    level = float(model.outer_mean) - model.similarity
    return float(np.median((mu.detach().numpy() - level) / grad.norm(dim=1).numpy()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+", type=Path)
    parser.add_argument("--scenes", type=Path, default=Path("examples/scenes/real"))
    parser.add_argument("--rho", type=float, nargs="+", default=[0.98, 0.9, 0.7])
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    rows, gaps = [], []
    for log, _run, world, model, data in visual_tactile_finals(args.logs, args.scenes):
        contacts = data.x[(data.task == 0) & (data.y == 0)]
        learned = model.task_covariance
        rho_hat = model.correlation
        seen = np.asarray(data.x[(data.task == 1) & (data.y == 0)])
        gap = implied_gap(model, seen) if rho_hat > 0.999 else math.nan
        true_gap = float(np.median(world.true_distance(seen)))
        _, f_hat = held_at(model, float(np.clip(rho_hat, -1.0, 1.0)))
        chamfer, drops = [], []
        for rho in [None, *args.rho]:
            if rho is None:
                model.task_covariance = learned
                drop = 0.0
            else:
                kt, f = held_at(model, rho)
                model.task_covariance = kt
                drop = f_hat - f
            measured = world.measure(model, contacts)
            chamfer.append(measured.shape["chamfer"] * 100 if measured.estimate else math.inf)
            drops.append(drop)
        model.task_covariance = learned
        rows.append(chamfer)
        gaps.append((gap, true_gap))
        print(f"{log.stem}: correlation {rho_hat:.3f} similarity {model.similarity:.2f} implied gap "
              f"{gap * 1e3:.1f} mm (seen points' distance from the body {true_gap * 1e3:.1f}) | Chamfer learned "
              f"{chamfer[0]:.2f} cm, " + ", ".join(f"rho {r:g}: {c:.2f} (MLL -{d:.1f})"
                                                  for r, c, d in zip(args.rho, chamfer[1:], drops[1:])), flush=True)
    if rows:
        ch = np.array(rows)
        print(f"{len(rows)} runs: median Chamfer learned {np.median(ch[:, 0]):.2f} cm, "
              + ", ".join(f"rho {r:g} {np.median(ch[:, j + 1]):.2f} (closer than learned on "
                          f"{(ch[:, j + 1] < ch[:, 0]).sum()})" for j, r in enumerate(args.rho)))
        g = np.array(gaps) * 1e3
        ok = np.isfinite(g[:, 0])
        print(f"  rank one on {ok.sum()} of {len(g)}: implied gap median {np.median(g[ok, 0]):.1f} mm "
              f"[IQR {np.percentile(g[ok, 0], 25):.1f}-{np.percentile(g[ok, 0], 75):.1f}], the seen points' distance "
              f"from the body {np.median(g[ok, 1]):.1f} mm")


if __name__ == "__main__":
    main()
