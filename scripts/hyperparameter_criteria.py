"""Which criterion would pick the kernel's length scale and the noise? Each one, against the shape it gives.

For each scene file and seed: a 0.15 m visual-tactile exploration with the scene's default settings (three views,
Matérn-5/2 of 0.1 m, sigma^2 0.08), then, on its final data, the length scale, sigma^2 and K_t learned together with
autograd (L-BFGS through one dense Cholesky, the length scale bounded to [0.02, 0.5] m and sigma^2 to [1e-4, 0.5])
by four criteria:

* ``mll``: the exact log marginal likelihood;
* ``loo``: the exact leave-one-out predictive log likelihood of every label (closed form from ``G^-1``: the held-out
  residual is ``alpha_i / [G^-1]_ii`` and its variance ``1 / [G^-1]_ii``, Rasmussen & Williams eq. 5.10-5.12);
* ``loo_inner``: the same summed over the touch task's labels only;
* ``loo_touch``: summed over the touched surface points only (the labels nearest the inner shape);
* ``cv_geo``: a criterion that scores the zero level itself, in metres. The touch task's data are cut, in the order
  they arrived, into five contiguous blocks (five pieces of the path, each with its free-space and inside points);
  each block is held out in turn, exactly (its held-out mean is ``y_B - [G^-1]_BB^-1 alpha_B``, the block form of
  eq. 5.12), and each held-out touched surface point scores its first-order distance from the zero level of the
  other data, ``mu_-B(x) / |grad mu(x)|`` (the gradient of the full posterior mean, analytic for the Matérn-5/2).
  The criterion is minus the mean squared distance: how far the estimate from the rest of the path misses the
  surface where the fingertip went next;

and the shape each gives (Chamfer, F-score at 1 cm, bias, Hausdorff; ``Scene3D.measure``) beside the fixed defaults.
docs/method-notes.md ("Learning theta and sigma^2") reports what it printed.

    python scripts/hyperparameter_criteria.py examples/scenes/real/duck-tight.toml 0 1 2
"""

from __future__ import annotations

import math
import sys
import time
import warnings

import torch

import torch_gpioius as tg
from torch_gpioius.sim.scenefile import load_scene

CRITERIA = ("mll", "loo", "loo_inner", "loo_touch", "cv_geo")
FOLDS = 5
ELL, NOISE = (0.02, 0.5), (1e-4, 0.5)


def _gram(x, t, ell, s, chol):
    """Dense Gram matrix of the Matérn-5/2 with K_t = chol chol^T, differentiable in ell, s and chol."""
    r = torch.cdist(x, x).pow(2).clamp_min(1e-30).sqrt()
    z = math.sqrt(5.0) * r / ell
    k = (1 + z + z * z / 3) * torch.exp(-z)
    kt = chol @ chol.T
    return k * kt[t][:, t] + s * torch.eye(len(x), dtype=x.dtype)


def _unpack(p):
    ell = p[0].clamp(math.log(ELL[0]), math.log(ELL[1])).exp()
    s = p[1].clamp(math.log(NOISE[0]), math.log(NOISE[1])).exp()
    zero = torch.zeros((), dtype=p.dtype)
    chol = torch.stack([torch.stack([p[2].exp(), zero]), torch.stack([p[3], p[4].exp()])])
    return ell, s, chol


def criterion(p, x, y, t, which: str):
    ell, s, chol = _unpack(p)
    c = torch.linalg.cholesky(_gram(x, t, ell, s, chol))
    r = (y - 1.0).unsqueeze(-1)                                  # prior mean 1 (eq. 2)
    alpha = torch.cholesky_solve(r, c).squeeze(-1)
    if which == "mll":
        return -(0.5 * (r.squeeze(-1) @ alpha) + c.diagonal().log().sum())
    if which == "cv_geo":
        return _cv_geo(x, y, t, ell, chol, c, alpha)
    var = 1.0 / torch.cholesky_inverse(c).diagonal()
    ll = -0.5 * var.log() - 0.5 * (alpha * var) ** 2 / var
    keep = {"loo": torch.ones_like(y, dtype=torch.bool), "loo_inner": t == 0, "loo_touch": (t == 0) & (y == 0)}[which]
    return ll[keep].sum()


