"""Generate the shipped example data: `data/example_2d.gpioius` (an exploration log of the paper's object A).

The log is what `tg.explore(..., log=...)` writes: the camera's outer observations and the approach (step 0),
then one record per sliding step. `gpioius fit` reads it as a dataset (its final state), `gpioius replay`
step by step. Deterministic: re-running reproduces the file's observations exactly.

Run:  python scripts/make_example_dataset.py [--steps 40] [--out data/example_2d.gpioius]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch_gpioius as tg
from torch_gpioius.sim import paper_objects_2d


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "data" / "example_2d.gpioius")
    args = parser.parse_args()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    trace = tg.explore(paper_objects_2d()["A"], mode="visual-tactile", max_steps=args.steps, log=args.out)
    ds = tg.load_dataset(args.out)
    print(f"wrote {args.out}: {trace.n_steps - 1} steps, {len(ds)} observations, "
          f"{args.out.stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
