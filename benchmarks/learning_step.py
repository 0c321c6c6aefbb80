"""What a step that learns the kernel's length and the noise costs (``learn="length"`` / ``"all"``), against one that
re-learns K_t alone, in one run.

Data: 3-D, an ellipsoidal body (20 x 14 x 25 cm half-axes) touched along a path (``--inner`` points: contacts with
free space 3 cm out and inside points 2 cm in, label -0.4) and a camera's view of a cover 8 mm out (``--outer``
points: surface, free space 5 cm out and inside points 2 cm in), the Matérn-5/2 of 0.1 m and sigma^2 0.08 as the
start (the defaults for a user's object).

Timed on one model each, in this order:

(a) ``fit()``: K_t re-learned warm on all the data by the structured engine (the exploration's ordinary step);
(b) ``learn_hyperparameters(256, 512, start=...)``: what the exploration runs on a restart step: L-BFGS on the thinned
    copy, then the engine rebuilt at the new length and K_t re-learned on all the data, then the keep-or-restore check;
(c) the same on all the data (no thinning): the reference for what the thinning saves and what it gives up (the full
    data's exact MLL each reaches is printed).

Prints each time, the ratios (b)/(a) and (c)/(b), and the learned values.

    python benchmarks/learning_step.py                      # 2000 outer + 300 inner, and 700 + 100
    python benchmarks/learning_step.py --outer 700 --inner 100
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
import torch

import torch_gpioius as tg

RADII = np.array([0.20, 0.14, 0.25])


def _on_ellipsoid(rng, n, grow=0.0):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v * (RADII + grow), v


def make_data(n_outer: int, n_inner: int, seed: int = 0):
    """`(x, y, task)` as described in the module docstring (a third of each task's points on the surface)."""
    rng = np.random.default_rng(seed)
    k_in, k_out = n_inner // 3, n_outer // 3
    s_in, d_in = _on_ellipsoid(rng, k_in)
    s_out, d_out = _on_ellipsoid(rng, k_out, grow=0.008)
    x = np.concatenate([s_in, s_in + 0.03 * d_in, s_in - 0.02 * d_in,
                        s_out, s_out + 0.05 * d_out, s_out - 0.02 * d_out])
    y = np.concatenate([np.zeros(k_in), np.ones(k_in), np.full(k_in, -0.4),
                        np.zeros(k_out), np.ones(k_out), np.full(k_out, -0.4)])
    t = np.r_[np.zeros(3 * k_in, np.int64), np.ones(3 * k_out, np.int64)]
    x = x + 0.002 * rng.standard_normal(x.shape)
    return torch.tensor(x), torch.tensor(y), torch.tensor(t)


def _model(x, y, t):
    return tg.GPIOIS(x, y, t, kernel=tg.kernels.Matern52(0.1), noise=0.08).fit()


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def run(n_outer: int, n_inner: int, learn_noise: bool) -> None:
    x, y, t = make_data(n_outer, n_inner)
    base = _model(x, y, t)
    t_fit = min(_timed(lambda: base.fit(multi_start=False)) for _ in range(3))
    thinned, full = _model(x, y, t), _model(x, y, t)
    t_thin = _timed(lambda: thinned.learn_hyperparameters(256, 512, start=(0.1, 0.08), learn_noise=learn_noise))
    t_full = _timed(lambda: full.learn_hyperparameters(start=(0.1, 0.08), learn_noise=learn_noise))
    print(f"\nN_outer {len(y) - int((t == 0).sum())}, N_inner {int((t == 0).sum())}, learn_noise={learn_noise}")
    print(f"  (a) fit(), K_t alone:                {t_fit * 1e3:9.1f} ms")
    for tag, m, sec in (("(b) learn, thinned 256 + 512", thinned, t_thin), ("(c) learn, all the data", full, t_full)):
        r = m.hyper_result
        print(f"  {tag}:        {sec * 1e3:9.1f} ms  ({r.evaluations} evaluations of {r.points} points, "
              f"L-BFGS {r.seconds * 1e3:.0f} ms); length {r.length:.4f} m, sigma^2 {r.noise:.5f}, kept {r.kept}, "
              f"full MLL {r.mll_full_before:.1f} -> {r.mll_full:.1f}")
    print(f"  ratio (b)/(a) = {t_thin / t_fit:.1f}, (c)/(b) = {t_full / t_thin:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--outer", type=int, nargs="*", default=[2000, 700])
    parser.add_argument("--inner", type=int, nargs="*", default=[300, 100])
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {platform.processor() or platform.machine()}, {args.threads} thread(s)")
    for n_outer, n_inner in zip(args.outer, args.inner):
        for learn_noise in (False, True):
            run(n_outer, n_inner, learn_noise)


if __name__ == "__main__":
    main()
