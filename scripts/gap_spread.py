"""How evenly does a cover stand off the body, as the touches measure it and as it truly is? On study logs.

The gap settings (docs/method-notes.md sections 16 and 26) take the cover's gap out of the transfer once the touches
show more than 3 cm: one number, the median of the contacts' distances below the seen cover's local planes
(``exploration.observations.CoverGap``). They help where the cover stands off evenly and harm where it does not (the
robot study's sleeve and poncho). This script replays each visual-tactile log's contacts in order against its seen
points (the outer task's surface observations at the end) and prints, per run:

* the contact at which the one-gap rule fires (the median gap of the contacts counted so far above ``--limit``, at
  least five counted), or "-" where it never does;
* at that contact and at the end: how many contacts were counted, the gaps' median, their quartiles and the spread
  ``(p75 - p25) / median``;
* where a field of the gaps would be taken (docs/method-notes.md section 32): the contact at which the field of the
  gaps counted so far (``GapField``) first passes ``--limit`` at a quarter of their places (``FIELD_SHARE``, at
  least ``FIELD_PLACES``: the ``gapfield`` preset's rule, the region alone), and what the default's rules do
  (``cover_even`` with ``cover_uneven_field``): one gap taken while the touches agree on it, then its field once they
  stop agreeing ("gap N, field M") or given up where the field does not pass ("gap N, retracted M"), and the camera's
  inside points retracted at once where the touches disagree from their first judgement ("retracted N"); replayed on
  the run's contacts, so exact up to the first step that differs;
* the truth, from the world the run was rebuilt in: the distance of each seen point from the body (the cover's real
  gap where the camera saw it), its median and spread, over all seen points in the exploration range.

A rule that reads the cover's evenness from the touches can only use the measured columns; the true ones say what
such a rule could hope to see.

    python scripts/gap_spread.py outputs/fh/logs/*visual-tactile*.gpioius
    python scripts/gap_spread.py outputs/wide/primitives-100-119/logs/*visual-tactile*.gpioius --limit 0.03
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from worst_errors import world_of  # noqa: E402  (a sibling script: the world a study log ran in)

from torch_gpioius.exploration.observations import (FIELD_PLACES, GAP_MIN_CONTACTS, CoverGap, ObservationPolicy,  # noqa: E402
                                                    _fires, _uneven, gap_spread)
from torch_gpioius.models.gapfield import GapField  # noqa: E402
from torch_gpioius.core.validation import INSIDE_DEPTH_MAX  # noqa: E402
from torch_gpioius.io.datasets import contact_rows  # noqa: E402
from torch_gpioius.io.runs import load_run  # noqa: E402
from torch_gpioius.sim.meshes import MeshDistance  # noqa: E402


def spread(gaps: np.ndarray) -> tuple[int, float, float, float, float]:
    """``(count, median, p25, p75, spread)`` of gaps [m], the spread as the loop's rule reads it (``gap_spread``:
    NaN with fewer than five); NaN where there are none."""
    if len(gaps) == 0:
        return 0, math.nan, math.nan, math.nan, math.nan
    p25, med, p75 = np.percentile(gaps, [25, 50, 75])
    return len(gaps), float(med), float(p25), float(p75), gap_spread(gaps)


def _field_passes(feet: np.ndarray, gaps: np.ndarray, limit: float) -> bool:
    """Whether the field of ``gaps`` measured at ``feet`` passes ``limit`` at a region of the places (as
    ``exploration.observations`` judges it before taking the field)."""
    if len(gaps) < FIELD_PLACES:                      # (refused by the rule itself; not worth a fit)
        return False
    return _fires(GapField.fit(feet, np.clip(gaps, 0.0, INSIDE_DEPTH_MAX)), feet,
                  ObservationPolicy(vision_inside_gap=limit))


def field_taken(contacts: np.ndarray, seen: np.ndarray, reach: float, limit: float, even: float) -> tuple:
    """``(region, taken)``: the contact count at which the field of the gaps first passes ``limit`` over a region
    (None: never), and what the default's rules do (``cover_even`` with ``cover_uneven_field``, as
    ``exploration.observations`` decides): "gap N" where one gap is taken at contact N and kept; "gap N, field M"
    where the touches stop agreeing on it at M and their field passes, "gap N, retracted M" where it does not (judged
    once the touches measured ``FIELD_PLACES`` places; the one gap is kept until then); "retracted N" where the
    touches disagree from their first judgement (no gap and no field: the camera's inside points are retracted at
    once); None where nothing is taken."""
    measure = CoverGap()
    rule = ObservationPolicy(vision_inside_gap=limit, cover_even=even)      # the loop's judgement of evenness
    region, held, state = None, None, None
    for k in range(GAP_MIN_CONTACTS, len(contacts) + 1):
        feet, gaps = measure.measured(contacts[:k], seen, reach)
        if len(gaps) < GAP_MIN_CONTACTS:
            continue
        passes = _field_passes(feet, gaps, limit)
        if region is None and passes:
            region = k
        if state is None:
            median = float(np.median(gaps))
            uneven = _uneven(gaps, rule, offset_set=held is not None)
            if uneven and held is None:                     # uneven from the first judgement: retracted at once
                state = f"retracted {k}"
            elif uneven and len(gaps) >= FIELD_PLACES:      # the one gap judged: the field, or given up
                state = f"gap {held}, " + ("field" if passes else "retracted") + f" {k}"
            elif held is None and not uneven and median > limit:
                held = k
        if region is not None and state is not None:
            break
    return region, state if state is not None else (f"gap {held}" if held else None)


def replay(log: Path, scenes: Path, limit: float, reach: float | None, even: float = 0.25) -> dict:
    """One run's measured gaps at the firing contact and at the end, and the true gap at its seen points."""
    run = load_run(log)
    final = run.states[run.steps[-1]]
    contacts = final.x[contact_rows(final.x, final.y, final.task)]
    seen = final.x[(final.task == 1) & (final.y == 0)]
    voxel = float(run.meta.get("voxel_size") or run.meta.get("voxel") or run.meta.get("policy", {}).get("voxel")
                  or 0.0)
    reach = reach if reach is not None else max(0.02, voxel)
    measure = CoverGap()
    fired, at_fire = None, None
    for k in range(GAP_MIN_CONTACTS, len(contacts) + 1):
        _, gaps = measure.measured(contacts[:k], seen, reach)
        if len(gaps) >= GAP_MIN_CONTACTS and np.median(gaps) > limit:
            fired, at_fire = k, spread(gaps)
            break
    _, gaps = measure.measured(contacts, seen, reach)
    region, taken = field_taken(contacts, seen, reach, limit, even)
    world = world_of(log, scenes)
    inside = world.in_range(seen) if hasattr(world, "in_range") else np.ones(len(seen), bool)
    true = np.abs(np.asarray(MeshDistance(world.inner, signed=False)(seen[inside]), dtype=float))
    return {"name": log.stem, "contacts": len(contacts), "fired": fired, "at_fire": at_fire, "end": spread(gaps),
            "true": spread(true), "region": region, "taken": taken}


