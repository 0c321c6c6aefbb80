"""Time one GPIOIS planning step: fast exact engine vs the naive per-step GPyTorch refit, in one run.

A planning step = ingest one contact + 4 free-space points, re-learn K_t to convergence (warm start from the
previous step), compute the next sliding direction (eq. 19) at the contact.

(a) fast:  ``GPIOIS(inference="structured")``: ``add_observations`` -> ``fit()`` (Newton, analytic derivatives)
           -> ``plan_direction``.
(b) naive: a fresh GPyTorch ``ExactGP`` (IMQ x IndexKernel, exact Cholesky settings) on all data each step,
           K_t learned by ``torch.optim.LBFGS`` (strong Wolfe) on ``ExactMarginalLogLikelihood`` to a gradient
           tolerance 100x tighter, no loss-change stop, warm-started from its previous K_t; direction from the
           GPyTorch posterior by autograd.

(a) runs alone over all steps first, as in an exploration loop (interleaving (b)'s large matrices between (a)'s
steps evicts (a)'s data from the caches and adds up to ~50 % noise to its timings); (b) and the dense check then
run over the same steps and data and are compared with what (a) recorded at each step.

Data: 3-D, outer points on an ellipsoid (half on it, y = 0; half 5 cm outside, y = 1), inner contacts on a
smaller ellipsoid with 20 % free space; theta = 0.15, sigma^2 = 0.08 (the paper's 3-D settings).
Prints medians, the ratio (b)/(a), the one-time setup cost, the largest disagreement between (a) and (b), and,
per step, the largest disagreement between (a) and the dense exact engine (one Cholesky of the full Gram matrix)
at (a)'s K_t, including the Newton step from there to the exact optimum. (b)'s L-BFGS stops on its own
tolerances, so (a) vs (b) mixes the two optimisers' convergence; (a) vs dense isolates the fast engine.

    python benchmarks/planning_step.py                    # N_outer 500, 2000, 8000 x N_inner 50, 300
    python benchmarks/planning_step.py --outer 500 --inner 50 --steps 3   # quick
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import time

import gpytorch
import numpy as np
import torch

import torch_gpioius as tg
from torch_gpioius.inference import DenseExactInference
from torch_gpioius.inference.optim import (
    chain_to_cholesky,
    chol_params_to_task_covariance,
    task_covariance_to_chol_params,
)
from torch_gpioius.exploration.planning import plan_direction
from torch_gpioius.kernels import InverseMultiquadricKernel as IMQ

THETA, NOISE, STEP = 0.15, 0.08, 0.01


def make_data(n_outer: int, n_inner_total: int, seed: int = 0):
    rng = np.random.default_rng(seed)

    def ellipsoid(n, radii):
        v = rng.normal(size=(n, 3))
        return v / np.linalg.norm(v, axis=1, keepdims=True) * np.asarray(radii)

    xo = np.concatenate([ellipsoid(n_outer // 2, (0.25, 0.18, 0.3)),
                         ellipsoid(n_outer - n_outer // 2, (0.30, 0.23, 0.35))])
    yo = np.r_[np.zeros(n_outer // 2), np.ones(n_outer - n_outer // 2)]
    # inner stream: groups of 1 contact (y = 0) + 4 free-space points 3 cm outside (y = 1)
    contacts = ellipsoid(n_inner_total // 5, (0.2, 0.14, 0.25))
    xi, yi = [], []
    for c in contacts:
        xi.append(c[None]), yi.append([0.0])
        free = c * (1 + 0.03 / np.linalg.norm(c)) + 0.01 * rng.normal(size=(4, 3))
        xi.append(free), yi.append([1.0] * 4)
    return (torch.tensor(xo), torch.tensor(yo), torch.tensor(np.concatenate(xi)), torch.tensor(np.concatenate(yi)))


def naive_step(x, y, t, kt_init, contact):
    """Per-step GPyTorch refit with L-BFGS; returns K_t, MLL, mu, V at contact, direction."""
    model = tg.GPIOIS(x, y, t, kernel=IMQ(THETA), noise=NOISE, task_covariance=kt_init, inference="dense")
    model.train()
    mll = gpytorch.mlls.ExactMarginalLogLikelihood(model.likelihood, model)
    params = [model.task_covar_module.covar_factor]
    n = len(y)
    opt = torch.optim.LBFGS(params, lr=1.0, max_iter=200, tolerance_grad=0.01 * tg.tol.fit_gtol / n,
                            tolerance_change=0.0, history_size=20, line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        with tg.exact_arithmetic():   # forward *and* backward: linear_operator reads the settings in backward
            loss = -mll(model(*model.train_inputs), model.train_targets)
            loss.backward()
        return loss

    for _ in range(5):
        opt.step(closure)
        g = params[0].grad
        if g is not None and float(g.abs().max()) <= 0.01 * tg.tol.fit_gtol / n:
            break
    with torch.no_grad(), tg.exact_arithmetic():   # LBFGS.step returns the loss at the start of its last step
        loss = -mll(model(*model.train_inputs), model.train_targets)
    model.eval()
    xq = contact.reshape(1, -1).clone().requires_grad_(True)
    # The backward pass must run inside the exact context too: linear_operator's autograd functions read the
    # settings again in backward and would otherwise take CG above N = 800 (docs/theory.md).
    with tg.exact_arithmetic():
        post = model(xq, 0)
        mean, var = post.mean, post.variance
        g_mu, = torch.autograd.grad(mean.sum(), xq, retain_graph=True)
        g_v, = torch.autograd.grad(var.sum(), xq)
    nrm = g_mu[0] / g_mu[0].norm()
    pg = g_v[0] - (g_v[0] @ nrm) * nrm
    direction = STEP * pg / pg.norm()
    return (model.task_covariance, -float(loss) * n, float(mean.detach()), float(var.detach()), direction.detach())


def timed_steps(n_outer: int, n_inner: int, steps: int, record: bool, device: str = "cpu", **model_kwargs) -> dict:
    """The structured engine alone: setup (engine, then the first fit) and ``steps`` planning steps, timed as in an
    exploration loop. With ``record``, each step's K_t, MLL, mu and V at the contact, direction and
    ``GPIOIS.truncation`` (taken outside the timed part). ``model_kwargs`` go to ``GPIOIS`` (e.g. ``outer_tol``)."""
    data = make_data(n_outer, n_inner + 5 * (steps + 1))
    xo, yo, xi_all, yi_all = data
    t0 = time.perf_counter()
    model = tg.GPIOIS(torch.cat([xi_all[:n_inner], xo]), torch.cat([yi_all[:n_inner], yo]),
                      torch.cat([torch.zeros(n_inner, dtype=torch.long), torch.ones(n_outer, dtype=torch.long)]),
                      kernel=IMQ(THETA), noise=NOISE, inference="structured", device=device, **model_kwargs)
    model._inference()
    t_engine = time.perf_counter() - t0
    model.fit()
    t_setup = time.perf_counter() - t0
    kt_first = model.task_covariance
    times, values = [], []
    for s in range(steps):
        lo = n_inner + 5 * s
        new_x, new_y = xi_all[lo:lo + 5].to(device), yi_all[lo:lo + 5].to(device)
        t1 = time.perf_counter()
        model.add_observations(new_x, new_y, 0)
        model.fit()
        plan = plan_direction(model, new_x[0], step=STEP)
        times.append(time.perf_counter() - t1)
        if record:
            mu, v = model.predict(new_x[0][None])
            values.append({"kt": model.task_covariance.cpu(), "mll": float(model.log_marginal_likelihood()),
                           "mu": float(mu), "v": float(v), "dir": plan.direction.cpu(), "bound": model.truncation})
    return {"data": data, "model": model, "engine_s": t_engine, "setup_s": t_setup, "kt_first": kt_first,
            "times": times, "values": values}


def run(n_outer: int, n_inner: int, steps: int, naive: bool, device: str = "cpu"):
    # (a) alone over all steps, as in an exploration loop; what (b) and the dense check need is recorded
    a = timed_steps(n_outer, n_inner, steps, naive, device)
    xo, yo, xi_all, yi_all = a["data"]
    t_o = torch.ones(n_outer, dtype=torch.long)
    model, t_eig, t_setup, kt_first, fast_times, fast = (a[k] for k in ("model", "engine_s", "setup_s", "kt_first",
                                                                         "times", "values"))
    # (b) on the same steps, then the dense exact engine at (a)'s K_t
    naive_times, diffs = [], []
    kt_prev = kt_first
    for s, f in enumerate(fast):
        lo = n_inner + 5 * s
        contact = xi_all[lo]
        x = torch.cat([xi_all[:lo + 5], xo])
        y = torch.cat([yi_all[:lo + 5], yo])
        t = torch.cat([torch.zeros(lo + 5, dtype=torch.long), t_o])
        t2 = time.perf_counter()
        kt_n, mll_n, mu_n, v_n, d_n = naive_step(x, y, t, kt_prev, contact)
        naive_times.append(time.perf_counter() - t2)
        kt_prev = kt_n
        kt_f = f["kt"]
        # the dense exact engine (one Cholesky of the full Gram matrix) at the fast K_t: the same quantities in
        # plain exact arithmetic, and the Newton step from there (distance to the exact optimum)
        dense = DenseExactInference(x, y, t, IMQ(THETA), NOISE)
        mll_d, g_d, h_d = dense.mll_derivatives(kt_f)
        mu_d, v_d = dense.predict(contact[None], 0, kt_f)
        phi = task_covariance_to_chol_params(kt_f)
        grad, hess = chain_to_cholesky(phi, g_d, h_d)
        kt_opt = chol_params_to_task_covariance(phi + np.linalg.solve(-hess, grad))
        cos = float(f["dir"] @ d_n) / STEP**2
        diffs.append({
            "K_t": float((kt_f - kt_n).abs().max() / kt_n.abs().max()),
            "MLL": abs(f["mll"] - mll_n) / abs(mll_n),
            "mu": abs(f["mu"] - mu_n) / max(abs(mu_n), 1e-12),
            "V": abs(f["v"] - v_n) / v_n,
            "dir_rad": math.acos(max(-1.0, min(1.0, cos))),
            "K_t_dense": float((kt_opt - kt_f).abs().max() / kt_f.abs().max()),
            "MLL_dense": abs(f["mll"] - mll_d) / abs(mll_d),
            "mu_dense": abs(f["mu"] - float(mu_d)) / max(abs(float(mu_d)), 1e-12),
            "V_dense": abs(f["v"] - float(v_d)) / float(v_d),
        })
    return {"n_outer": n_outer, "n_inner": n_inner, "eig_s": t_eig, "setup_s": t_setup,
            "fast_ms": 1e3 * statistics.median(fast_times),
            "naive_ms": 1e3 * statistics.median(naive_times) if naive_times else float("nan"),
            "diff": {k: max(d[k] for d in diffs) for k in diffs[0]} if diffs else None,
            "orders": f"{len(model._inference().series.n_j) - 1} / {sum(model._inference().series.n_j)}",
            "n": len(model.train_targets)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--outer", type=int, nargs="+", default=[500, 2000, 8000])
    parser.add_argument("--inner", type=int, nargs="+", default=[50, 300])
    parser.add_argument("--steps", type=int, default=7, help="planning steps timed per configuration")
    parser.add_argument("--naive-max-outer", type=int, default=2000,
                        help="skip the naive side above this N_outer (it takes minutes per step there)")
    parser.add_argument("--device", default="cpu", help="where the fast side runs (cuda: on a GPU, float64)")
    args = parser.parse_args()
    if args.device != "cpu":
        print(f"# fast side on {args.device}: "
              f"{torch.cuda.get_device_name(args.device) if args.device.startswith('cuda') else args.device}")
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, torch {torch.__version__} "
          f"({torch.get_num_threads()} threads), gpytorch {gpytorch.__version__}, float64")
    print("| N_outer | N_inner | setup: eigh + first fit [s] | fast step [ms] | naive step [ms] | ratio | "
          "max rel. diff vs naive: K_t / MLL / mu / V | max dir. diff [rad] | "
          "max rel. diff vs dense exact: K_t optimum / MLL / mu / V | Chebyshev orders (max / total) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n_outer in args.outer:
        for n_inner in args.inner:
            r = run(n_outer, n_inner, args.steps, naive=n_outer <= args.naive_max_outer, device=args.device)
            if r["diff"]:
                d = r["diff"]
                diff = f"{d['K_t']:.1e} / {d['MLL']:.1e} / {d['mu']:.1e} / {d['V']:.1e}"
                ddir = f"{d['dir_rad']:.1e}"
                dense = f"{d['K_t_dense']:.1e} / {d['MLL_dense']:.1e} / {d['mu_dense']:.1e} / {d['V_dense']:.1e}"
                naive = f"{r['naive_ms']:.0f}"
                ratio = f"{r['naive_ms'] / r['fast_ms']:.0f}x"
            else:
                diff = ddir = naive = ratio = dense = "skipped (minutes per step)"
            print(f"| {n_outer} | {n_inner} | {r['eig_s']:.2f} + {r['setup_s'] - r['eig_s']:.2f} | "
                  f"{r['fast_ms']:.1f} | {naive} | {ratio} | {diff} | {ddir} | {dense} | {r['orders']} |", flush=True)


if __name__ == "__main__":
    main()
