"""What a restart's fixed starts cost on the thinned copy of the data (``GPIOIS.fit(scout=...)``): the structured
engine with its Chebyshev store of ``T(c)`` (rebuilt whenever ``K_t[1, 1]`` leaves a window of a factor of 2)
against ``DirectStructuredInference`` (``T(c)`` by direct products at every evaluation, no store).

Both sides run the same Newton runs (``maximize_mll``) from the same starts, the restart's warm K_t and its three
fixed ones (``GPIOIS._fixed_starts``), on the same data; the optima must agree. The data: by default a body of
revolution's surface (``--inner`` contacts, a fifth of them free-space points 3 cm out) under a cover seen at
``--outer`` points (half on it, half 5 cm out); with ``--log`` the data of one step of a study's log, thinned as the
restart thins it (``--scout`` inner points evenly along their arrival, every outer point), and the K_t in use there.

    OMP_NUM_THREADS=1 python benchmarks/scout_copy.py
    OMP_NUM_THREADS=1 python benchmarks/scout_copy.py --log outputs/STUDY/logs/H_visual-tactile_0.gpioius --step 125
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
import torch

import torch_gpioius as tg
from torch_gpioius.inference.optim import maximize_mll
from torch_gpioius.inference.structured import DirectStructuredInference, StructuredExactInference


def _synthetic(n_inner: int, n_outer: int, seed: int = 0):
    rng = np.random.default_rng(seed)

    def body(n, grow):
        v = rng.normal(size=(n, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        return v * (np.array([0.12, 0.09, 0.2]) + grow)

    n_free = n_inner // 5
    xi = np.concatenate([body(n_inner - n_free, 0.0), body(n_free, 0.03)])
    yi = np.r_[np.zeros(n_inner - n_free), np.ones(n_free)]
    xo = np.concatenate([body(n_outer // 2, 0.008), body(n_outer - n_outer // 2, 0.058)])
    yo = np.r_[np.zeros(n_outer // 2), np.ones(n_outer - n_outer // 2)]
    x, y = torch.tensor(np.concatenate([xi, xo])), torch.tensor(np.r_[yi, yo])
    task = torch.tensor(np.r_[np.zeros(n_inner), np.ones(n_outer)].astype(np.int64))
    kt = torch.tensor([[0.029, 0.084], [0.084, 0.2435]], dtype=torch.float64)   # a correlation of 0.9996
    return x, y, task, kt


def _from_log(path: str, step: int, scout: int):
    from torch_gpioius.io.datasets import read_records
    from torch_gpioius.io.runs import load_run

    records = [r for r in read_records(path) if r.kind == "step"]
    data = load_run(path).states[step]
    kt = torch.as_tensor(np.asarray(records[step - 1].arrays["kt"], dtype=np.float64))
    model = tg.GPIOIS(torch.as_tensor(data.x), torch.as_tensor(data.y), torch.as_tensor(data.task),
                      task_covariance=kt)
    keep = model._thinned(scout)
    return model.train_inputs[0][keep], model.train_targets[keep], model.train_task[keep], kt


def _restart(cls, x, y, task, kt, theta: float, noise: float) -> dict:
    """The warm and the fixed starts' Newton runs on a fresh engine of ``cls``: time [s], evaluations, optima."""
    t0 = time.perf_counter()
    engine = cls(x, y, task, theta=theta, noise=noise)
    calls = []

    def evaluate(b):
        calls.append(1)
        return engine.mll_derivatives(b)

    starts = [kt, torch.eye(2, dtype=torch.float64), 0.1 * torch.tensor([[1.0, 0.9], [0.9, 1.0]], dtype=torch.float64),
              torch.diag(kt.diagonal().clamp_min(1e-6))]
    results = [maximize_mll(evaluate, k0) for k0 in starts]
    return {"time": time.perf_counter() - t0, "evaluations": len(calls), "results": results}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inner", type=int, default=256, help="inner points of the copy (synthetic data)")
    parser.add_argument("--outer", type=int, default=500, help="outer points (synthetic data)")
    parser.add_argument("--log", default=None, help="a study's .gpioius log: take the data of --step from it")
    parser.add_argument("--step", type=int, default=125, help="the log's step (a restart's: a multiple of 25)")
    parser.add_argument("--scout", type=int, default=256, help="inner points the copy keeps (with --log)")
    parser.add_argument("--repeat", type=int, default=3, help="timed repetitions per side (the best is reported)")
    args = parser.parse_args()
    theta, noise = 0.15, 0.08
    if args.log:
        x, y, task, kt = _from_log(args.log, args.step, args.scout)
        source = f"{args.log} step {args.step}"
    else:
        x, y, task, kt = _synthetic(args.inner, args.outer)
        source = "synthetic body"
    n_i = int((task == 0).sum())
    print(f"{platform.processor() or platform.machine()}, torch {torch.__version__} "
          f"({torch.get_num_threads()} threads); {source}: {n_i} inner, {len(task) - n_i} outer points")
    sides = {}
    for name, cls in (("store (StructuredExactInference)", StructuredExactInference),
                      ("direct (DirectStructuredInference)", DirectStructuredInference)):
        runs = [_restart(cls, x, y, task, kt, theta, noise) for _ in range(args.repeat)]
        sides[name] = min(runs, key=lambda r: r["time"])
    print("| side | restart's fixed starts [s] | evaluations | per evaluation [ms] |\n|---|---|---|---|")
    for name, r in sides.items():
        print(f"| {name} | {r['time']:.3f} | {r['evaluations']} | {1e3 * r['time'] / r['evaluations']:.1f} |")
    (store, direct) = sides.values()
    gap = max(float((a.task_covariance - b.task_covariance).abs().max() / a.task_covariance.abs().max())
              for a, b in zip(store["results"], direct["results"]))
    mll = max(abs(a.mll - b.mll) for a, b in zip(store["results"], direct["results"]))
    print(f"ratio store / direct: {store['time'] / direct['time']:.1f}x; optima: K_t within {gap:.1e} (relative), "
          f"MLL within {mll:.1e} nats")


if __name__ == "__main__":
    main()
