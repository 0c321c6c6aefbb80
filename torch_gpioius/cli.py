"""Command-line interface: ``gpioius simulate`` (the 2-D study)."""

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
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, OSError) as exc:
        print(f"gpioius: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
