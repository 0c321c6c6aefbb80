"""Scaling in the outer (visual) points: the exact structured engine vs its truncated-basis approximation.

Issue 26's targets (1 CPU thread, N_inner = 300): N_outer = 10,000: setup <= 30 s, median step <= 65 ms;
N_outer = 20,000: setup <= 120 s, median step <= 150 ms. Each configuration runs in its own process (so its peak
RSS is its own) on the data of ``planning_step.py`` (outer points on an ellipsoid and 5 cm outside it, inner
contacts with free space; theta = 0.15, sigma^2 = 0.08):

* setup: engine construction (the eigendecomposition, or the pivoted Cholesky and the r x r eigenproblem of
  ``outer_tol``) and the first K_t fit;
* a step: one contact + 4 free-space points, re-learn K_t (warm start), plan the sliding direction at the contact.

Where the exact engine runs too (``--exact-max-outer``), each step of the approximation is compared with the
exact engine's same step: learned K_t, MLL, mean and variance at the contact, planned direction. The bound the
approximation reports (``GPIOIS.truncation``: ``K_t[1,1] tr(E) / sigma^2``) is printed beside them.

    OMP_NUM_THREADS=1 python benchmarks/outer_scaling.py --outer 2000 5000 --tol 1e-3 1e-5
    OMP_NUM_THREADS=1 python benchmarks/outer_scaling.py --outer 10000 20000 --tol 1e-3 --exact-max-outer 5000
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import statistics
import subprocess
import sys

import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from planning_step import timed_steps  # noqa: E402


def one(n_outer: int, n_inner: int, steps: int, outer_tol: float | None, device: str) -> dict:
    """One configuration in this process: setup, steps, per-step values; peak RSS at the end."""
    torch.set_num_threads(1)
    r = timed_steps(n_outer, n_inner, steps, True, device, outer_tol=outer_tol)
    values = [{**v, "kt": v["kt"].flatten().tolist(), "dir": v["dir"].tolist()} for v in r["values"]]
    return {"n_outer": n_outer, "n_inner": n_inner, "outer_tol": outer_tol, "rank": r["model"]._inference().rank,
            "basis_s": r["engine_s"], "setup_s": r["setup_s"], "step_ms": 1e3 * statistics.median(r["times"]),
            "rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20, "values": values}


def compare(approx: list[dict], exact: list[dict]) -> dict:
    """Largest per-step differences of the approximation from the exact engine."""
    out = {"K_t": 0.0, "MLL": 0.0, "mu": 0.0, "V": 0.0, "dir_rad": 0.0}
    for a, e in zip(approx, exact):
        ka, ke = torch.tensor(a["kt"]), torch.tensor(e["kt"])
        da, de = torch.tensor(a["dir"]), torch.tensor(e["dir"])
        cos = float(da @ de) / float(da.norm() * de.norm())
        out["K_t"] = max(out["K_t"], float((ka - ke).abs().max() / ke.abs().max()))
        out["MLL"] = max(out["MLL"], abs(a["mll"] - e["mll"]) / abs(e["mll"]))
        out["mu"] = max(out["mu"], abs(a["mu"] - e["mu"]))
        out["V"] = max(out["V"], abs(a["v"] - e["v"]) / e["v"])
        out["dir_rad"] = max(out["dir_rad"], math.acos(max(-1.0, min(1.0, cos))))
    return out


def launch(n_outer: int, args, outer_tol: float | None) -> dict:
    cmd = [sys.executable, os.path.abspath(__file__), "--one", str(n_outer), str(outer_tol), "--inner",
           str(args.inner), "--steps", str(args.steps), "--device", args.device]
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    done = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--outer", type=int, nargs="+", default=[2000, 5000, 10000, 20000])
    parser.add_argument("--inner", type=int, default=300)
    parser.add_argument("--tol", type=float, nargs="+", default=[1e-3], help="outer_tol values of the approximation")
    parser.add_argument("--steps", type=int, default=7)
    parser.add_argument("--exact-max-outer", type=int, default=5000,
                        help="run the exact engine up to this N_outer (273 s of setup at 10,000 on one thread)")
    parser.add_argument("--device", default="cpu", help="cpu or cuda (float64 either way)")
    parser.add_argument("--one", nargs=2, metavar=("N_OUTER", "OUTER_TOL"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        n, t = int(args.one[0]), (None if args.one[1] == "None" else float(args.one[1]))
        print(json.dumps(one(n, args.inner, args.steps, t, args.device)))
        return
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, torch {torch.__version__} "
          f"(1 thread per configuration, each in its own process), float64, N_inner {args.inner}, "
          f"{args.steps} steps, device {args.device}")
    print("| N_outer | engine | rank | setup: basis + first fit [s] | median step [ms] | peak RSS [GiB] | "
          "bound c tr(E)/s (max) | max diff vs exact: K_t rel / MLL rel / mu abs / V rel / direction [rad] |")
    print("|---|---|---|---|---|---|---|---|")
    for n_outer in args.outer:
        exact = launch(n_outer, args, None) if n_outer <= args.exact_max_outer else None
        rows = ([("exact", exact)] if exact else []) + [(f"outer_tol {t:g}", launch(n_outer, args, t))
                                                        for t in args.tol]
        for name, r in rows:
            bound = max(v["bound"] for v in r["values"])
            if exact is None:
                diff = "exact not run"
            elif r is exact:
                diff = "-"
            else:
                d = compare(r["values"], exact["values"])
                diff = f"{d['K_t']:.1e} / {d['MLL']:.1e} / {d['mu']:.1e} / {d['V']:.1e} / {d['dir_rad']:.1e}"
            print(f"| {n_outer} | {name} | {r['rank']} | {r['basis_s']:.1f} + {r['setup_s'] - r['basis_s']:.1f} | "
                  f"{r['step_ms']:.0f} | {r['rss_gib']:.2f} | {bound:.1e} | {diff} |", flush=True)


if __name__ == "__main__":
    main()