def _cv_geo(x, y, t, ell, chol, c, alpha):
    """Minus the mean squared distance [m^2] of held-out touched surface points from the other data's zero level."""
    inv = torch.cholesky_inverse(c)
    inner = torch.nonzero(t == 0).squeeze(-1)
    # grad mu(x_i) = sum_j grad_x k(x_i, x_j) alpha_j; Matern-5/2: grad_x k = -(5 / 3 ell^2) (1 + z) e^-z (x - x')
    surface = inner[y[inner] == 0]
    d = x[surface].unsqueeze(1) - x.unsqueeze(0)
    z = math.sqrt(5.0) * d.pow(2).sum(-1).clamp_min(1e-30).sqrt() / ell
    kt = chol @ chol.T
    w = -(5.0 / (3.0 * ell * ell)) * (1 + z) * torch.exp(-z) * kt[0][t]
    grad = torch.einsum("ij,ijk,j->ik", w, d, alpha)
    gnorm = dict(zip(surface.tolist(), grad.norm(dim=-1).clamp_min(1e-6)))
    sq = []
    for block in torch.tensor_split(inner, FOLDS):
        e = -torch.linalg.solve(inv[block][:, block], alpha[block])      # mu_-B(x_B) - y_B
        for k, i in enumerate(block.tolist()):
            if i in gnorm:
                sq.append((e[k] / gnorm[i]) ** 2)                     # y_i = 0: mu_-B(x_i) is the miss itself
    return -torch.stack(sq).mean()


def learn(x, y, t, which: str, model) -> tuple[float, float]:
    chol = torch.linalg.cholesky(model.task_covariance + 1e-9 * torch.eye(2, dtype=torch.float64))
    p = torch.tensor([math.log(0.1), math.log(0.08), math.log(chol[0, 0]), chol[1, 0], math.log(chol[1, 1])],
                     dtype=torch.float64, requires_grad=True)
    opt = torch.optim.LBFGS([p], lr=0.5, max_iter=60, line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        f = -criterion(p, x, y, t, which)
        f.backward()
        return f

    opt.step(closure)
    ell, s, _ = _unpack(p.detach())
    return float(ell), float(s)


def main(argv: list[str]) -> None:
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    path, seeds = argv[0], [int(v) for v in argv[1:]] or [0]
    print("| scene | seed | criterion | length scale [m] | sigma^2 | H [cm] | Chamfer [cm] | F@1cm | bias [cm] | "
          "correlation | learning [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for seed in seeds:
        scene = load_scene(path, seed=seed)
        trace = tg.explore(scene, max_travel=0.15, metrics_every=1000)
        x, y, t = trace.model.train_inputs[0], trace.model.train_targets, trace.model.train_task
        rows = [("fixed", 0.1, 0.08, 0.0)]
        for which in CRITERIA:
            t0 = time.perf_counter()
            rows.append((which, *learn(x, y, t, which, trace.model), time.perf_counter() - t0))
        for which, ell, s, seconds in rows:
            model = tg.GPIOIS(x, y, t, kernel=tg.kernels.Matern52(ell), noise=s).fit()
            m = scene.measure(model, trace.contacts)
            sh = m.shape
            print(f"| {scene.name} | {seed} | {which} | {ell:.3f} | {s:.4f} | {m.hausdorff * 100:.1f} | "
                  f"{sh['chamfer'] * 100:.2f} | {sh['fscore_10mm']:.2f} | {sh['bias'] * 100:.2f} | "
                  f"{model.correlation:.2f} | {seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
