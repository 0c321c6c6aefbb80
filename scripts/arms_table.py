"""Several study folders as arms of one table: per object, the medians over seeds of H, Chamfer, F-score, bias and
unseen share at 10 %, 25 % and the end (docs/results-real.md uses it), with the paired difference of final
Chamfer against the first arm.

Each argument is ``LABEL=FOLDER[:MODE]`` (MODE: visual-tactile by default, tactile, or ``baseline:NAME``: the
baseline NAME scored beside each visual-tactile run, from the same observations; it has final Chamfer, H, F-score and
bias only); objects are matched by name, runs by seed. A failed run's missing estimate counts as inf (worse than any
distance), as in every study table; so does a baseline that gave no surface.

    python scripts/arms_table.py "no inside points=outputs/real_ff_noinside" \\
        "default=outputs/real_ff_inside" "touch alone=outputs/real_ff_inside:tactile" \\
        "shrunk by 5 touches=outputs/real_ff_inside:baseline:vision-shrunk-5"
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
from claims_table import _f  # noqa: E402  (scripts/ is not a package)
from torch_gpioius.studies.stats import paired_difference  # noqa: E402

COLUMNS = (("H 10 %", "hausdorff_10", 100, 1), ("H 25 %", "hausdorff_25", 100, 1),
           ("H final", "final_hausdorff", 100, 1), ("Chamfer 25 %", "chamfer_25", 100, 2),
           ("Chamfer final", "final_chamfer", 100, 2), ("F@1cm final", "final_fscore_10mm", 1, 2),
           ("bias final", "final_bias", 100, 2), ("unseen 25 %", "unseen_25", 1, 2),
           ("rho final", "final_correlation", 1, 2), ("outer mean final", "final_outer_mean", 1, 2),
           ("length final [cm]", "final_length", 100, 1),
           ("sigma^2 final", "final_noise", 1, 4), ("step [ms]", "median_step_time", 1000, 0),
           # each run's 95th percentile of its steps: the median over seeds, and the worst run
           ("step p95 [ms]", "p95_step_time", 1000, 0), ("worst run's p95 [ms]", "p95_step_time", 1000, 0, max),
           ("slowest step [s]", "max_step_time", 1, 1, max))
# NaN there: not recorded (older runs; no learnable length; touch alone has no outer mean), not a failed estimate
TIMES = ("median_step_time", "p95_step_time", "max_step_time", "final_length", "final_noise", "final_outer_mean")


# a baseline's columns in runs.csv (``baseline_<name>_<metric>``) by the run's column they stand for
BASELINE_COLUMNS = {"final_chamfer": "chamfer", "final_hausdorff": "hausdorff", "final_fscore_10mm": "fscore_10mm",
                    "final_fscore_5mm": "fscore_5mm", "final_bias": "bias"}


def _arm(spec: str) -> tuple[str, dict]:
    label, _, where = spec.partition("=")
    folder, _, mode = where.partition(":")
    mode, _, baseline = (mode or "visual-tactile").partition(":")
    path = Path(folder) / "runs.csv"
    if not label or not where:
        raise SystemExit(f"arms_table: {spec!r} is not LABEL=FOLDER[:MODE]")
    if not path.is_file():
        raise SystemExit(f"arms_table: {spec!r}: no {path}")
    runs = defaultdict(dict)
    for r in csv.DictReader(open(path)):
        if mode == "baseline":
            if r["mode"] != "visual-tactile":
                continue
            if f"baseline_{baseline}_chamfer" not in r:
                raise SystemExit(f"arms_table: {spec!r}: {path} has no baseline {baseline!r} (its runs were made "
                                 "before baselines were scored, or under another name)")
            r = {"object": r["object"], "seed": r["seed"],
                 **{key: r[f"baseline_{baseline}_{m}"] for key, m in BASELINE_COLUMNS.items()}}
        elif r["mode"] != mode:
            continue
        runs[r["object"]][int(r["seed"])] = r
    return label, runs


def _value(run: dict, key: str) -> float:
    if key not in run:        # a column this arm does not have (a baseline's H at 25 %): not a failure
        return math.nan
    v = _f(run[key])
    failed_estimate = key not in ("final_correlation", "unseen_25", *TIMES) and not math.isfinite(v)
    return math.inf if failed_estimate else v


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("arms", nargs="+")
    args = parser.parse_args()
    arms = [_arm(a) for a in args.arms]
    objects = sorted({o for _, runs in arms for o in runs})
    print("| object | run | " + " | ".join(c[0] for c in COLUMNS) + " | Chamfer final - first arm (wins / losses) |")
    print("|---|---|" + "---|" * (len(COLUMNS) + 1))
    for o in objects:
        first = arms[0][1].get(o, {})
        for label, runs in arms:
            r = runs.get(o)
            if not r:
                continue
            cells = []
            for _, key, scale, digits, *agg in COLUMNS:
                vals = [v for v in (_value(run, key) for run in r.values()) if not math.isnan(v)]
                summary = agg[0] if agg else statistics.median
                cells.append(f"{scale * summary(vals):.{digits}f}" if vals else "-")
            seeds = sorted(set(r) & set(first))
            diff = "-"
            if runs is not arms[0][1] and seeds:
                d = paired_difference([_value(r[s], "final_chamfer") for s in seeds],
                                      [_value(first[s], "final_chamfer") for s in seeds])
                diff = f"{100 * d['median']:.2f} ({d['wins']} / {d['losses']})"
            print(f"| {o} | {label} ({len(r)}) | " + " | ".join(cells) + f" | {diff} |")


if __name__ == "__main__":
    main()
