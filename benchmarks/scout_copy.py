"""What a restart's fixed starts cost on the thinned copy of the data (``GPIOIS.fit(scout=...)``): the copy as the
structured engine with its Chebyshev store of ``T(c)`` (rebuilt whenever ``K_t[1, 1]`` leaves a window of a factor of
2) against ``DirectStructuredInference`` (``T(c)`` by direct products at every evaluation, no store), the library's
choice.

Both sides run the library's restart on the copy (``GPIOIS._scout_starts``: the warm start's Newton run, then the
three fixed starts', each ending once it heads into a basin already found) from the same K_t on the same data; the
basins they find must agree. The data: by default a body of revolution's surface (``--inner`` contacts, a fifth of
them free-space points 3 cm out) under a cover seen at ``--outer`` points (half on it, half 5 cm out), K_t at a
correlation of 0.9996; with ``--log`` the data of one step of a study's log and the K_t in use there. The copy keeps
``--scout`` inner points (evenly along their arrival) and every outer point.

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
from torch_gpioius.models import gpiois as gpiois_module
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


def _from_log(path: str, step: int):
    from torch_gpioius.io.datasets import read_records
    from torch_gpioius.io.runs import load_run

    records = [r for r in read_records(path) if r.kind == "step"]
    data = load_run(path).states[step]
    kt = torch.as_tensor(np.asarray(records[step - 1].arrays["kt"], dtype=np.float64))
    return torch.as_tensor(data.x), torch.as_tensor(data.y), torch.as_tensor(data.task), kt


def _counting(base):
    """``base`` with its likelihood evaluations counted: ``[with derivatives, value alone]``."""
    class Counting(base):
        calls = [0, 0]

        def mll_derivatives(self, b):
            Counting.calls[0] += 1
            return super().mll_derivatives(b)

        def mll_value(self, b):
            Counting.calls[1] += 1
            return super().mll_value(b)

    return Counting


def _restart(base, x, y, task, kt, theta: float, noise: float, scout: int) -> dict:
    """The library's restart on a copy built as ``base``: time [s], evaluations, the other basins' K_t."""
    model = tg.GPIOIS(x, y, task, theta=theta, noise=noise, task_covariance=kt, inference="batched")
    engine = _counting(base)
    saved = gpiois_module.DirectStructuredInference
    gpiois_module.DirectStructuredInference = engine          # what _scout_copy builds the copy as
    try:
        t0 = time.perf_counter()
        found = model._scout_starts(model._fixed_starts(), scout, kt)
        elapsed = time.perf_counter() - t0
    finally:
        gpiois_module.DirectStructuredInference = saved
    return {"time": elapsed, "derivatives": engine.calls[0], "values": engine.calls[1], "found": found}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inner", type=int, default=1500, help="inner points (synthetic data)")
    parser.add_argument("--outer", type=int, default=500, help="outer points (synthetic data)")
    parser.add_argument("--log", default=None, help="a study's .gpioius log: take the data of --step from it")
    parser.add_argument("--step", type=int, default=125, help="the log's step (a restart's: a multiple of 25)")
    parser.add_argument("--scout", type=int, default=256, help="inner points the copy keeps")
    parser.add_argument("--repeat", type=int, default=3, help="timed repetitions per side (the best is reported)")
    args = parser.parse_args()
    theta, noise = 0.15, 0.08
    if args.log:
        x, y, task, kt = _from_log(args.log, args.step)
        source = f"{args.log} step {args.step}"
    else:
        x, y, task, kt = _synthetic(args.inner, args.outer)
        source = "synthetic body"
    n_i = int((task == 0).sum())
    print(f"{platform.processor() or platform.machine()}, torch {torch.__version__} "
          f"({torch.get_num_threads()} threads); {source}: {n_i} inner, {len(task) - n_i} outer points, the copy "
          f"{min(n_i, args.scout)} inner")
    sides = {}
    for name, base in (("store (StructuredExactInference)", StructuredExactInference),
                       ("direct (DirectStructuredInference)", DirectStructuredInference)):
        runs = [_restart(base, x, y, task, kt, theta, noise, args.scout) for _ in range(args.repeat)]
        sides[name] = min(runs, key=lambda r: r["time"])
    print("| copy | restart on the copy [s] | evaluations with derivatives / value alone | per evaluation [ms] |\n"
          "|---|---|---|---|")
    for name, r in sides.items():
        n = r["derivatives"] + r["values"]
        print(f"| {name} | {r['time']:.3f} | {r['derivatives']} / {r['values']} | {1e3 * r['time'] / n:.1f} |")
    store, direct = sides.values()
    same = len(store["found"]) == len(direct["found"]) and all(
        float((a - b).abs().max()) <= 1e-6 * float(a.abs().max()) for a, b in zip(store["found"], direct["found"]))
    print(f"ratio store / direct: {store['time'] / direct['time']:.1f}x; other basins found: "
          f"{len(direct['found'])}, the same on both sides: {same}")


if __name__ == "__main__":
    main()
