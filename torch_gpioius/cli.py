"""Command-line interface: ``gpioius simulate`` (the 2-D study), ``simulate3d`` (the robot study), ``fit DATASET``,
``replay LOG``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["main"]


def _simulate(args: argparse.Namespace) -> int:
    from .study import run_study

    objects = ["A", "B", "C", "D"] if args.object == "all" else [args.object]
    max_steps = 12 if args.smoke else args.max_steps
    result = run_study(objects, out=args.out, max_steps=max_steps, progress=not args.quiet)
    print((Path(args.out) / "summary.md").read_text())
    print(f"wrote figures, records.csv/json and summary.md to {args.out} in {result['seconds']:.0f} s")
    return 0


def _simulate3d(args: argparse.Namespace) -> int:
    from .study3d import run_study_3d

    objects = ["E", "F", "G", "H"] if args.object == "all" else [args.object]
    travel = 0.06 if args.smoke else args.max_travel
    result = run_study_3d(objects, out=args.out, max_travel=travel, metrics_every=args.metrics_every,
                          progress=not args.quiet, mesh_resolution=0.01 if args.smoke else 0.006)
    print((Path(args.out) / "summary.md").read_text())
    print(f"wrote figures, records.csv/json, logs/ and summary.md to {args.out} in {result['seconds']:.0f} s")
    return 0


def _fit(args: argparse.Namespace) -> int:
    from .offline import fit_dataset

    info = fit_dataset(args.dataset, args.out, theta=args.theta, noise=args.noise)
    print(f"{args.dataset}: {info['n']} observations ({info['n_inner']} inner, {info['n_outer']} outer), "
          f"theta = {info['theta']:g} m, sigma^2 = {info['noise']:g}")
    if "task_covariance" in info:
        kt = info["task_covariance"]
        print(f"K_t = [[{kt[0][0]:.5g}, {kt[0][1]:.5g}], [{kt[1][0]:.5g}, {kt[1][1]:.5g}]]")
        print(f"similarity K_t[0,1]/K_t[0,0] = {info['similarity']:.4f}   (correlation {info['correlation']:.4f})")
    else:
        print("no outer observations: fitted a tactile-only GPIS")
    print(f"log marginal likelihood = {info['mll']:.4f}")
    if args.out:
        print(f"wrote {info['checkpoint']}, {info['figure']} and fit.json")
    return 0


def _replay(args: argparse.Namespace) -> int:
    from .offline import replay_log

    rows = replay_log(args.log, args.out, every=args.every, progress=not args.quiet)
    last = rows[-1]
    print(f"replayed {len(rows)} steps of {args.log}; last step {last['step']}: similarity {last['similarity']:.3f}, "
          f"uncertainty {last['uncertainty']:.4g}, Hausdorff {last['hausdorff'] * 100:.2f} cm")
    print(f"wrote records.csv, records.json and transition.png to {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="gpioius", description="Visuo-tactile inner-shape estimation (GPIOIS).")
    sub = parser.add_subparsers(dest="command", required=True)
    sim = sub.add_parser("simulate", help="run the paper's 2-D study (objects A-D, both modes) and write figures",
                         description="Reproduce the paper's 2-D study: sliding exploration of objects A-D with "
                                     "visual-tactile GPIOIS and tactile-only GPIS; writes Fig. 4/5-like figures, "
                                     "per-step records (CSV/JSON) and a summary table.")
    sim.add_argument("--object", default="all", choices=["all", "A", "B", "C", "D"], help="object(s) to explore")
    sim.add_argument("--out", default="outputs/study2d", help="output folder")
    sim.add_argument("--max-steps", type=int, default=400, help="cap on planning steps per run")
    sim.add_argument("--smoke", action="store_true", help="a few steps per run only (CI)")
    sim.add_argument("--quiet", action="store_true", help="no progress bars")
    sim.set_defaults(func=_simulate)
    s3 = sub.add_parser("simulate3d", help="run the robot study in simulation (objects E-H, both modes)",
                        description="Sec. VI in simulation: objects E-H (arm and torso under tight and loose "
                                    "covers) explored by the simulated UR5 with a fingertip force sensor, after one "
                                    "capture of a simulated depth camera; visual-tactile GPIOIS vs tactile-only "
                                    "GPIS until 1.5 m of travel. Writes Fig. 9/10-like figures, records, logs and "
                                    "a summary table with the Sec. VI-B claims as measured.")
    s3.add_argument("--object", default="all", choices=["all", "E", "F", "G", "H"], help="object(s) to explore")
    s3.add_argument("--out", default="outputs/study3d", help="output folder")
    s3.add_argument("--max-travel", type=float, default=1.5, help="fingertip travel per run [m]")
    s3.add_argument("--metrics-every", type=int, default=5, help="surface metrics every k steps")
    s3.add_argument("--smoke", action="store_true", help="6 cm of travel on coarse meshes (CI)")
    s3.add_argument("--quiet", action="store_true", help="no progress bars")
    s3.set_defaults(func=_simulate3d)
    fit = sub.add_parser("fit", help="learn K_t on a dataset or log; save a checkpoint and a figure",
                         description="Fit GPIOIS (GPIS if there are no outer observations) on a torch_gpioius "
                                     "dataset or exploration log (docs/data-format.md): prints K_t, the similarity "
                                     "and the marginal likelihood; with --out saves model.pt and fit.png.")
    fit.add_argument("dataset", help="dataset or exploration log file (.gpioius)")
    fit.add_argument("--out", default=None, help="folder for model.pt (checkpoint), fit.png and fit.json")
    fit.add_argument("--theta", type=float, default=None, help="IMQ theta [m] (default: the file's, else 0.1)")
    fit.add_argument("--noise", type=float, default=None, help="sigma^2 (default: the file's, else 0.006)")
    fit.set_defaults(func=_fit)
    rep = sub.add_parser("replay", help="re-run the estimation of an exploration log step by step",
                         description="Rebuild the model after each logged step, re-learn K_t, and write per-step "
                                     "records (similarity, uncertainty, Hausdorff when the scene is known) and a "
                                     "transition figure.")
    rep.add_argument("log", help="exploration log (.gpioius) written by explore(log=...) or `gpioius simulate`")
    rep.add_argument("--out", default="outputs/replay", help="output folder")
    rep.add_argument("--every", type=int, default=1, help="replay every k-th step (the last is always included)")
    rep.add_argument("--quiet", action="store_true", help="no progress bar")
    rep.set_defaults(func=_replay)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, OSError, RuntimeError) as exc:
        print(f"gpioius: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
