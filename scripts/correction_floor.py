"""What sets the precision of the camera correction: on finished calibrated runs' final contacts, each view captured
again and corrected (:func:`~torch_gpioius.sensors.extrinsics.correct_captures`, the loop's bound and table) in
versions that take one source of error away at a time (issue 63; docs/method-notes.md section 23).

Versions, each a comma-separated list of ``+``-joined flags (``as-run`` alone: the loop's own inputs):

* ``exact``: the contacts moved onto the body's surface, with its normals (no fingertip depth, no estimate's normal);
* ``noiseless``: the views without depth noise or lost pixels;
* ``independent``: the overlaps' pairs counted as independent with a fixed 1 mm (the correction before 2026-11-30);
* ``no-overlap``: the overlaps between views left out.

With ``--error`` every view is also off by a rigid error of those sizes (drawn per view and run), and the figures are
what the correction leaves of it; without, what it moves a calibrated view by. Printed per version: the error left at
the body's middle [mm] (median, 90th percentile, over views) and the rotation left [deg] (in all and about the
vertical).

    python scripts/correction_floor.py as-run,noiseless,exact+noiseless \\
        outputs/reach64/primitives-0-99/logs/primitives-00?_visual-tactile_0.gpioius
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

FLAGS = ("as-run", "exact", "noiseless", "independent", "no-overlap")


def _views(world, seed: list, error, noiseless: bool) -> list:
    """Each view of ``world`` as a fresh simulated camera seeded ``seed + [k]``: with ``error`` (or none), without
    depth noise and lost pixels when ``noiseless``."""
    cam = world.cameras(world.views)
    out = []
    for k, v in enumerate(getattr(cam, "sources", [cam])):
        noise = dict(noise_a=0.0, noise_b=0.0, dropout=0.0) if noiseless else \
            dict(noise_a=v.noise_a, noise_b=v.noise_b, dropout=v.dropout)
        out.append(type(v)(v.mesh, v.intrinsics, v.T_base_camera, seed=seed + [k], engine=v.engine,
                           support=world.support, **noise, **({"error": error} if error is not None else {})))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("versions", help=f"comma-separated versions, each flags joined by '+': {', '.join(FLAGS)}")
    parser.add_argument("logs", nargs="+", type=Path)
    parser.add_argument("--scenes", type=Path, default=Path("examples/scenes/real"))
    parser.add_argument("--error", default=None, help="each view's calibration error (e.g. 6mm,1deg); none: calibrated")
    parser.add_argument("--bound", default="12mm,2deg", help="the correction's bound")
    args = parser.parse_args()
    versions = args.versions.split(",")
    for v in versions:
        if unknown := set(v.split("+")) - set(FLAGS):
            parser.error(f"unknown flags {sorted(unknown)} in {v!r}: use {', '.join(FLAGS)}")
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    import trimesh
    from scipy.spatial.transform import Rotation

    from torch_gpioius.exploration.calibration import contact_normals, vision_crop
    from torch_gpioius.io.datasets import contact_rows
    from torch_gpioius.sensors.extrinsics import correct_captures
    from torch_gpioius.sensors.simulated.camera import CameraError

    error = CameraError.parse(args.error) if args.error else None
    bound = CameraError.parse(args.bound)
    found = {v: ([], [], []) for v in versions}
    for log, run, world, model, data in visual_tactile_finals(args.logs, args.scenes):
        contacts = data.x[contact_rows(data.x, data.y, data.task)]
        faced, normals = contact_normals(model, contacts)
        on_body, _, face = trimesh.proximity.closest_point(world.inner, faced)
        middle = world.inner.bounds.mean(axis=0)
        crop = vision_crop(world, world.defaults.policy)
        seed = [0, zlib.crc32(log.stem.encode()) % 2 ** 31]
        cams = {quiet: _views(world, seed, error, quiet) for quiet in (False, True)}
        caps = {quiet: [c.capture() for c in cs] for quiet, cs in cams.items()}
        if crop is not None:
            caps = {quiet: [c.cropped(crop[0], crop[1]) for c in cs] for quiet, cs in caps.items()}
        line = []
        for version in versions:
            flags = set(version.split("+"))
            p, n = (on_body, world.inner.face_normals[face]) if "exact" in flags else (faced, normals)
            sigma = {"independent": 0.001 / math.sqrt(12), "no-overlap": 1.0}
            overlap = next((sigma[f] for f in ("no-overlap", "independent") if f in flags), None)
            quiet = "noiseless" in flags
            fix = correct_captures(caps[quiet], p, n, max_translation=bound.translation, max_rotation=bound.rotation,
                                   support=world.support, overlap_sigma=overlap)
            if not fix.enough:
                line.append(f"{version}: not enough")
                continue
            left, turn, vertical = [], [], []
            for c, cam, cap in zip(fix.captures, cams[quiet], caps[quiet]):
                seen = cam.applied_error.apply(middle[None], cap.origin) if error is not None else middle[None]
                left.append(float(np.linalg.norm(c.apply(seen)[0] - middle)) * 1e3)
                rest = Rotation.from_rotvec(c.rotation)
                if error is not None:
                    rest = rest * Rotation.from_rotvec(cam.applied_error.rotation)
                w = np.degrees(rest.as_rotvec())
                turn.append(float(np.linalg.norm(w)))
                vertical.append(abs(float(w[2])))
            for store, values in zip(found[version], (left, turn, vertical)):
                store.extend(values)
            line.append(f"{version}: {np.round(left, 1).tolist()} mm")
        print(f"{log.stem} | " + " | ".join(line), flush=True)
    for version, (left, turn, vertical) in found.items():
        if left:
            print(f"{version}: error left at the body's middle median {np.median(left):.2f} mm (90th percentile "
                  f"{np.percentile(left, 90):.2f}); rotation left {np.median(turn):.2f} deg, about the vertical "
                  f"{np.median(vertical):.2f} ({len(left)} views)")


if __name__ == "__main__":
    main()
