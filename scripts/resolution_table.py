"""What finer camera voxels buy: one table from study folders run at different ``--voxel`` (docs/results-resolution.md).

Each folder is a ``gpioius study`` of one world at one voxel setting (the folder records it; each run records its
voxel and outer-point count). Tactile-only runs do not use the camera, so they are run once (any folder holding
them, usually the 5 cm one) and paired with every voxel setting's visual-tactile runs by object and seed.
Per object and voxel it prints the outer points, H at 10 % of the tactile run's travel and at the end (medians
with 95 % intervals), the paired differences VT - T with the claims' rules of ``scripts/claims_table.py`` (early
benefit: the interval at 10 % below 0; no harm: the final interval's upper end within the sweep's margin), the
final correlation (median over seeds, the median of the runs' own 95 % profile intervals, and how many runs'
intervals reach below 0, i.e. do not exclude an unrelated cover) and the median step time. Then the similarity
ordering per voxel: tight covers (E, G) above loose ones (F, H) with disjoint intervals of the median final
correlation.

    python scripts/resolution_table.py outputs/res_5cm outputs/res_2cm outputs/res_1cm
"""

from __future__ import annotations

import argparse
import csv
import statistics
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from claims_table import _cm, _f, _hausdorff  # noqa: E402  (scripts/ is not a package)

from torch_gpioius.studies.stats import median_interval  # noqa: E402
from torch_gpioius.studies.study import no_harm_margin  # noqa: E402

#: Tight and loose covers of the same body (docs/results-3d.md).
PAIRS = (("E", "F"), ("G", "H"))


def _read(folders: list[Path]) -> tuple[dict, dict]:
    """``vt[(object, voxel)][seed]`` and ``tactile[object][seed]`` rows from the folders' runs.csv."""
    vt, tactile = defaultdict(dict), defaultdict(dict)
    for folder in folders:
        for r in csv.DictReader(open(folder / "runs.csv")):
            if r["mode"] == "tactile":
                tactile[r["object"]][int(r["seed"])] = r
            elif r["mode"] == "visual-tactile":
                vt[(r["object"], _f(r["voxel"]))][int(r["seed"])] = r
    return vt, tactile


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("studies", type=Path, nargs="+")
    args = parser.parse_args()
    vt, tactile = _read(args.studies)
    print("| object | voxel [cm] | N_outer | H 10 % VT / T [cm] | VT - T at 10 % [cm] | early benefit | "
          "H final VT / T [cm] | VT - T final [cm] (allowed) | no harm | rho final [interval] | "
          "runs' own 95 % interval (median ends) | runs whose interval reaches below 0 | failed VT / T | "
          "step VT / T [ms] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    corr = {}
    for (obj, voxel) in sorted(vt, key=lambda k: (k[0], -k[1])):
        runs, tact = vt[(obj, voxel)], tactile.get(obj, {})
        seeds = sorted(set(runs) & set(tact))
        if not seeds:
            continue

        h = _hausdorff(runs, tact, seeds)
        h10, hf, early, final = h["h10"], h["hf"], h["d10"], h["dfin"]
        allowed = no_harm_margin(hf[1])
        rho = median_interval([_f(runs[s]["final_correlation"]) for s in seeds], failed="drop")
        corr[(obj, voxel)] = rho
        lo = statistics.median(_f(runs[s]["final_correlation_lo"]) for s in seeds)
        hi = statistics.median(_f(runs[s]["final_correlation_hi"]) for s in seeds)
        n_outer = statistics.median(_f(runs[s]["n_outer"]) for s in seeds)
        flagged = sum(1 for s in seeds if _f(runs[s]["final_correlation_lo"]) < 0)   # "unrelated" not excluded
        fails = [sum(1 for s in seeds if rs[s]["failed"]) for rs in (runs, tact)]
        step = [1e3 * statistics.median(_f(rs[s]["median_step_time"]) for s in seeds) for rs in (runs, tact)]
        print(
            f"| {obj} | {100 * voxel:g} | {n_outer:.0f} | {_cm(h10[0])} / {_cm(h10[1])} | {_cm(early)} | "
            f"{'yes' if early['hi'] < 0 else '**no**'} | {_cm(hf[0])} / {_cm(hf[1])} | {_cm(final)} "
            f"(+{100 * allowed:.1f}) | {'yes' if final['hi'] <= allowed else '**no**'} | "
            f"{rho['median']:.2f} [{rho['lo']:.2f}, {rho['hi']:.2f}] | [{lo:.2f}, {hi:.2f}] | "
            f"{flagged} of {len(seeds)} | "
            f"{fails[0]} / {fails[1]} | {step[0]:.0f} / {step[1]:.0f} |"
        )
    print()
    print("| voxel [cm] | tight | loose | tight above loose (disjoint intervals) |")
    print("|---|---|---|---|")
    for voxel in sorted({v for _, v in corr}, reverse=True):
        for tight, loose in PAIRS:
            a, b = corr.get((tight, voxel)), corr.get((loose, voxel))
            if a is None or b is None:
                continue
            print(f"| {100 * voxel:g} | {tight} {a['median']:.2f} [{a['lo']:.2f}, {a['hi']:.2f}] | {loose} "
                  f"{b['median']:.2f} [{b['lo']:.2f}, {b['hi']:.2f}] | {'yes' if a['lo'] > b['hi'] else '**no**'} |")


if __name__ == "__main__":
    main()
