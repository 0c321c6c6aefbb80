"""A camera-error study against its calibrated twin: the paired Chamfer distances and what each run's last camera
correction left of the error its views were given (issue 63; docs/results-benchmark.md "A camera whose calibration
is off").

Each corrected run's record holds the error drawn for each view (``camera_error``) and the correction the loop last
found (``camera_corrections``), both rigid motions about the view's optical centre; composed, they leave the view off
by a rigid motion whose displacement at the body's middle and whose rotation are printed (the middle taken at the
object sets' placement, ``--middle``, for every object). Without ``camera_error`` in the records (a calibrated camera
corrected) the correction itself is what is left.

    python scripts/camera_error_table.py outputs/cam65/primitives-0-99 outputs/reach64/primitives-0-99
"""

from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation


def _about(motion: dict) -> tuple[Rotation, np.ndarray]:
    """``(R, t)`` of a record's rigid motion about the view's optical centre ``o``: ``p -> o + R (p - o) + t``."""
    return Rotation.from_rotvec(np.radians(motion["rotation_deg"])), np.asarray(motion["translation_mm"]) / 1e3


def left_of(record: dict, middle: np.ndarray) -> list[tuple[float, float, float, float]]:
    """What a run's last camera correction left of each view's error: per view ``(displacement at middle [mm],
    rotation [deg], its part about horizontal axes [deg], about the vertical [deg])``; empty where no correction was
    made (none recorded, or not ``enough``). Without ``camera_error`` in the record the views were calibrated and the
    correction is what is left."""
    found = record.get("camera_corrections")
    if not found or not found.get("enough"):
        return []
    given = list((record.get("camera_error") or {}).get("views", {}).values())
    out = []
    for k, c in enumerate(found["captures"]):
        o = np.asarray(c["origin"], dtype=np.float64)
        Rc, tc = _about(c)
        Re, te = _about(given[k]) if given else (Rotation.identity(), np.zeros(3))
        seen = o + Re.apply(middle - o) + te
        w = np.degrees((Rc * Re).as_rotvec())
        out.append((float(np.linalg.norm(o + Rc.apply(seen - o) + tc - middle)) * 1e3, float(np.linalg.norm(w)),
                    float(np.linalg.norm(w[:2])), abs(float(w[2]))))
    return out


def _finals(study: Path) -> dict:
    """``object -> (final Chamfer [m], F-score at 5 mm)`` of a study's visual-tactile runs (inf and NaN without an
    estimate)."""
    with open(study / "runs.csv") as f:
        return {row["object"]: (float(row["final_chamfer"]) if row["has_estimate"] == "True" else math.inf,
                                float(row["final_fscore_5mm"] or "nan"))
                for row in csv.DictReader(f) if row["mode"] == "visual-tactile"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("corrected", type=Path, help="the study with --camera-bound (and --camera-error)")
    parser.add_argument("calibrated", type=Path, help="the same objects' study without either")
    parser.add_argument("--middle", type=float, nargs=3, default=(0.5, 0.0, 0.16),
                        help="the body's middle [m], base frame (the object sets' placement, 6 cm above the table)")
    args = parser.parse_args()
    fixed, calibrated = _finals(args.corrected), _finals(args.calibrated)
    both = sorted(set(fixed) & set(calibrated))
    a, fa = np.array([calibrated[o] for o in both]).T
    b, fb = np.array([fixed[o] for o in both]).T
    finite = np.isfinite(a) & np.isfinite(b)
    ratio = b[finite] / a[finite]
    left, turn, level, vertical = [], [], [], []
    for path in sorted((args.corrected / "runs").glob("*.json")):
        for views in left_of(json.loads(path.read_text()), np.asarray(args.middle)):
            for store, value in zip((left, turn, level, vertical), views):
                store.append(value)
    print(f"{len(both)} objects in both: calibrated median Chamfer {np.median(a) * 100:.2f} cm, corrected "
          f"{np.median(b) * 100:.2f} cm ({(np.median(b) / np.median(a) - 1) * 100:+.0f} %); paired ratio median "
          f"{np.median(ratio):.2f} [IQR {np.percentile(ratio, 25):.2f}-{np.percentile(ratio, 75):.2f}]; within 10 % of "
          f"calibrated on {int((b <= 1.1 * a).sum())} of {len(both)}, closer on {int((b < a).sum())} of "
          f"{int(finite.sum())}; F-score at 5 mm {np.nanmedian(fa):.2f} -> {np.nanmedian(fb):.2f}")
    if left:
        print(f"left at the body's middle: median {np.median(left):.1f} mm (90th percentile "
              f"{np.percentile(left, 90):.1f}), {len(left)} views; rotation left: {np.median(turn):.2f} deg, about "
              f"horizontal axes {np.median(level):.2f}, about the vertical {np.median(vertical):.2f}")


if __name__ == "__main__":
    main()
