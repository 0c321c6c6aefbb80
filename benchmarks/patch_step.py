"""Time one planning step with a tactile patch of k inner points: batched engine vs today's engine vs a dense refit.

A patch step = ingest k points (one contact, surface points of a 2 cm pad around it, free space 1 cm in front of
the pad), update K_t, plan the next sliding direction (eq. 19) at the contact. Three sides, each over the same
steps and data, in one run:

(a) batched: ``GPIOIS(inference="batched")``, ``add_observations`` -> ``fit(min_gain)`` -> ``plan_direction``:
    rank-k bordering at a held K_t; K_t re-learned when the exact gradient predicts a gain above ``min_gain``
    nats (docs/performance.md states the rule).
(b) today's engine: ``GPIOIS(inference="structured")``, ``fit()`` to convergence every step (O(N_i^3) per Newton
    evaluation).
(c) dense refit: ``GPIOIS(inference="dense")`` built on all data, ``fit()`` warm-started from (c)'s previous K_t.

Reported per N_inner (the inner points before the first timed step): medians, means and maxima of the step time,
how many of (a)'s steps re-learned K_t, and at the last step (a)'s exactness against a dense solve at (a)'s K_t
(largest difference of the posterior mean, of the variance over the prior variance K_t[0,0], at 200 points near
the surface; relative MLL; largest gradient difference in nats per unit of K_t) and how far (a)'s held K_t lags the
optimum, in nats of marginal likelihood. (b) and (c) run fewer steps at large N_inner (minutes per step).

    OMP_NUM_THREADS=1 python benchmarks/patch_step.py                   # N_outer 2000, N_inner 1000 and 3000
    python benchmarks/patch_step.py --inner 300 --steps 4 --others 1   # quick
    python benchmarks/patch_step.py --device cuda                      # on a GPU (float64)

**Whole runs** (``--whole-run SCENE``): visual-tactile patch explorations of a scene file, or of one of the
force-field world's objects (E-H), every step timed (plan, ingest, re-learning: the trace's ``step_time``), at each
``--travel``, for each ``--max-points`` (``none``: every point of each patch, the exact reference; a number:
``PatchTouch.max_points``, the informative points) and each ``--relearn`` schedule of K_t (``track``: the default,
held-Hessian tracking steps and restarts scouted on 256 inner points; ``full``: every re-learning and restart to
convergence on all the data, the schedule before it), in one run: median, 95th percentile and maximum of the step,
the steps that re-learned in full and that tracked, the largest ``fit_gap`` [nats], the inner points at the end, the
final correlation and shape (Hausdorff, Chamfer, F-score at 1 cm, bias):

    OMP_NUM_THREADS=1 python benchmarks/patch_step.py --whole-run examples/scenes/real/duck-tight.toml \
        --travel 0.3 1.0 1.5 --max-points 12 none
    OMP_NUM_THREADS=1 python benchmarks/patch_step.py --whole-run H --travel 1.0 --max-points 12 \
        --relearn track full --seed 3
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import time

import numpy as np
import torch

import torch_gpioius as tg
from torch_gpioius.inference import DenseExactInference
from torch_gpioius.exploration.planning import plan_direction
from torch_gpioius.kernels import InverseMultiquadricKernel as IMQ

THETA, NOISE, STEP = 0.15, 0.08, 0.01
OUTER_RADII, OUTER_FAR, INNER_RADII = (0.25, 0.18, 0.3), (0.30, 0.23, 0.35), (0.2, 0.14, 0.25)


def _ellipsoid(rng, n, radii):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True) * np.asarray(radii)


def make_outer(n_outer: int, rng):
    """Outer points: half on an ellipsoid (y = 0), half 5 cm outside it (y = 1), as benchmarks/planning_step.py."""
    xo = np.concatenate(
        [_ellipsoid(rng, n_outer // 2, OUTER_RADII), _ellipsoid(rng, n_outer - n_outer // 2, OUTER_FAR)]
    )
    return torch.tensor(xo), torch.tensor(np.r_[np.zeros(n_outer // 2), np.ones(n_outer - n_outer // 2)])


def make_patch(rng, k: int):
    """One patch of k points on the inner ellipsoid: the contact first, 3/4 surface points in a 2 cm disc, 1/4 free
    space 1 cm in front of the pad."""
    radii = np.asarray(INNER_RADII)
    c = _ellipsoid(rng, 1, radii)[0]
    n_free = k // 4
    n_surf = k - 1 - n_free
    normal = c / radii ** 2
    normal /= np.linalg.norm(normal)
    t1 = np.cross(normal, [0.0, 0.0, 1.0] if abs(normal[2]) < 0.9 else [1.0, 0.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)
    disc = rng.uniform(-0.01, 0.01, size=(n_surf + n_free, 2))
    pts = c + disc[:, :1] * t1 + disc[:, 1:] * t2
    # back onto the ellipsoid along the ray from its centre (a surface within rounding of the pad's plane)
    pts = pts / np.sqrt(((pts / radii) ** 2).sum(1, keepdims=True))
    surf, free = pts[:n_surf], pts[n_surf:] + 0.01 * normal
    x = np.concatenate([c[None], surf, free])
    y = np.r_[np.zeros(1 + n_surf), np.ones(n_free)]
    return torch.tensor(x), torch.tensor(y)


def make_stream(n_start: int, steps: int, k: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    patches = [make_patch(rng, k) for _ in range(-(-n_start // k) + steps)]
    x0 = torch.cat([p[0] for p in patches])[:n_start]
    y0 = torch.cat([p[1] for p in patches])[:n_start]
    return x0, y0, patches[-steps:]


def run_side(inference: str, xo, yo, x0, y0, patches, min_gain, device):
    n_o = len(xo)
    x = torch.cat([x0, xo]).to(device)
    y = torch.cat([y0, yo]).to(device)
    t = torch.cat([torch.zeros(len(x0), dtype=torch.long), torch.ones(n_o, dtype=torch.long)]).to(device)
    t_setup = time.perf_counter()
    model = tg.GPIOIS(
        x, y, t, kernel=IMQ(THETA), noise=NOISE, inference="structured" if inference == "dense" else inference
    )
    model.fit()
    setup = time.perf_counter() - t_setup
    times, relearned, kt_prev = [], 0, model.task_covariance
    for xn, yn in patches:
        xn, yn = xn.to(device), yn.to(device)
        t1 = time.perf_counter()
        if inference == "dense":                 # a fresh dense model on all data, warm-started
            data = (torch.cat([model.train_inputs[0], xn]), torch.cat([model.train_targets, yn]),
                    torch.cat([model.train_task, torch.zeros(len(xn), dtype=torch.long, device=device)]))
            model = tg.GPIOIS(*data, kernel=IMQ(THETA), noise=NOISE, task_covariance=kt_prev, inference="dense")
            model.fit(multi_start=False)
        else:
            model.add_observations(xn, yn, 0)
            model.fit(min_gain=min_gain if inference == "batched" else None)
        plan_direction(model, xn[0], step=STEP)
        times.append(time.perf_counter() - t1)
        kt_prev = model.task_covariance
        relearned += bool(model.fit_result.relearned)
    return model, setup, times, relearned


def exactness(model, seed: int = 1):
    """(a)'s posterior, MLL and gradient against a dense solve at (a)'s K_t, and the MLL gap to the optimum."""
    x, y, t = model.train_inputs[0], model.train_targets, model.train_task
    kt = model._task_matrix()
    dense = DenseExactInference(x, y, t, IMQ(THETA), NOISE)
    rng = np.random.default_rng(seed)
    q = torch.tensor(_ellipsoid(rng, 200, INNER_RADII) * rng.uniform(0.9, 1.1, size=(200, 1)), device=x.device)
    mu_a, v_a = model.predict(q, 0)
    mu_d, v_d = dense.predict(q, 0, kt)
    engine = model._inference()
    mll_a, g_a = engine.mll_gradient(kt)
    mll_d, g_d, _ = dense.mll_derivatives(kt)
    held_mll = mll_d
    best = tg.GPIOIS(x, y, t, kernel=IMQ(THETA), noise=NOISE, task_covariance=model.task_covariance,
                     inference="structured").fit(multi_start=False)
    prior = float(kt[0, 0])                   # the IMQ kernel is 1 at distance 0: prior variance K_t[0,0]
    return {"mu": float((mu_a - mu_d).abs().max()), "V": float((v_a - v_d).abs().max()) / prior,
            "MLL": abs(mll_a - mll_d) / abs(mll_d), "grad": float((g_a - g_d).abs().max()),
            "lag_nats": best.fit_result.mll - held_mll}


def fmt(times):
    ms = [1e3 * v for v in times]
    return f"{statistics.median(ms):.0f} / {statistics.fmean(ms):.0f} / {max(ms):.0f}"


#: ``--relearn`` schedules: PatchTouch's settings of K_t's re-learning.
RELEARN = {"track": {}, "full": {"track": False, "scout": None, "max_hold": 20}}


def whole_runs(scene: str, travels, max_points, seed: int, device, relearn=("track",)) -> None:
    """Time every step of whole patch runs (see the module docstring) and print one row per run."""
    import warnings

    from torch_gpioius.exploration.registry import make_world
    from torch_gpioius.exploration.touch import PatchTouch
    from torch_gpioius.sim.scenefile import load_scene

    print("| scene | travel [m] | max_points | relearn | steps | step median / p95 / max [ms] | full / tracked | "
          "max fit_gap [nats] | N_inner at end | rho | H [cm] | Chamfer [cm] | F@1cm | bias [cm] | wall [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for travel in travels:
        for mp, schedule in ((mp, r) for mp in max_points for r in relearn):
            world = (make_world("forcefield", scene, seed) if scene in ("E", "F", "G", "H")
                     else load_scene(scene, seed=seed))
            touch = PatchTouch(max_points=None if mp == "none" else int(mp), **RELEARN[schedule])
            relearned, tracked = [], []

            class Relearns:                                   # counts the steps whose fit re-learned or tracked K_t
                def start(self, run, state): ...
                def step(self, run, state, record):
                    fr = getattr(state.model, "fit_result", None)
                    relearned.append(bool(fr is not None and fr.relearned))
                    tracked.append(bool(fr is not None and fr.tracked))
                def end(self, run, state): ...

            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                trace = tg.explore(world, touch=touch, max_travel=travel, metrics_every=10_000, device=device,
                                   recorders=[Relearns()])
            wall = time.perf_counter() - t0
            st = {k: 1e3 * v for k, v in trace.step_time_summary().items()}      # [ms]
            sh = {k: float(v[-1]) for k, v in trace.shape.items()}
            n_inner = int((trace.model.train_task == 0).sum())
            print(f"| {world.name} | {travel:g} | {mp} | {schedule} | {trace.n_steps - 1} | {st['median']:.0f} / "
                  f"{st['p95']:.0f} / {st['max']:.0f} | {sum(relearned)} / {sum(tracked)} | "
                  f"{float(np.nanmax(trace.fit_gap)):.3f} | {n_inner} | {trace.correlation[-1]:.2f} | "
                  f"{trace.hausdorff[-1] * 100:.1f} | "
                  f"{sh['chamfer'] * 100:.2f} | {sh['fscore_10mm']:.2f} | {sh['bias'] * 100:.2f} | {wall:.0f} |",
                  flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--outer", type=int, default=2000)
    parser.add_argument("--inner", type=int, nargs="+", default=[1000, 3000])
    parser.add_argument("--k", type=int, default=64, help="points per patch")
    parser.add_argument("--steps", type=int, default=15, help="timed steps of (a)")
    parser.add_argument("--others", type=int, default=3, help="timed steps of (b) and (c)")
    parser.add_argument("--min-gain", type=float, default=0.1, help="(a)'s re-learning threshold [nats]")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--skip", nargs="*", default=[], choices=["structured", "dense"], help="sides to leave out")
    parser.add_argument("--whole-run", default=None, metavar="SCENE",
                        help="time whole patch runs of this scene file, or of a force-field object (E-H)")
    parser.add_argument("--travel", type=float, nargs="+", default=[0.3, 1.0], help="whole runs' travel [m]")
    parser.add_argument("--max-points", nargs="+", default=["12", "none"], help="whole runs' PatchTouch.max_points")
    parser.add_argument("--seed", type=int, default=0, help="whole runs' seed")
    parser.add_argument("--relearn", nargs="+", default=["track"], choices=sorted(RELEARN),
                        help="whole runs' re-learning schedules of K_t")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    dev = torch.cuda.get_device_name(device) if device.type == "cuda" else (platform.processor() or platform.machine())
    if args.whole_run:
        print(f"# {dev}, {os.cpu_count()} CPUs, torch {torch.__version__} ({torch.get_num_threads()} threads), "
              f"seed {args.seed}, metrics only at the end")
        whole_runs(args.whole_run, args.travel, args.max_points, args.seed,
                   None if device.type == "cpu" else str(device), args.relearn)
        return
    print(f"# {dev}, {os.cpu_count()} CPUs, torch {torch.__version__} ({torch.get_num_threads()} threads), float64, "
          f"N_outer {args.outer}, k {args.k}, min_gain {args.min_gain} nats")
    print("| N_inner | (a) batched: median / mean / max [ms] | re-learned | (b) today's engine [ms] | "
          "(c) dense refit [ms] | median (b)/(a) | (a) vs dense at its K_t: mu / V / MLL / grad | "
          "K_t lag [nats] | setup (a) [s] | peak RSS [GiB] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    rng = np.random.default_rng(0)
    xo, yo = make_outer(args.outer, rng)
    for n_inner in args.inner:
        x0, y0, patches = make_stream(n_inner, args.steps, args.k)
        model, setup, times_a, relearned = run_side("batched", xo, yo, x0, y0, patches, args.min_gain, device)
        ex = exactness(model)
        others = {}
        for side in ("structured", "dense"):
            if side in args.skip or args.others < 1:
                others[side] = None
                continue
            others[side] = run_side(side, xo, yo, x0, y0, patches[:args.others], None, device)[2]
        b = fmt(others["structured"]) if others["structured"] else "skipped"
        c = fmt(others["dense"]) if others["dense"] else "skipped"
        ratio = (f"{statistics.median(others['structured']) / statistics.median(times_a):.0f}x"
                 if others["structured"] else "-")
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20
        print(f"| {n_inner} | {fmt(times_a)} | {relearned} of {len(times_a)} | {b} | {c} | {ratio} | "
              f"{ex['mu']:.1e} / {ex['V']:.1e} / {ex['MLL']:.1e} / {ex['grad']:.1e} | {ex['lag_nats']:.3f} | "
              f"{setup:.1f} | {rss:.1f} |", flush=True)


if __name__ == "__main__":
    main()
