"""Point touch vs tactile patch: one table from two study folders (``gpioius study --touch point`` and ``--touch
patch`` on the same objects, modes and seeds).

Per object and mode: H at 10 % of the reference travel and at the end for each touch (medians with 95 %
intervals), the paired difference patch - point on the same seed, the final correlation with the median of the
runs' own 95 % profile intervals, how many runs' intervals reach below 0.9 (the data tell the tasks apart there)
and the median step time.

    python scripts/touch_table.py outputs/touch_point_ff outputs/touch_patch_ff
"""

from __future__ import annotations

import argparse
import csv
import math
import statistics
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from claims_table import _cm, _f, _hausdorff  # noqa: E402  (scripts/ is not a package)


def _runs(folder: Path) -> dict:
    out = defaultdict(dict)
    for r in csv.DictReader(open(folder / "runs.csv")):
        out[(r["object"], r["mode"])][int(r["seed"])] = r
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("point", type=Path)
    parser.add_argument("patch", type=Path)
    args = parser.parse_args()
    point, patch = _runs(args.point), _runs(args.patch)
    print("| object | mode | H 10 % point / patch [cm] | patch - point at 10 % [cm] | H final point / patch [cm] | "
          "patch - point final [cm] | rho final point / patch [runs' intervals] | "
          "runs with interval lower end < 0.9: point / patch | step point / patch [ms] |")
    print("|---|---|---|---|---|---|---|---|---|")
    for key in sorted(set(point) & set(patch)):
        a, b = point[key], patch[key]
        seeds = sorted(set(a) & set(b))
        if not seeds:
            continue
        h = _hausdorff(b, a, seeds)                          # patch first: the differences are patch - point
        h10, hf, d10, dfin = h["h10"][::-1], h["hf"][::-1], h["d10"], h["dfin"]
        rho, wide = [], []
        for rs in (a, b):
            los = [_f(rs[s]["final_correlation_lo"]) for s in seeds]
            wide.append(f"{sum(v < 0.9 for v in los if math.isfinite(v))} of {sum(math.isfinite(v) for v in los)}"
                        if any(math.isfinite(v) for v in los) else "-")
            vals = [_f(rs[s]["final_correlation"]) for s in seeds]
            if not any(math.isfinite(v) for v in vals):
                rho.append("-")
                continue
            lo = statistics.median(_f(rs[s]["final_correlation_lo"]) for s in seeds)
            hi = statistics.median(_f(rs[s]["final_correlation_hi"]) for s in seeds)
            rho.append(f"{statistics.median(vals):.2f} [{lo:.2f}, {hi:.2f}]")
        step = [1e3 * statistics.median(_f(rs[s]["median_step_time"]) for s in seeds) for rs in (a, b)]
        print(f"| {key[0]} | {key[1]} | {_cm(h10[0])} / {_cm(h10[1])} | {_cm(d10)} | {_cm(hf[0])} / {_cm(hf[1])} | "
              f"{_cm(dfin)} | {rho[0]} / {rho[1]} | {wide[0]} / {wide[1]} | {step[0]:.0f} / {step[1]:.0f} |")


if __name__ == "__main__":
    main()
