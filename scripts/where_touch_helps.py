"""Where on the body does the fusion beat the camera's surface shrunk by the touches' gap, and where does it lose?
On study logs (docs/method-notes.md section 24).

For each visual-tactile log: the final estimate of the run and the simple baseline ``vision-shrunk-5`` rebuilt from the
same log (the capture as the run labelled it, the first five contacts' gap: :mod:`torch_gpioius.baselines`). The true
body's samples in the range are put in bands by their distance from the run's nearest contact (0-1, 1-3, 3-6 and
beyond 6 cm), and per band the script prints the share of the body there and each estimate's mean distance from those
samples (body -> estimate, unsigned) and its signed mean (negative: the estimate lies inside the body). The medians over
the runs say whether the fusion loses to the shrunk surface where the touches went (their own error) or away from
them (the transfer of the camera's shape), which are different levers.

    python scripts/where_touch_helps.py outputs/pl62/primitives-tight100/logs/primitives-00*visual-tactile*
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
from worst_errors import final_arrays, offline_parser  # noqa: E402  (scripts/ is not a package)

#: The bands of distance from the nearest contact [m].
BANDS = (0.0, 0.01, 0.03, 0.06, math.inf)
SPACING = 0.003


def band_errors(body: np.ndarray, contacts: np.ndarray, surfaces: dict, inner_distance) -> dict:
    """Per band of ``body`` `(m, 3)`'s distance from ``contacts`` `(k, 3)`: its share of the samples and, per named
    surface of ``surfaces`` (a trimesh each, or None), the mean unsigned distance from the band's samples to it and
    the signed mean of the surface's nearest points' distance from the body (``inner_distance``: the body's signed
    distance, negative inside) [m]. NaN where a band is empty or a surface missing."""
    from torch_gpioius.sim.meshes import MeshDistance

    reach = cKDTree(contacts).query(body)[0]
    out = {}
    for name, surface in surfaces.items():
        if surface is None:
            out[name] = [(math.nan, math.nan)] * (len(BANDS) - 1)
            continue
        d, nearest, _ = MeshDistance(surface, signed=False).closest(body)
        signed = np.asarray(inner_distance(nearest), dtype=float)
        out[name] = [(float(d[m].mean()), float(signed[m].mean())) if m.any() else (math.nan, math.nan)
                     for m in ((reach >= lo) & (reach < hi) for lo, hi in zip(BANDS[:-1], BANDS[1:]))]
    out["share"] = [float(((reach >= lo) & (reach < hi)).mean()) for lo, hi in zip(BANDS[:-1], BANDS[1:])]
    return out


def one_sided(bands: dict, name: str, near: int = 0) -> float:
    """The body -> estimate mean distance [m] of the surface ``name`` over the whole body, from :func:`band_errors`'
    per-band means and shares; with ``near`` > 0, the fusion's in the first ``near`` bands and ``name``'s beyond (a
    blend: what the fusion would score if it matched that surface away from the touches)."""
    total = 0.0
    for i, share in enumerate(bands["share"]):
        if share > 0:
            total += share * (bands["fusion"] if i < near else bands[name])[i][0]
    return total


def main() -> None:
    args = offline_parser(__doc__).parse_args()
    from torch_gpioius.baselines import BASELINES, BaselineData
    from torch_gpioius.sim.meshes import MeshDistance
    from torch_gpioius.sim.ruler import METRICS_GRID

    rows = []
    for log, run, world, model, x, y, task, contacts in final_arrays(args):
        first = run.states[run.steps[0]]
        fx, fy, ft = np.asarray(first.x), np.asarray(first.y), np.asarray(first.task)
        base = BaselineData(fx[ft == 1], fy[ft == 1], contacts, run.kernel(), float(model.noise),
                            world.bounds(METRICS_GRID), METRICS_GRID, 0.005, world.range)
        shrunk = BASELINES.get("vision-shrunk-5")(base)
        estimate = world.measure(model, contacts).surface
        body = world.inner_samples_in_range(SPACING)
        bands = band_errors(body, contacts, {"fusion": estimate, "shrunk": None if shrunk is None else shrunk.surface},
                            MeshDistance(world.inner))
        rows.append(bands)
        cells = " | ".join(f"{s:.0%}: {f[0] * 100:.2f}/{b[0] * 100:.2f}"
                           for s, f, b in zip(bands["share"], bands["fusion"], bands["shrunk"]))
        print(f"{log.stem}: per band share: fusion/shrunk mean distance [cm]  {cells}", flush=True)
    if not rows:
        return
    fusion = np.array([one_sided(r, "fusion") for r in rows])
    shrunk_all = np.array([one_sided(r, "shrunk") for r in rows])
    print(f"body -> estimate over the whole body: fusion closer than the shrunk surface on "
          f"{(fusion < shrunk_all).sum()} of {len(rows)}; the fusion within 1 / 3 cm of a contact and the shrunk "
          f"surface beyond: closer on "
          f"{(np.array([one_sided(r, 'shrunk', 1) for r in rows]) < shrunk_all).sum()} / "
          f"{(np.array([one_sided(r, 'shrunk', 2) for r in rows]) < shrunk_all).sum()}")
    names = [f"{lo * 100:g}-{hi * 100:g} cm" for lo, hi in zip(BANDS[:-1], BANDS[1:])]
    print(f"{len(rows)} runs; medians per band (from the nearest contact):")
    for i, name in enumerate(names):
        share = np.median([r["share"][i] for r in rows])
        f = np.array([r["fusion"][i] for r in rows])
        b = np.array([r["shrunk"][i] for r in rows])
        ok = ~np.isnan(f[:, 0]) & ~np.isnan(b[:, 0])
        print(f"  {name}: share {share:.0%}; mean distance fusion {np.median(f[ok, 0]) * 100:.2f} / shrunk "
              f"{np.median(b[ok, 0]) * 100:.2f} cm (fusion closer on {(f[ok, 0] < b[ok, 0]).sum()} of {ok.sum()}); "
              f"signed fusion {np.nanmedian(f[ok, 1]) * 1000:+.1f} / shrunk {np.nanmedian(b[ok, 1]) * 1000:+.1f} mm")


if __name__ == "__main__":
    main()