def _cm(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{100 * v:.1f}"


def _row(s: tuple | None) -> str:
    if s is None:
        return "- | - | - | -"
    n, med, p25, p75, rel = s
    return f"{n} | {_cm(med)} | {_cm(p25)}-{_cm(p75)} | {'-' if not math.isfinite(rel) else f'{rel:.2f}'}"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+", type=Path)
    parser.add_argument("--scenes", type=Path, default=Path("examples/scenes/real"), help="the study's scene files")
    parser.add_argument("--limit", type=float, default=0.03, help="the gap beyond which the rule fires [m]")
    parser.add_argument("--reach", type=float, default=None,
                        help="a contact counts within this of its seen patch [m] (default: the run's voxel or 2 cm)")
    parser.add_argument("--even", type=float, default=0.25, help="cover_even: the spread one gap is kept within")
    args = parser.parse_args(argv)
    print("| run | contacts | fires at | counted | median [cm] | IQR [cm] | spread | end: counted | median | IQR "
          "| spread | true: seen points | median | IQR | spread | field's region at | cover_uneven_field |")
    print("|---" * 17 + "|")
    for log in args.logs:
        if "visual-tactile" not in log.stem:
            continue
        r = replay(log, args.scenes, args.limit, args.reach, args.even)
        print(f"| {r['name']} | {r['contacts']} | {r['fired'] or '-'} | {_row(r['at_fire'])} | {_row(r['end'])} "
              f"| {_row(r['true'])} | {r['region'] or '-'} | {r['taken'] or '-'} |")


if __name__ == "__main__":
    main()
