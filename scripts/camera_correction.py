"""What a camera calibration error costs the estimate, and how much of it a correction from the touches wins back:
on finished visual-tactile runs' final contacts (issue 63; docs/results-benchmark.md "A camera whose calibration is
off").

For each log of a study of calibrated runs (objects of a set, or scene files of ``--scenes``): the run's final
contacts (inner task, y = 0) and inside points, with the captures of the run's own simulated views taken again
(``--draws`` draws per run: each view's noise and error from ``[draw, view, run]``), in four versions:

* ``calibrated``: the views as they stand;
* ``off``: every capture moved by a rigid error of ``--error`` sizes (:class:`~torch_gpioius.sensors.pointcloud.
  CameraError`), its reported origin unmoved;
* ``corrected``: the off captures corrected by :func:`~torch_gpioius.sensors.extrinsics.correct_captures` from the
  contacts (their normals the final model's) within ``--bound`` (default: twice the error), the gap
  estimated with the corrections;
* ``corrected, gap known``: the same with the cover's true gap held (what a user who knows the cover's thickness
  could give);
* with ``--table``, ``corrected with the table``: each capture's points on the table the body stands on (the
  simulated camera's ``support``) held to the table's plane, known (the robot can touch it), as well (gap
  estimated).

Each version is fitted as the run fitted (the run's kernel, sigma^2 and observation policy; K_t learned) and measured
by the converged ruler; the printed rows give Chamfer [cm] and, for the corrections, the error left at the object
(the corrected capture's displacement at the body's middle from the calibrated one) [mm].

    python scripts/camera_correction.py outputs/bench61/primitives-tight/logs/primitives-00?_visual-tactile_0.*
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
import zlib
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from worst_errors import visual_tactile_finals  # noqa: E402  (scripts/ is not a package)


def _views(world):
    cam = world.cameras(world.views)
    return list(getattr(cam, "sources", [cam]))


def _outer(world, policy, captures):
    """The camera's observations of ``captures``, labelled and cropped as a run labels them."""
    from torch_gpioius.exploration.calibration import vision_crop
    from torch_gpioius.exploration.observations import vision_observations
    from torch_gpioius.sensors.pointcloud import PointCloud

    return vision_observations(PointCloud.merge(captures), policy, vision_crop(world, policy))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+", type=Path)
    parser.add_argument("--scenes", type=Path, default=Path("examples/scenes/real"))
    parser.add_argument("--error", default="6mm,1deg", help="the calibration error's sizes")
    parser.add_argument("--bound", default=None, help="the correction's bound (default: twice the error)")
    parser.add_argument("--draws", type=int, default=1, help="error draws per run")
    parser.add_argument("--gap", type=float, default=0.008, help="the cover's true gap [m] (the tight cover's 8 mm)")
    parser.add_argument("--table", action="store_true",
                        help="also correct with each capture's view of the table held to its known plane")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    from torch_gpioius.exploration.calibration import contact_normals
    from torch_gpioius.models.gpiois import GPIOIS
    from torch_gpioius.sensors.extrinsics import correct_captures
    from torch_gpioius.sensors.simulated.camera import CameraError

    error = CameraError.parse(args.error)
    bound = CameraError.parse(args.bound) if args.bound else CameraError(min(2 * error.translation, 0.1),
                                                                          min(2 * error.rotation, math.radians(20)))
    names = ("calibrated", "off", "corrected", "corrected, gap known") + (("corrected with the table",)
                                                                         if args.table else ())
    rows = []
    for log, run, world, model, data in visual_tactile_finals(args.logs, args.scenes):
        policy = world.defaults.policy
        inner = data.task == 0
        contacts = data.x[inner & (data.y == 0)]
        faced, normals = contact_normals(model, contacts)          # those where the estimate has a normal
        middle = world.inner.bounds.mean(axis=0)
        tag = zlib.crc32(log.stem.encode()) % 2 ** 31          # each run its own errors (and noise)
        for draw in range(args.draws):
            views = _views(world)
            plain = [v.reseeded([draw, k, tag]) for k, v in enumerate(views)]
            table = world.support if args.table else None
            off_cams = [type(v)(v.mesh, v.intrinsics, v.T_base_camera, noise_a=v.noise_a, noise_b=v.noise_b,
                                dropout=v.dropout, seed=[draw, k, tag], engine=v.engine, error=error, support=table)
                        for k, v in enumerate(views)]
            calibrated = [c.capture() for c in plain]
            off = [c.capture() for c in off_cams]
            fixes = [correct_captures(off, faced, normals, max_translation=bound.translation,
                                      max_rotation=bound.rotation),
                     correct_captures(off, faced, normals, max_translation=bound.translation,
                                      max_rotation=bound.rotation, gap=args.gap)]
            if args.table:
                fixes.append(correct_captures(off, faced, normals, max_translation=bound.translation,
                                              max_rotation=bound.rotation, support=table))
            versions = [calibrated, off] + [[type(c)(f.apply(c.points), c.origin) for c, f in zip(off, fix.captures)]
                                            for fix in fixes]
            left = []
            for fix in fixes:                # the error left at the body's middle, per view [mm]
                left.append([float(np.linalg.norm(f.apply(cam.applied_error.apply(middle[None], cam.origin))[0]
                                                  - middle)) * 1e3 for f, cam in zip(fix.captures, off_cams)])
            before = [float(np.linalg.norm(cam.applied_error.apply(middle[None], cam.origin)[0] - middle)) * 1e3
                      for cam in off_cams]
            chamfer = []
            for caps in versions:
                ox, oy = _outer(world, policy, caps)
                m = GPIOIS(np.r_[data.x[inner], ox], np.r_[data.y[inner], oy],
                           np.r_[np.zeros(int(inner.sum()), np.int64), np.ones(len(oy), np.int64)],
                           noise=float(model.noise), kernel=run.kernel()).fit(multi_start=True)
                measured = world.measure(m, contacts)
                chamfer.append(measured.shape["chamfer"] * 100 if measured.estimate else math.inf)
            rows.append((chamfer, before, left, [f.gap for f in fixes]))
            print(f"{log.stem} draw {draw}: Chamfer " + ", ".join(f"{n} {c:.2f}" for n, c in zip(names, chamfer))
                  + f" cm | error at the body {np.round(before, 1).tolist()} mm -> corrected "
                  f"{np.round(left[0], 1).tolist()} (gap {fixes[0].gap * 1e3:.1f} mm), gap known "
                  f"{np.round(left[1], 1).tolist()}"
                  + (f", with the table {np.round(left[2], 1).tolist()}" if args.table else ""), flush=True)
    if rows:
        ch = np.array([r[0] for r in rows])
        print(f"{len(rows)} runs: median Chamfer " + ", ".join(f"{n} {v:.2f}" for n, v in
                                                             zip(names, np.median(ch, axis=0))) + " cm")
        for j, n in enumerate(names[2:], start=2):
            print(f"  {n}: closer than off on {(ch[:, j] < ch[:, 1]).sum()} of {len(ch)}; within 10 % of calibrated "
                  f"on {(ch[:, j] <= 1.1 * ch[:, 0]).sum()}")
        print(f"  off within 10 % of calibrated on {(ch[:, 1] <= 1.1 * ch[:, 0]).sum()} of {len(ch)}")
        before = np.concatenate([r[1] for r in rows])
        for j, n in enumerate(names[2:]):
            after = np.concatenate([r[2][j] for r in rows])
            print(f"  {n}: error at the body median {np.median(before):.1f} mm -> {np.median(after):.1f} mm "
                  f"(90th percentile {np.percentile(after, 90):.1f})")


if __name__ == "__main__":
    main()
