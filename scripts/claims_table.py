"""The paper's three general claims judged on any study's objects (docs/results-real.md uses it).

Reads ``runs.csv`` of a ``gpioius study`` folder with visual-tactile and tactile-only runs on the same seeds, and
prints a markdown table per object. Failed runs stay in: a run with no estimate is +inf (worse than any distance),
a failed pair is a loss for the failed side (``torch_gpioius.studies.stats``). The rules, fixed before looking:

* **early benefit**: the 95 % interval of the median paired difference VT - T of H at 10 % of the tactile run's
  travel lies below 0;
* **no harm**: the upper end of the interval of the median paired difference of final H is at most
  max(10 % of the tactile-only median, 0.5 cm);
* **similarity ordering**: for an object under a tight and a looser cover (names ``<shape>-tight`` and
  ``<shape>-loose`` or ``<shape>-wide``), the tight cover's median final correlation is above the other's with
  95 % intervals at least 0.01 apart (the outer shape predicts the inner one better when it hugs it). Beside it,
  not part of it: on how many seeds (paired) the looser cover's correlation is lower than the tight one's.

    python scripts/claims_table.py outputs/real_ff [outputs/real_ff_wide ...]   # several folders: their runs together
"""

from __future__ import annotations

import argparse
import csv
import math
from collections import defaultdict
from pathlib import Path

from torch_gpioius.studies.stats import median_interval, paired_difference
from torch_gpioius.studies.study import no_harm_margin


#: How far apart [correlation] two intervals must lie to count as disjoint: correlations of 1 - 1e-10 and
#: 1 - 1e-9 are the same learned K_t (at the boundary of the PSD cone), not an ordering.
SEPARATION = 0.01


def _f(v: str) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


#: A seed's correlation under the looser cover counts as lower than under the tight one by more than this: the
#: rounding of a K_t at the boundary of the PSD cone (see SEPARATION), not a difference of the data.
SEED_MARGIN = 1e-3


def seeds_lower(tight: dict, other: dict) -> tuple[int, int]:
    """On how many of the seeds both covers' runs share (finite correlations, paired by seed: the same perturbed
    approach and noise) the looser cover's final correlation lies more than :data:`SEED_MARGIN` below the tight
    one's, and of how many. Reported beside the rule, not part of it: the rule needs the looser cover's interval to
    end below 1 - SEPARATION, since no correlation exceeds 1, so differences of a few hundredths near 1 cannot pass
    it with 5 seeds whatever their direction."""
    pairs = [s for s in sorted(set(tight) & set(other)) if math.isfinite(tight[s]) and math.isfinite(other[s])]
    return sum(1 for s in pairs if other[s] < tight[s] - SEED_MARGIN), len(pairs)


def _cm(d: dict) -> str:
    def one(v: float) -> str:
        return "inf" if math.isinf(v) else f"{100 * v:.1f}"

    return f"{one(d['median'])} [{one(d['lo'])}, {one(d['hi'])}]"


def _column(runs: dict, seeds: list, key: str) -> list[float]:
    """A metric over the seeds; a failed run's missing estimate is +inf (a finite value of a failed run is its
    estimate at the stop)."""
    return [v if math.isfinite(v) else math.inf for v in (_f(runs[s][key]) for s in seeds)]


def _hausdorff(x: dict, y: dict, seeds: list) -> dict:
    """H at 10 % of the travel and at the end for runs ``x`` and ``y`` on the same seeds: ``h10`` and ``hf``, the
    medians with intervals of each (x first), and ``d10`` / ``dfin``, the paired differences x - y."""
    return {"h10": [median_interval(_column(r, seeds, "hausdorff_10")) for r in (x, y)],
            "hf": [median_interval(_column(r, seeds, "final_hausdorff")) for r in (x, y)],
            "d10": paired_difference(_column(x, seeds, "hausdorff_10"), _column(y, seeds, "hausdorff_10")),
            "dfin": paired_difference(_column(x, seeds, "final_hausdorff"), _column(y, seeds, "final_hausdorff"))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", type=Path, nargs="+")
    args = parser.parse_args()
    rows = [r for folder in args.study for r in csv.DictReader(open(folder / "runs.csv"))]
    by = defaultdict(dict)
    for r in rows:
        by[(r["object"], r["mode"])][int(r["seed"])] = r
    objects = sorted({r["object"] for r in rows})
    print("| object | H 10 % VT - T [cm] | early benefit | final H VT - T [cm] (allowed) | no harm | wins / losses "
          "| failed VT / T (why) | on body VT / T |")
    print("|---|---|---|---|---|---|---|---|")
    corr, by_seed = {}, {}
    for o in objects:
        vt, t = by[(o, "visual-tactile")], by[(o, "tactile")]
        if vt:                           # the similarity's ordering needs the visual-tactile runs alone
            by_seed[o] = {s: _f(vt[s]["final_correlation"]) for s in sorted(vt)}
            corr[o] = median_interval(list(by_seed[o].values()), failed="drop")
        seeds = sorted(set(vt) & set(t))
        if not seeds:
            continue

        def col(runs, key):
            return _column(runs, seeds, key)

        fails = [sum(1 for s in seeds if runs[s]["failed"]) for runs in (vt, t)]
        why = sorted({runs[s]["failed"] for runs in (vt, t) for s in seeds if runs[s]["failed"]})
        if all(not math.isfinite(v) for v in col(vt, "final_hausdorff") + col(t, "final_hausdorff")):
            print(f"| {o} | - | n/a | - | n/a | - | {fails[0]} / {fails[1]} ({', '.join(why)}) | - |")
            continue
        early = paired_difference(col(vt, "hausdorff_10"), col(t, "hausdorff_10"))
        final = paired_difference(col(vt, "final_hausdorff"), col(t, "final_hausdorff"))
        allowed = no_harm_margin(median_interval(col(t, "final_hausdorff")))      # the sweep's own rule
        onb = [median_interval([_f(runs[s]["contacts_on_body"]) for s in seeds], failed="drop")["median"]
               for runs in (vt, t)]
        print(
            f"| {o} | {_cm(early)} | {'yes' if early['hi'] < 0 else '**no**'} | {_cm(final)} "
            f"(+{100 * allowed:.1f}) | {'yes' if final['hi'] <= allowed else '**no**'} | "
            f"{final['wins']} / {final['losses']} | {fails[0]} / {fails[1]}"
            f"{' (' + ', '.join(why) + ')' if why else ''} "
            f"| {onb[0]:.2f} / {onb[1]:.2f} |"
        )
    print()
    print("| shape | cover | final correlation tight | final correlation under it | tight above (disjoint intervals) "
          "| lower than tight, by seed |")
    print("|---|---|---|---|---|---|")
    for o in objects:
        for other in ("loose", "wide"):
            if o.endswith("-tight") and o in corr and o.replace("-tight", f"-{other}") in corr:
                a, b = corr[o], corr[o.replace("-tight", f"-{other}")]
                holds = a["lo"] > b["hi"] + SEPARATION
                lower, pairs = seeds_lower(by_seed[o], by_seed[o.replace("-tight", f"-{other}")])
                print(f"| {o[:-6]} | {other} | {a['median']:.2f} [{a['lo']:.2f}, {a['hi']:.2f}] | {b['median']:.2f} "
                      f"[{b['lo']:.2f}, {b['hi']:.2f}] | {'yes' if holds else '**no**'} | {lower} / {pairs} |")


if __name__ == "__main__":
    main()
